"""Experiment files (configs/experiments/*.toml): loading, overlays, overrides, validation.

An experiment is data: the scenes (or traces), GPUs, fidelity levels, schemes
with their parameters, and GPU or scene overrides to sweep. In every table a
list is a grid axis and a scalar a fixed value::

    name = "kbuffer-k"
    scenes = ["default", "foliage"]
    size = "320x240"
    gpus = ["gtx280"]
    fidelity = ["analytic", "full"]
    [schemes.kbuffer]
    k = [2, 4, 8]
    [gpu-set]
    "rop.reorder_entries" = [16, 64]

:func:`load_experiment` reads a file, overlays it on its ``include`` (the
including file's keys win, tables merge key by key), applies ``--set``
overrides and validates everything a run will need (scenes, traces, GPU
presets and keys, schemes and their parameters) before anything runs: the
first problem raises a one-line :class:`~gpusim.errors.ConfigError` naming the
file, the key and the valid choices.
"""

from __future__ import annotations

import copy
import dataclasses
import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from gpusim.config import apply_overrides, load_toml, parse_override
from gpusim.errors import ConfigError, GpusimError
from gpusim.hw import FIDELITIES, gpu_presets
from gpusim.hw.gpu import GpuConfig, preset_file
from gpusim.schemes import scheme_class, scheme_names

EXPERIMENT_DIR = Path(__file__).resolve().parents[2] / "configs" / "experiments"
DEFAULT_EXPERIMENT = "quick-start"

#: "none" runs the functional model only; the others are gpusim.hw's timing levels.
FIDELITY_CHOICES = ("none", *FIDELITIES)

#: top-level keys and what each holds (documented in the README's experiment reference)
TOP_KEYS = {
    "name": "experiment name; the default output directory is reports/<name>/",
    "description": "one line about the experiment",
    "include": "a base experiment file (or a list of them) this file overlays",
    "scenes": "built-in scene names, scene files or mesh files",
    "traces": "trace files (.npz)",
    "size": "WIDTHxHEIGHT: override every scene's screen size",
    "gpus": "GPU presets or GPU files",
    "fidelity": "levels: none (functional only), analytic, sampled, full, thesis",
    "schemes": "one table per scheme: its parameters (a list is an axis)",
    "gpu-set": "GPU config overrides (a list is an axis)",
    "scene-set": "scene overrides applied to every scene (a list is an axis)",
    "scene-sweeps": "[[scene-sweeps]] tables: a scene with its own override axes (scene, name, set)",
    "paper": "a paper comparison (gpusim.papers): the report opens with its Paper vs gpusim table",
}
#: keys of one ``[[scene-sweeps]]`` table
SWEEP_KEYS = {
    "scene": "a built-in scene name, scene file or mesh file",
    "name": "the scene column of its runs (default: the scene's name)",
    "set": "scene overrides for this scene only (a list is an axis), as in [scene-set]",
}
_NAME = re.compile(r"^[A-Za-z0-9][A-Za-z0-9._-]*$")


@dataclass(frozen=True)
class SchemeEntry:
    """One ``[schemes.LABEL]`` table: the registered scheme it runs and its parameter axes."""

    label: str
    scheme: str
    axes: dict[str, list[Any]]          # every parameter given; a fixed value is a list of one


@dataclass(frozen=True)
class SceneSweep:
    """One ``[[scene-sweeps]]`` table: a scene swept over its own override axes."""

    scene: str                           # as given: a built-in name, a scene file or a mesh file
    name: str                            # the ``scene`` column of its runs
    axes: dict[str, list[Any]]           # scene keys; a fixed value is a list of one


