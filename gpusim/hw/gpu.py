"""GPU configurations: the machine the timing model builds (configs/gpus/*.toml).

The TOML tree mirrors the unit tree: one table per registered unit, named as
the unit (``[core]``, ``[raster]``, ``[coalescer]``, ``[l2]``, ``[dram]``,
``[atomic]``, ``[rop]``, ``[blender]``, ``[scoreboard]``), plus ``[memory]``
(the partitions the memory units are spread over and the memory path),
``[runner]`` (the guards of the event model) and ``[sample]`` (the sampled
fidelity level). Every parameter is typed, documented and carries its unit;
all times are in cycles of the shader (core) clock, the one clock of the
model. Presets are selected by name (``--gpu gtx280``) or a file path; unknown
sections and keys and impossible values fail at load time naming the key
(gpusim.config). A unit registered later (a new memory level) brings its own
section, with its defaults, into every config.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from pathlib import Path

# importing the unit modules registers them and their config sections, in this order
from gpusim.hw import core, raster, memory, atomic, rop, blender, scoreboard, driver  # noqa: F401
from gpusim.config import build, build_overridden, load_toml, param, to_dict
from gpusim.errors import ConfigError
from gpusim.hw.memory import MemoryLevel
from gpusim.hw.unit import SECTIONS, UNITS, register_section

GPU_DIR = Path(__file__).resolve().parents[2] / "configs" / "gpus"
DEFAULT_GPU = "gtx280"


@dataclass(frozen=True)
class RunnerConfig:
    """Guards of the event model."""

    max_cycles: int = param(10**12, unit="cycles", doc="stop with an error past this many cycles", min=1)
    no_progress_cycles: int = param(1_000_000, unit="cycles", doc="fail with a diagnosis when no warp "
                                    "instruction completes for this long while no timed work is scheduled (a "
                                    "deadlock)", min=1)
    max_operations: int = param(50_000_000, unit="operations", doc="the most operations the event model "
                                "lowers at once (about 80 bytes each: 50 M is about 4 GiB); the full level "
                                "replays a larger run a chunk of passes at a time, each within it (refused: a "
                                "pass over it, more than 64 operations per fragment, an L2), the sampled level "
                                "refuses it; the analytic level has no such limit", min=1)
    trace_every: int = param(0, unit="cycles", doc="print a one-line trace of every unit's state to stderr "
                             "every this many cycles while a pass runs (0: never); for debugging a model", min=0)
    workers: int = param(0, unit="processes", doc="processes the event model replays passes in (passes are "
                         "barriers, so shares of them replay apart with identical results): 1 serial, N up to N, "
                         "0 one per available CPU when the run is large enough to gain", min=0)


@dataclass(frozen=True)
class SampleConfig:
    """The ``sampled`` fidelity level (gpusim.hw.sample): the event model on replicate stratified samples of the
    work, each on the GPU cut down to the sample's share of its SMs."""

    tile: int = param(8, unit="pixels", doc="edge of the screen tiles sampled (fragment and pixel threads)",
                      min=1, max=4096)
    fraction: float = param(0.03125, unit="1", doc="share of the GPU's SMs each replicate simulates, rounded to "
                            "whole SMs (at least one), and the share of the work it samples; 1: the full level",
                            gt=0, max=1)
    replicates: int = param(4, unit="samples", doc="disjoint replicate samples; the estimate is their mean, its "
                            "95% confidence interval from their spread (Student's t with replicates - 1 degrees "
                            "of freedom) and the scale check's bias; the level costs about replicates x fraction "
                            "of the full level (the check: 2 x fraction more)", min=2,
                            max=64)
    min_tiles: int = param(30, unit="tiles", doc="screen tiles with fragments a replicate samples at least: a run "
                           "with fewer than this many / fraction samples a larger share, on as many more SMs (all of "
                           "them, the run itself, for a run of at most replicates x this many tiles, where the "
                           "replicates would cost as much as the run)", min=1)
    thin: float = param(0.25, unit="1", doc="share of its SMs' work a replicate keeps where the run has enough "
                        "tiles (at least thin_min_tiles a replicate): the replicate then stands for the GPU on a "
                        "frame thinned to that share, and the work checks (replicates 0 and 1, and 2 and 3, together "
                        "on the same SMs, twice the share) extrapolate each pass's cycles linearly to the whole "
                        "work, the interval's degrees of freedom counting their slope's one (Welch-Satterthwaite); "
                        "shares over 0.5 thin nothing; 1: off", gt=0, max=1)
    thin_min_tiles: int = param(16, unit="tiles", doc="screen tiles with fragments a thinned replicate keeps at "
                                "least (and as many triangle blocks, where a software rasterizer's passes sample "
                                "them): the share it keeps is raised to keep them", min=1)
    seed: int = param(1, doc="random seed of the samples", min=0)
    scale_check: bool = param(True, doc="also run replicates 0 and 1's samples together on their SMs together "
                              "and widen the 95% interval by the bias of a replicate's machine size this gives "
                              "(a pass's end, its latest SM's, taken to grow as the log of the SMs); costs about "
                              "half of the replicates' event work more")
    run_traffic: bool = param(True, doc="set the memory partitions' load in the graphics pipeline's fragment "
                              "passes from the whole run's coalesced traffic, estimated from a sample of the run's "
                              "warps (traffic_share; on a GPU with an L2, from the whole run, lowered anyway to "
                              "warm it): a replicate packs "
                              "fragments of tiles far apart into its warps, which coalesce worse than the run's; "
                              "off, a replicate's traffic is scaled by its operations' bytes, quicker (the run's "
                              "lowering took half as long as the replicates on TFSS) but up to 7% over on the "
                              "fidelity-speed case")
    traffic_share: float = param(0.125, unit="1", doc="share of the run's warps the level lowers for its "
                                 "coalesced traffic (sample.run_traffic) in a fragment-shader pass packed in "
                                 "submission order: one warp at random of every round(1 / share) consecutive ones, "
                                 "the run's own warps; each partition's bytes in the pass are the run's memory load on "
                                 "it times their coalesced bytes per unit of their load there. A pass of fewer than "
                                 "2048 / share warps, or with a scoreboard, is lowered whole, and every pass where "
                                 "round(1 / share) is 1", gt=0, max=1)


