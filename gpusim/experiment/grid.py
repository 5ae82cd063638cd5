"""The run grid of an experiment: scenes x GPUs x gpu-set axes x each scheme's parameter grid x fidelity.

:func:`expand` turns a validated :class:`~gpusim.experiment.spec.Experiment`
into :class:`RunSpec` s in a fixed order (scene, GPU, gpu-set values, scheme
table, parameter values, fidelity level innermost), building every GPU config
and scheme once so a bad value fails before anything runs. A combination a
scheme cannot run is kept as a run with a ``skip`` reason, never failed.

A run's id (:func:`run_id`) is a stable hash of its resolved config, the
content of its trace and the code that computes its figures
(:func:`model_fingerprint`), so a finished run is recognised in any later sweep
of the same code, and never reused by code that would compute it differently.
"""

from __future__ import annotations

import functools
import hashlib
import itertools
import json
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from gpusim.errors import ConfigError
from gpusim.hw import THESIS_RULES
from gpusim.hw.gpu import GpuConfig
from gpusim.schemes import make_scheme

#: levels that run the GPU model (the others ignore the GPU)
GPU_LEVELS = ("analytic", "sampled", "full")


@dataclass(frozen=True)
class Source:
    """Where a run's trace comes from: a scene (with overrides) or a trace file."""

    label: str                               # the ``scene`` column
    kind: str                                # "scene" or "trace"
    spec: str                                # the scene name or file, or the trace path
    overrides: tuple[str, ...] = ()          # scene --set overrides (size, scene-set values)
    scene_set: tuple[tuple[str, Any], ...] = ()


@dataclass(frozen=True)
class RunSpec:
    """One grid point."""

    index: int
    source: Source
    gpu: str
    gpu_set: tuple[tuple[str, Any], ...]
    gpu_config: GpuConfig
    label: str                               # the [schemes.LABEL] table (the ``variant`` column)
    scheme: str
    params: dict                             # resolved: every parameter with its default filled in
    fidelity: str
    skip: str | None = None

    @property
    def group_key(self) -> tuple:
        """Runs that share one functional model run: same trace, scheme table and parameters."""
        return (self.source, self.label, json.dumps(self.params, sort_keys=True))


def skip_reason(scheme: str, fidelity: str) -> str | None:
    """Why ``scheme`` cannot run at ``fidelity`` (None when it can)."""
    if fidelity == "thesis" and scheme not in THESIS_RULES:
        return (f"fidelity 'thesis' models only {', '.join(sorted(THESIS_RULES))} (seed 003 section 4.3.2)")
    return None


def _frozen(value: Any) -> Any:
    return tuple(_frozen(v) for v in value) if isinstance(value, (list, tuple)) else value


def set_combinations(axes: dict[str, list[Any]]) -> list[tuple[tuple[str, Any], ...]]:
    """Every combination of the axes' values, in file order (one empty combination without axes); a value
    that is itself a list becomes a tuple, so combinations can be compared and hashed."""
    keys = list(axes)
    return [tuple(zip(keys, map(_frozen, values))) for values in itertools.product(*(axes[k] for k in keys))]


def _toml_value(value: Any) -> str:
    return json.dumps(value) if not isinstance(value, bool) else ("true" if value else "false")


def scene_overrides(exp, combo: tuple[tuple[str, Any], ...]) -> list[str]:
    """Scene ``--set`` overrides for the experiment's size and one scene-set combination."""
    out = [f"{k}={_toml_value(v)}" for k, v in combo]
    if exp.size:
        out += [f"screen.width={exp.size[0]}", f"screen.height={exp.size[1]}"]
    return out


def scene_axes(exp) -> list[tuple[str, str, str, list[tuple], str]]:
    """(the entry as errors name it, the scene column, the scene spec, its scene-set combinations, the key
    that gives them) for each ``scenes`` entry, then each ``[[scene-sweeps]]`` table (its own axes first,
    then ``[scene-set]``'s)."""
    from gpusim.experiment.spec import scene_label
    out = [(f"scenes: {scene}", scene_label(scene), exp.scene_spec(scene), set_combinations(exp.scene_set),
            "scene-set") for scene in exp.scenes]
    for i, sweep in enumerate(exp.scene_sweeps):
        out.append((f"scene-sweeps.{i}.scene: {sweep.scene}", sweep.name, exp.scene_spec(sweep.scene),
                    set_combinations({**sweep.axes, **exp.scene_set}), f"scene-sweeps.{i}.set"))
    return out