@dataclass(frozen=True)
class Experiment:
    """A validated experiment: everything :func:`gpusim.experiment.grid.expand` needs."""

    name: str
    description: str
    path: str                            # the file it was read from ("<memory>" when built in code)
    base_dir: Path                       # relative paths resolve here first, then in the working directory
    scenes: list[str] = field(default_factory=list)
    traces: list[str] = field(default_factory=list)
    size: tuple[int, int] | None = None
    gpus: list[str] = field(default_factory=lambda: ["gtx280"])
    fidelity: list[str] = field(default_factory=lambda: ["full"])
    schemes: list[SchemeEntry] = field(default_factory=list)
    gpu_set: dict[str, list[Any]] = field(default_factory=dict)
    scene_set: dict[str, list[Any]] = field(default_factory=dict)
    scene_sweeps: list[SceneSweep] = field(default_factory=list)
    data: dict = field(default_factory=dict)     # the resolved tree (overlays and --set applied)

    def resolved_data(self) -> dict:
        """The experiment tree as run, with file paths made absolute, so it can be run from anywhere."""
        data = copy.deepcopy(self.data)
        data.pop("include", None)
        for key in ("scenes", "traces", "gpus"):
            if key in data:
                values = [data[key]] if isinstance(data[key], str) else data[key]
                data[key] = [self._absolute(v) for v in values]
        for sweep, parsed in zip(data.get("scene-sweeps", []), self.scene_sweeps):
            sweep["scene"] = self._absolute(sweep["scene"])
            sweep["name"] = parsed.name
        return data

    def _absolute(self, text: str) -> str:
        return str(self.resolve_path(text).resolve()) if (Path(text).suffix and self.resolve_path(text).exists()) \
            else text

    def scene_spec(self, scene: str) -> str:
        """What :func:`gpusim.scene.load_scene` takes for a ``scenes`` entry: a file resolved, a name as given."""
        return str(self.resolve_path(scene)) if Path(scene).suffix else scene

    def resolve_path(self, text: str) -> Path:
        """A path from the file: relative to the experiment's folder if it exists there, else as given."""
        path = Path(text)
        if not path.is_absolute() and (self.base_dir / path).exists():
            return self.base_dir / path
        return path


def scene_label(scene: str) -> str:
    """The ``scene`` column of a ``scenes`` entry: a file's stem, or the built-in scene's name."""
    return Path(scene).stem if Path(scene).suffix else scene


def experiment_path(spec: str | None) -> Path:
    """A file path, or the name of a bundled experiment (configs/experiments/NAME.toml)."""
    spec = spec or DEFAULT_EXPERIMENT
    path = Path(spec)
    if path.is_file():
        return path
    if not path.suffix and "/" not in spec:
        bundled = EXPERIMENT_DIR / f"{spec}.toml"
        if bundled.is_file():
            return bundled
        names = sorted(p.stem for p in EXPERIMENT_DIR.glob("*.toml"))
        raise ConfigError(f"unknown experiment '{spec}' (bundled: {', '.join(names)}); or give a .toml file")
    raise ConfigError(f"{spec}: no such experiment file; check the path")


def _merge(base: dict, top: dict) -> dict:
    """``top`` overlaid on ``base``: tables merge key by key, anything else in ``top`` wins."""
    out = copy.deepcopy(base)
    for key, value in top.items():
        if isinstance(value, dict) and isinstance(out.get(key), dict):
            out[key] = _merge(out[key], value)
        else:
            out[key] = copy.deepcopy(value)
    return out


def _read_with_includes(path: Path, seen: tuple[Path, ...] = ()) -> dict:
    path = path.resolve()
    if path in seen:
        raise ConfigError(f"{path}: include: the file includes itself (through {' -> '.join(p.name for p in seen)})")
    data = load_toml(path)
    includes = data.pop("include", [])
    if isinstance(includes, str):
        includes = [includes]
    if not isinstance(includes, list) or not all(isinstance(i, str) for i in includes):
        raise ConfigError(f"{path}: include: expected a file name or a list of them, e.g. include = \"base.toml\"")
    merged: dict = {}
    for inc in includes:
        inc_path = (path.parent / inc) if not Path(inc).is_absolute() else Path(inc)
        if not inc_path.is_file():
            raise ConfigError(f"{path}: include: {inc}: no such file (looked in {path.parent})")
        merged = _merge(merged, _read_with_includes(inc_path, seen + (path,)))
    return _merge(merged, data)