register_section("runner", RunnerConfig)
register_section("sample", SampleConfig)


class GpuConfig:
    """A whole GPU: one config per section (``gpu.core``, ``gpu.dram``, ...), immutable.

    ``GpuConfig(name=..., core=CoreConfig(...))`` takes any registered section
    by keyword and the defaults for the others; :meth:`from_table` builds one
    from a TOML tree, :meth:`replace` changes sections, :meth:`to_dict`
    exports it.
    """

    def __init__(self, name: str = "custom", source: str = "", **sections):
        unknown = [k for k in sections if k not in SECTIONS]
        if unknown:
            raise ValueError(f"unknown GPU config section {unknown[0]!r} (valid: {', '.join(SECTIONS)})")
        values = {k: sections[k] if k in sections else cls() for k, cls in SECTIONS.items()}
        object.__setattr__(self, "name", name)
        object.__setattr__(self, "source", source)
        object.__setattr__(self, "sections", values)
        self._check()

    def __getattr__(self, key: str):
        sections = self.__dict__.get("sections")
        if sections is not None and key in sections:
            return sections[key]
        raise AttributeError(f"GpuConfig has no section {key!r}")

    def __setattr__(self, key, value):
        raise AttributeError("GpuConfig is immutable; use replace()")

    def __eq__(self, other) -> bool:
        return isinstance(other, GpuConfig) and self.to_dict() == other.to_dict()

    def __hash__(self) -> int:
        return hash(repr(self.to_dict()))

    def __repr__(self) -> str:
        return f"GpuConfig(name={self.name!r})"

    def __getstate__(self):
        return self.__dict__

    def __setstate__(self, state):
        self.__dict__.update(state)

    def replace(self, **sections) -> "GpuConfig":
        """A copy with the given sections replaced."""
        return GpuConfig(self.name, self.source, **(self.sections | sections))

    def to_dict(self) -> dict:
        return {"name": self.name, "source": self.source} | {k: to_dict(v) for k, v in self.sections.items()}

    @classmethod
    def from_table(cls, data: dict, where: str) -> "GpuConfig":
        """Build from a parsed TOML tree; errors name ``where`` and the dotted key."""
        if not isinstance(data, dict):
            raise ConfigError(f"{where}: expected a table")
        fields = ("name", "source", *SECTIONS)
        unknown = [k for k in data if k not in fields]
        if unknown:
            problem = f"unknown key (valid: {', '.join(fields)})"
            raise ConfigError(f"{where}: {unknown[0]}: {problem}", key=unknown[0], problem=problem)
        for key in ("name", "source"):
            if key in data and not isinstance(data[key], str):
                problem = f"expected a string, got {data[key]!r}"
                raise ConfigError(f"{where}: {key}: {problem}", key=key, problem=problem)
        sections = {k: build(SECTIONS[k], data[k], where, k) for k in SECTIONS if k in data}
        try:
            return cls(data.get("name", "custom"), data.get("source", ""), **sections)
        except ValueError as exc:
            raise ConfigError(f"{where}: {exc}", problem=str(exc)) from None

    def _check(self) -> None:
        """Checks across sections (each section checks its own fields)."""
        levels = self.memory.levels
        if not levels:
            raise ValueError("memory.levels: the memory path is empty; name its levels, e.g. "
                             "['coalescer', 'l2', 'dram']")
        for name in levels:
            if name not in UNITS or not issubclass(UNITS[name], MemoryLevel):
                valid = [n for n, c in UNITS.items() if issubclass(c, MemoryLevel)]
                raise ValueError(f"memory.levels: {name!r} is not a memory level (valid: {', '.join(valid)})")
        if len(set(levels)) != len(levels):
            raise ValueError(f"memory.levels: {list(levels)} names a level twice")
        if not UNITS[levels[0]].issued:
            raise ValueError(f"memory.levels: the first level must take the core's requests "
                             f"({levels[0]!r} does not; start with 'coalescer')")
        if not UNITS[levels[-1]].terminal:
            raise ValueError(f"memory.levels: the last level must be a memory ({levels[-1]!r} passes requests "
                             f"on; end with 'dram')")
        if self.scoreboard.entries < self.core.warp_size:
            raise ValueError(f"scoreboard.entries ({self.scoreboard.entries}) must be >= core.warp_size "
                             f"({self.core.warp_size}), or one warp could never be dispatched")
        slowest = max(self.dram.latency + self.l2.latency, self.atomic.latency, self.rop.latency,
                      self.core.pipeline_latency) + 2 * self.memory.interconnect_latency
        if self.runner.no_progress_cycles <= slowest:
            raise ValueError(f"runner.no_progress_cycles ({self.runner.no_progress_cycles}) must exceed the "
                             f"slowest latency of the machine ({slowest} cycles)")