def sources(exp) -> list[Source]:
    out: list[Source] = [Source(label, "scene", spec, tuple(scene_overrides(exp, combo)), combo)
                         for _, label, spec, combos, _ in scene_axes(exp) for combo in combos]
    for trace in exp.traces:
        out.append(Source(Path(trace).stem, "trace", str(exp.resolve_path(trace))))
    named: dict[tuple, Source] = {}
    for source in out:
        other = named.setdefault((source.label, source.scene_set), source)
        if other is not source and other == source:
            values = " ".join(f"{k}={v!r}" for k, v in source.scene_set)
            raise ConfigError(f"{exp.path}: scenes: '{source.label}'{' ' + values if values else ''} is listed twice "
                              "(in scenes or [[scene-sweeps]]); give it once, or a sweep another name")
        if other.spec != source.spec or other.kind != source.kind:
            raise ConfigError(f"{exp.path}: scenes: '{other.spec}' and '{source.spec}' would both be the scene "
                              f"'{source.label}' in the results; list one, or rename a file")
    return out


def _params(entry, where: str) -> list[dict]:
    keys = list(entry.axes)
    grid = []
    for values in itertools.product(*(entry.axes[k] for k in keys)):
        given = dict(zip(keys, values))
        grid.append(make_scheme(entry.scheme, given, where=f"{where}: schemes.{entry.label}").params())
    return grid


def expand(exp) -> list[RunSpec]:
    """Every grid point of ``exp`` in order; bad GPU keys, scheme parameters and values fail here."""
    from gpusim.experiment.spec import build_gpu, gpu_table
    gpu_combos = set_combinations(exp.gpu_set)
    machines: dict[tuple, GpuConfig] = {}
    for gpu in exp.gpus:
        table = gpu_table(gpu, exp)           # read (and a file validated) once per GPU
        for combo in gpu_combos:
            machines[(gpu, combo)] = build_gpu(table, [f"{k}={_toml_value(v)}" for k, v in combo], exp)
    params = {entry.label: _params(entry, exp.path) for entry in exp.schemes}
    runs: list[RunSpec] = []
    for source in sources(exp):
        for gpu in exp.gpus:
            for combo in gpu_combos:
                for entry in exp.schemes:
                    for p in params[entry.label]:
                        for level in exp.fidelity:
                            runs.append(RunSpec(len(runs), source, gpu, combo, machines[(gpu, combo)],
                                                entry.label, entry.scheme, p, level,
                                                skip_reason(entry.scheme, level)))
    if not runs:
        raise ConfigError(f"{exp.path}: the grid is empty; give at least one scene, GPU, level and scheme")
    return runs


#: gpusim's subpackages whose code computes no figure of a run: the report's rendering, the command line
PRESENTATION = ("report", "cli")


@functools.cache
def model_fingerprint() -> str:
    """:func:`source_fingerprint` of the gpusim package that is running. A run's id includes it: a sweep into
    a directory of runs made by other code (an edited model, another version) computes them again instead
    of reusing figures this code would not give."""
    return source_fingerprint(Path(__file__).resolve().parents[1])


def source_fingerprint(root: Path) -> str:
    """16 hex digits of a hash of the ``.py`` files under the package directory ``root``, all but the
    :data:`PRESENTATION` subpackages' (their paths and contents)."""
    digest = hashlib.sha256()
    for path in sorted(root.rglob("*.py")):
        rel = path.relative_to(root)
        if rel.parts[0] in PRESENTATION:
            continue
        digest.update(rel.as_posix().encode() + b"\0" + path.read_bytes() + b"\0")
    return digest.hexdigest()[:16]


def gpu_identity(config: GpuConfig) -> dict:
    """The GPU config as it enters a run's id: ``runner.workers`` changes no figure, so it is left out."""
    data = config.to_dict()
    data["runner"] = {k: v for k, v in data["runner"].items() if k != "workers"}
    return data


def resolved_run(run: RunSpec, trace_sha: str) -> dict:
    """The run's resolved config: what its id hashes and what ``runs/<run>/config.toml`` records."""
    return {"scene": run.source.label, "source": {"kind": run.source.kind, "spec": run.source.spec,
                                                  "overrides": list(run.source.overrides)},
            "scene_set": dict(run.source.scene_set), "trace_sha256": trace_sha, "scheme": run.scheme,
            "variant": run.label, "params": run.params,
            "fidelity": run.fidelity, "gpu": run.gpu, "gpu_set": dict(run.gpu_set),
            "gpu_config": gpu_identity(run.gpu_config), "model": model_fingerprint()}


def run_id(run: RunSpec, trace_sha: str) -> str:
    """A stable 16-hex-digit id of the run's resolved config, its trace's content and the model's code (where
    the trace came from, a path, is left out: the content decides; so is ``runner.workers``, which changes no
    figure)."""
    identity = {k: v for k, v in resolved_run(run, trace_sha).items() if k != "source"}
    identity["gpu_set"] = {k: v for k, v in identity["gpu_set"].items() if k != "runner.workers"}
    text = json.dumps(identity, sort_keys=True, default=str)
    return hashlib.sha256(text.encode()).hexdigest()[:16]