def apply_experiment_overrides(data: dict, overrides: list[str]) -> dict:
    """``--set KEY=VALUE`` on an experiment tree. Under ``gpu-set`` and ``scene-set`` the rest of the key is
    one dotted key (``--set gpu-set.rop.units=[16,32]``); elsewhere dots are tables
    (``--set schemes.kbuffer.k=[4]``)."""
    plain = []
    for text in overrides:
        parts, value = parse_override(text)
        if parts[0] == "include":
            raise ConfigError(f"--set {text}: include is read from the file before --set applies; write it in "
                              "the file, or give the other file as FILE")
        if parts == ["size"] and not isinstance(value, str):      # 0x10 reads as a TOML hex number
            value = text.split("=", 1)[1].strip()
        if parts[0] in ("gpu-set", "scene-set") and len(parts) > 1:
            data.setdefault(parts[0], {})
            if not isinstance(data[parts[0]], dict):
                raise ConfigError(f"--set {text}: '{parts[0]}' is not a table")
            data[parts[0]][".".join(parts[1:]).strip('"')] = value
        elif parts[0] == "scene-sweeps" and len(parts) > 3 and parts[2] == "set":
            sweeps = data.get("scene-sweeps")
            if not isinstance(sweeps, list) or not parts[1].isdigit() or int(parts[1]) >= len(sweeps) \
                    or not isinstance(sweeps[int(parts[1])], dict):
                count = len(sweeps) if isinstance(sweeps, list) else 0
                raise ConfigError(f"--set {text}: 'scene-sweeps.{parts[1]}' is not one of the file's {count} "
                                  "[[scene-sweeps]] tables" + (f" (valid: 0..{count - 1})" if count else ""))
            table = sweeps[int(parts[1])].setdefault("set", {})
            if not isinstance(table, dict):
                raise ConfigError(f"--set {text}: 'scene-sweeps.{parts[1]}.set' is not a table")
            table[".".join(parts[3:]).strip('"')] = value
        else:
            plain.append(text)
    return apply_overrides(data, plain)


def _axis(value: Any, key: str, where: str) -> list[Any]:
    values = list(value) if isinstance(value, list) else [value]
    if not values:
        raise ConfigError(f"{where}: {key}: an empty list leaves no runs; give a value")
    seen = []
    for v in values:
        if v in seen:
            raise ConfigError(f"{where}: {key}: lists {v!r} twice; give each value once")
        seen.append(v)
    return values


def _strings(data: dict, key: str, where: str) -> list[str]:
    value = data.get(key, [])
    value = [value] if isinstance(value, str) else value
    if not isinstance(value, list) or not all(isinstance(v, str) for v in value):
        raise ConfigError(f"{where}: {key}: expected a list of strings, e.g. {key} = [\"...\"]")
    if len(set(value)) != len(value):
        raise ConfigError(f"{where}: {key}: lists {sorted({v for v in value if value.count(v) > 1})[0]!r} twice")
    return value


def _parse_size(text: Any, where: str) -> tuple[int, int]:
    from gpusim.cli.common import parse_size
    if not isinstance(text, str):
        raise ConfigError(f"{where}: size: expected \"WIDTHxHEIGHT\" in pixels, e.g. size = \"320x240\"")
    try:
        return parse_size(text)
    except GpusimError:
        raise ConfigError(f"{where}: size: {text!r} is not WIDTHxHEIGHT with sides of 1..16384 pixels, "
                          "e.g. size = \"320x240\"") from None


def _check_schemes(table: Any, where: str) -> list[SchemeEntry]:
    if table is not None and not isinstance(table, dict):
        raise ConfigError(f"{where}: schemes: expected tables such as [schemes.kbuffer], got {table!r}")
    if not table:
        raise ConfigError(f"{where}: schemes: name at least one scheme, e.g. [schemes.alpha-blend] "
                          f"(valid: {', '.join(scheme_names())})")
    entries = []
    for label, params in table.items():
        if not isinstance(params, dict):
            raise ConfigError(f"{where}: schemes.{label}: expected a table of parameters, e.g. [schemes.{label}]")
        params = dict(params)
        name = params.pop("scheme", label)
        if name not in scheme_names():
            hint = "" if "scheme" in table[label] else "; or name one with scheme = \"...\" inside the table"
            raise ConfigError(f"{where}: schemes.{label}: unknown scheme '{name}' "
                              f"(valid: {', '.join(scheme_names())}){hint}")
        if label != name and label in scheme_names():
            raise ConfigError(f"{where}: schemes.{label}: the label names the scheme {label} but scheme = \"{name}\"; "
                              f"use another label (e.g. [schemes.{name}-{label}])")
        if not _NAME.match(label):
            raise ConfigError(f"{where}: schemes.{label}: a label holds letters, digits, '.', '_' and '-' only")
        valid = [f.name for f in dataclasses.fields(scheme_class(name))]
        for key in params:
            if key not in valid:
                raise ConfigError(f"{where}: schemes.{label}.{key}: unknown parameter of {name} "
                                  f"(valid: {', '.join(valid)})")
        entries.append(SchemeEntry(label, name, {k: _axis(v, f"schemes.{label}.{k}", where)
                                                 for k, v in params.items()}))
    return entries