def with_section(gpu: GpuConfig, section: str, **fields) -> GpuConfig:
    """``gpu`` with some fields of one section changed."""
    return gpu.replace(**{section: dataclasses.replace(getattr(gpu, section), **fields)})


def gpu_presets() -> list[str]:
    return sorted(p.stem for p in GPU_DIR.glob("*.toml"))


def preset_file(name: str) -> Path:
    """The file of the GPU preset ``name`` (configs/gpus/NAME.toml)."""
    return GPU_DIR / f"{name}.toml"


def load_gpu(spec: str | None = None, overrides: list[str] | None = None) -> GpuConfig:
    """A preset name (configs/gpus/NAME.toml) or a TOML file path; ``overrides`` are ``a.b=value``."""
    spec = spec or DEFAULT_GPU
    path = Path(spec)
    if not (spec.endswith(".toml") or path.is_file()):
        if spec not in gpu_presets():
            raise ConfigError(f"--gpu {spec}: unknown GPU preset (valid: {', '.join(gpu_presets())}, "
                              f"or a .toml file)")
        path = preset_file(spec)
    data = load_toml(path)
    if not data:
        raise ConfigError(f"{path}: the GPU file is empty; give at least one section such as [core] "
                          f"(start from a preset: {preset_file(DEFAULT_GPU)})")
    return build_overridden(GpuConfig.from_table, data, str(path), overrides or [], "--gpu-set",
                            "rop.reorder_entries=16")
