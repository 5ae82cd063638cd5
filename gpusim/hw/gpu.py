"""GPU configurations: the machine the timing model builds (configs/gpus/*.toml).

The TOML tree mirrors the unit tree (``[core]``, ``[memory]``, ``[l2]``,
``[dram]``, ``[atomic]``, ``[rop]``, ``[blender]``, ``[scoreboard]``,
``[runner]``). Every parameter is typed, documented and carries its unit; all
times are in cycles of the shader (core) clock, the one clock of the model.
Presets are selected by name (``--gpu gtx280``) or a file path; unknown keys
and impossible values fail at load time naming the key (gpusim.config).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Literal

from gpusim.config import apply_overrides, build, load_toml, param, to_dict
from gpusim.errors import ConfigError

GPU_DIR = Path(__file__).resolve().parents[2] / "configs" / "gpus"
DEFAULT_GPU = "gtx280"


@dataclass(frozen=True)
class CoreConfig:
    """SIMT cores (streaming multiprocessors) and their warp schedulers."""

    sms: int = param(30, unit="SMs", doc="streaming multiprocessors", min=1)
    warp_size: int = param(32, unit="threads", doc="threads per warp", min=1, max=1024)
    lanes_per_sm: int = param(8, unit="lanes", doc="scalar lanes per SM (a warp instruction issues over "
                              "warp_size / lanes_per_sm cycles)", min=1)
    warps_per_sm: int = param(32, unit="warps", doc="resident warps per SM (latency hiding)", min=1)
    clock_mhz: float = param(1296.0, unit="MHz", doc="shader clock: the model's cycle", gt=0)
    instructions_per_op: int = param(4, unit="instructions", doc="ALU instructions a thread issues per memory "
                                     "operation (address arithmetic, the shader or rasterizer work around it)",
                                     min=0)
    thread_mapping: Literal["auto", "fragment", "triangle"] = param(
        "auto", doc="thread of a geometry pass: one per fragment, one per triangle (FreePipe: the thread "
                    "rasterizes its triangle and issues its fragments' operations in turn), or auto "
                    "(triangle for software-pipeline passes, fragment for the graphics pipeline)")
    pipeline_latency: int = param(200, unit="cycles", doc="cycles to drain the pipeline at a flush "
                                  "(a pass boundary that waits for all work)", min=0)

    @property
    def issue_cycles(self) -> int:
        """Cycles one warp instruction occupies the SM's issue port."""
        return -(-self.warp_size // self.lanes_per_sm)


@dataclass(frozen=True)
class RasterConfig:
    """Primitive processing: the fixed-function rasterizer, or a software one in the threads."""

    triangles_per_cycle: float = param(0.46, unit="triangles/cycle", doc="fixed-function setup and raster "
                                       "rate: a graphics-pipeline geometry pass sends every triangle through "
                                       "it, and a warp starts once its fragments' triangles are rasterized", gt=0)
    setup_instructions: int = param(40, unit="instructions", doc="per-triangle setup a software-rasterizer "
                                    "thread issues before its fragments (triangle thread mapping)", min=0)


@dataclass(frozen=True)
class MemoryConfig:
    """Memory partitions: address interleaving and the core-partition interconnect."""

    partitions: int = param(8, unit="partitions", doc="memory partitions (each one L2 slice, one DRAM "
                            "channel and one atomic unit)", min=1)
    interleave_bytes: int = param(256, unit="bytes", doc="address interleave granularity across partitions",
                                  min=1)
    segment_bytes: int = param(64, unit="bytes", doc="coalescing segment: a warp's accesses to one segment "
                               "become one request", min=1)
    interconnect_latency: int = param(20, unit="cycles", doc="core to partition latency (each way)", min=0)


@dataclass(frozen=True)
class L2Config:
    """One L2 slice per partition (set-associative, LRU, write-allocate)."""

    size_bytes: int = param(0, unit="bytes", doc="capacity per slice (0: no L2; requests go to DRAM)", min=0)
    line_bytes: int = param(128, unit="bytes", doc="line size", min=1)
    ways: int = param(16, unit="ways", doc="associativity", min=1)
    latency: int = param(100, unit="cycles", doc="hit latency", min=0)
    bytes_per_cycle: float = param(64.0, unit="bytes/cycle", doc="slice bandwidth", gt=0)


@dataclass(frozen=True)
class DramConfig:
    """One DRAM channel per partition."""

    bytes_per_cycle: float = param(13.67, unit="bytes/cycle", doc="channel bandwidth per shader cycle", gt=0)
    latency: int = param(400, unit="cycles", doc="access latency (row activation, CAS, return)", min=0)


@dataclass(frozen=True)
class AtomicConfig:
    """Atomic unit in each partition."""

    latency: int = param(500, unit="cycles", doc="latency of one atomic (read, modify, write at the partition)",
                         min=0)
    ops_per_cycle: float = param(1.0, unit="ops/cycle", doc="atomic throughput per partition", gt=0)
    same_address_cycles: int = param(60, unit="cycles", doc="occupancy of one address by one atomic: "
                                     "operations on the same address serialize at this interval", min=1)


@dataclass(frozen=True)
class RopConfig:
    """ROP units with a reorder buffer (fixed-function blend, depth test, stencil)."""

    units: int = param(32, unit="ROPs", doc="ROP units (pixels interleaved across them by address)", min=1)
    reorder_entries: int = param(64, unit="fragments", doc="reorder-buffer entries per ROP unit; a full "
                                 "buffer stalls the core", min=1)
    ops_per_cycle: float = param(0.5, unit="fragments/cycle", doc="operations committed per ROP unit per "
                                 "shader cycle", gt=0)
    latency: int = param(100, unit="cycles", doc="latency from commit to the framebuffer write landing", min=0)


@dataclass(frozen=True)
class BlenderConfig:
    """Programmable blender at the ROP (k-buffer proposal 2, seed 004 section 3.1.2)."""

    cycles_per_op: int = param(8, unit="cycles", doc="program cycles per invocation (one fragment)", min=1)
    bytes_per_cycle: float = param(16.0, unit="bytes/cycle", doc="k-buffer data streamed through the "
                                   "blender per cycle", gt=0)


@dataclass(frozen=True)
class ScoreboardConfig:
    """Scoreboard at fragment dispatch (k-buffer proposal 1, seed 004 section 3.1.1)."""

    entries: int = param(1024, unit="cells", doc="cells of the coarse in-flight image that can be held", min=1)
    granularity: int = param(1, unit="pixels", doc="cell edge: a cell covers granularity x granularity pixels",
                             min=1)


@dataclass(frozen=True)
class RunnerConfig:
    """Guards of the event model."""

    max_cycles: int = param(10**12, unit="cycles", doc="stop with an error past this many cycles", min=1)
    no_progress_cycles: int = param(1_000_000, unit="cycles", doc="fail with a diagnosis when no warp "
                                    "instruction completes for this long", min=1)
    workers: int = param(0, unit="processes", doc="processes the event model replays passes in (passes are "
                         "barriers, so shares of them replay apart with identical results): 1 serial, N up to N, "
                         "0 one per available CPU when the run is large enough to gain", min=0)


@dataclass(frozen=True)
class SampleConfig:
    """The ``sampled`` fidelity level: the event model on a sample of screen tiles."""

    tile: int = param(32, unit="pixels", doc="tile edge", min=1)
    fraction: float = param(0.125, unit="1", doc="share of non-empty tiles simulated", gt=0, max=1)
    seed: int = param(1, doc="random seed of the tile sample", min=0)


@dataclass(frozen=True)
class GpuConfig:
    """A whole GPU: the unit tree of the timing model."""

    name: str = param("custom", doc="machine name")
    source: str = param("", doc="where the figures come from")
    core: CoreConfig = field(default_factory=CoreConfig)
    raster: RasterConfig = field(default_factory=RasterConfig)
    memory: MemoryConfig = field(default_factory=MemoryConfig)
    l2: L2Config = field(default_factory=L2Config)
    dram: DramConfig = field(default_factory=DramConfig)
    atomic: AtomicConfig = field(default_factory=AtomicConfig)
    rop: RopConfig = field(default_factory=RopConfig)
    blender: BlenderConfig = field(default_factory=BlenderConfig)
    scoreboard: ScoreboardConfig = field(default_factory=ScoreboardConfig)
    runner: RunnerConfig = field(default_factory=RunnerConfig)
    sample: SampleConfig = field(default_factory=SampleConfig)

    def __post_init__(self):
        if self.l2.size_bytes and self.l2.size_bytes % (self.l2.line_bytes * self.l2.ways):
            raise ValueError(f"l2.size_bytes ({self.l2.size_bytes}) must be a multiple of "
                             f"l2.line_bytes x l2.ways ({self.l2.line_bytes * self.l2.ways})")
        if self.scoreboard.entries < self.core.warp_size:
            raise ValueError(f"scoreboard.entries ({self.scoreboard.entries}) must be >= core.warp_size "
                             f"({self.core.warp_size}), or one warp could never be dispatched")
        slowest = max(self.dram.latency + self.l2.latency, self.atomic.latency, self.rop.latency,
                      self.core.pipeline_latency) + 2 * self.memory.interconnect_latency
        if self.runner.no_progress_cycles <= slowest:
            raise ValueError(f"runner.no_progress_cycles ({self.runner.no_progress_cycles}) must exceed the "
                             f"slowest latency of the machine ({slowest} cycles)")

    def to_dict(self) -> dict:
        return to_dict(self)


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
    data = apply_overrides(load_toml(path), overrides or [])
    return build(GpuConfig, data, str(path))