def _check_sets(data: dict, key: str, where: str) -> dict[str, list[Any]]:
    return _set_axes(data.get(key, {}), key, where)


def _set_axes(table: Any, key: str, where: str) -> dict[str, list[Any]]:
    """A ``[gpu-set]`` or ``[scene-set]``-style table (``key`` names it in errors) as axes."""
    if not isinstance(table, dict):
        raise ConfigError(f"{where}: {key}: expected a table of KEY = value or [values], e.g. [{key}]")
    out = {}
    for k, v in table.items():
        if isinstance(v, dict):
            raise ConfigError(f"{where}: {key}.{k}: give dotted keys as one quoted key, "
                              f"e.g. \"{k}.{next(iter(v), 'key')}\" = ...")
        out[k] = _axis(v, f"{key}.{k}", where)
        if key == "gpu-set" and k == "runner.workers" and len(out[k]) > 1:
            raise ConfigError(f"{where}: gpu-set.runner.workers: the number of processes changes no figure, so "
                              "its values would give identical runs; give one value")
    return out


def _check_sweeps(data: dict, scene_set: dict[str, list[Any]], where: str) -> list[SceneSweep]:
    tables = data.get("scene-sweeps", [])
    if not isinstance(tables, list) or not all(isinstance(t, dict) for t in tables):
        raise ConfigError(f"{where}: scene-sweeps: expected [[scene-sweeps]] tables, e.g. [[scene-sweeps]] "
                          "scene = \"layer-stack\" set = { \"objects.0.layers\" = [1, 4] }")
    out = []
    for i, table in enumerate(tables):
        at = f"scene-sweeps.{i}"
        unknown = [k for k in table if k not in SWEEP_KEYS]
        if unknown:
            raise ConfigError(f"{where}: {at}.{unknown[0]}: unknown key (valid: {', '.join(SWEEP_KEYS)})")
        scene = table.get("scene")
        if not isinstance(scene, str) or not scene:
            raise ConfigError(f"{where}: {at}.scene: expected a scene name or file, e.g. scene = \"layer-stack\"")
        name = table.get("name", scene_label(scene))
        if not isinstance(name, str) or not _NAME.match(name):
            raise ConfigError(f"{where}: {at}.name: {name!r} must be letters, digits, '.', '_' or '-' "
                              "(it is the scene column of its runs)")
        axes = _set_axes(table.get("set", {}), f"{at}.set", where)
        both = [k for k in axes if k in scene_set]
        if both:
            raise ConfigError(f"{where}: {at}.set: {both[0]} is also in [scene-set]; give it in one of them")
        out.append(SceneSweep(scene, name, axes))
    return out


def experiment_from_data(data: dict, where: str, base_dir: Path, default_name: str = "experiment") -> Experiment:
    """Validate an experiment tree (keys, values, schemes, parameters, GPUs, scenes) into an Experiment."""
    unknown = [k for k in data if k not in TOP_KEYS]
    if unknown:
        raise ConfigError(f"{where}: {unknown[0]}: unknown key (valid: {', '.join(TOP_KEYS)})")
    name = data.get("name", default_name)
    if not isinstance(name, str) or not _NAME.match(name):
        raise ConfigError(f"{where}: name: {name!r} must be letters, digits, '.', '_' or '-' "
                          "(it names the output directory)")
    description = data.get("description", "")
    if not isinstance(description, str) or "\n" in description:
        raise ConfigError(f"{where}: description: expected one line of text")
    scenes, traces = _strings(data, "scenes", where), _strings(data, "traces", where)
    scene_set = _check_sets(data, "scene-set", where)
    sweeps = _check_sweeps(data, scene_set, where)
    if not scenes and not traces and not sweeps:
        raise ConfigError(f"{where}: scenes: give scenes = [\"default\", ...], traces = [\"traces/x.npz\"] or "
                          "[[scene-sweeps]] tables")
    fidelity = _strings(data, "fidelity", where) if "fidelity" in data else ["full"]
    for level in fidelity:
        if level not in FIDELITY_CHOICES:
            raise ConfigError(f"{where}: fidelity: '{level}' is not a level (valid: {', '.join(FIDELITY_CHOICES)})")
    if not fidelity:
        raise ConfigError(f"{where}: fidelity: an empty list leaves no runs (valid: {', '.join(FIDELITY_CHOICES)})")
    gpus = _strings(data, "gpus", where) if "gpus" in data else ["gtx280"]
    if not gpus:
        raise ConfigError(f"{where}: gpus: an empty list leaves no runs (valid: {', '.join(gpu_presets())})")
    size = _parse_size(data["size"], where) if "size" in data else None
    if size and traces and not scenes and not sweeps:
        raise ConfigError(f"{where}: size: a trace's screen is fixed; size applies to scenes only")
    if "paper" in data:
        from gpusim.papers import paper_names
        if data["paper"] not in paper_names():
            raise ConfigError(f"{where}: paper: {data['paper']!r} is not a paper comparison "
                              f"(valid: {', '.join(paper_names())})")
    exp = Experiment(name=name, description=description, path=where, base_dir=base_dir, scenes=scenes,
                     traces=traces, size=size, gpus=gpus, fidelity=fidelity,
                     schemes=_check_schemes(data.get("schemes"), where),
                     gpu_set=_check_sets(data, "gpu-set", where), scene_set=scene_set, scene_sweeps=sweeps,
                     data=data)
    _check_sources(exp)
    return exp


def _check_sources(exp: Experiment) -> None:
    """Every scene loads (with the size and scene-set or sweep values) and every trace file exists."""
    from gpusim.experiment.grid import scene_axes, scene_overrides
    from gpusim.scene import load_scene
    for entry, _, spec, combos, what in scene_axes(exp):
        try:
            load_scene(spec)                 # a problem of the scene itself
        except GpusimError as exc:
            raise ConfigError(f"{exp.path}: {entry}: {exc}") from None
        scene = entry.partition(": ")[2]
        for combo in combos:
            try:
                load_scene(spec, scene_overrides(exp, combo))
            except GpusimError as exc:       # a problem of the experiment's overrides: name them, not the file
                head, _, rest = str(exc).partition(": ")
                text = (rest if Path(head).suffix else str(exc)).removeprefix("--set ")
                raise ConfigError(f"{exp.path}: {what if combo else 'size'} on scene {scene}: {text}") from None
    for trace in exp.traces:
        if not exp.resolve_path(trace).is_file():
            raise ConfigError(f"{exp.path}: traces: {trace}: no such file (make it with gpusim trace, "
                              f"or fix the path)")


def gpu_table(spec: str, exp: Experiment) -> dict:
    """The parsed TOML of a GPU preset or file (a file is validated here, so its own errors name it)."""
    if spec in gpu_presets():
        return load_toml(preset_file(spec))
    path = exp.resolve_path(spec)
    if spec and path.is_dir():
        raise ConfigError(f"{exp.path}: gpus: {spec}: is a directory, not a GPU file; give a .toml file or a "
                          f"preset (valid: {', '.join(gpu_presets())})")
    if path.suffix == ".toml" and path.is_file():
        data = load_toml(path)
        try:
            GpuConfig.from_table(copy.deepcopy(data), str(path))
        except ConfigError as exc:
            raise ConfigError(f"{exp.path}: gpus: {exc}") from None
        return data
    if path.suffix == ".toml":
        raise ConfigError(f"{exp.path}: gpus: {spec}: no such GPU file (looked beside the experiment and in the "
                          "working directory)")
    raise ConfigError(f"{exp.path}: gpus: '{spec}' is not a GPU preset (valid: {', '.join(gpu_presets())}) "
                      "or a .toml file")


def build_gpu(table: dict, overrides: list[str], exp: Experiment) -> GpuConfig:
    """A GPU's table (from :func:`gpu_table`) with the ``gpu-set`` overrides applied; bad keys name the
    experiment file."""
    data = copy.deepcopy(table)
    try:
        apply_overrides(data, overrides)
    except ConfigError as exc:
        raise ConfigError(f"{exp.path}: gpu-set: {str(exc).removeprefix('--set ')}") from None
    return GpuConfig.from_table(data, f"{exp.path}: gpu-set")


def load_experiment(spec: str | None = None, overrides: list[str] | None = None) -> Experiment:
    """Read, overlay, override and validate an experiment (a file or a bundled name)."""
    path = experiment_path(spec)
    data = apply_experiment_overrides(_read_with_includes(path), list(overrides or []))
    exp = experiment_from_data(data, str(path), path.parent, default_name=path.stem)
    from gpusim.experiment.grid import expand
    expand(exp)                 # every GPU, override and parameter combination is built once here
    return exp
