"""Timing models: *when* a scheme's operations happen, in cycles of a modelled GPU.

Fidelity levels are selected by name (``FIDELITIES``, ``gpusim replay
--fidelity NAME``); each is a function ``(result, trace, gpu, reference) ->
(record, image or None)``:

* ``analytic``: per-pass bounds from work / throughput and latency chains
  (gpusim.hw.analytic), no events;
* ``sampled``: the event model on replicate stratified samples of the work,
  each on the GPU cut down to the sample's share of its SMs; their mean, and
  a 95% confidence interval from their spread (gpusim.hw.sample);
* ``full``: the event model on every operation, with RMW hazards replayed into
  the image;
* ``thesis``: the execution-time model of seed 003 section 4.3.2
  (gpusim.hw.thesis), for the three schemes that thesis compares.

The event model
---------------

Lowering (gpusim.hw.lower) turns the scheme's OpPlan (gpusim.opplan) into a
program (gpusim.hw.program): per pass, warps of thread programs of typed
instructions. A :class:`~gpusim.hw.machine.Machine` is assembled from the
registered units the program reaches and runs it pass by pass on one
``simpy.Environment``, the only event kernel and clock.

Granularity: one simpy process per resident-warp slot of each SM
(gpusim.hw.core) runs its warps one after the other; a process yields a
simpy event only where its warp waits (for a result it depends on, for the
SM's issue port, for a unit that cannot take it yet, for the rasterizer).
Units are *timestamp servers*: serving an instruction is arithmetic on the
unit's free time (``max(arrival, free) + service``), done at the cycle the
instruction issues, so requests reach every unit in time order and an
instruction that need not wait costs no event at all. A unit that must hold
a warp back (a full reorder buffer, a busy scoreboard cell) hands it a
``simpy.Event`` that it triggers when the condition clears.

The unit interface
------------------

A unit is one class, registered by name (gpusim.hw.unit), with

* ``name`` and ``Config``: its registry name and TOML section, and the
  section's dataclass (every field typed, with unit, bounds and description);
* ``issued`` / ``reached``: the operations the core sends it, or that reach it
  through another unit; the machine builds it only when the program issues one
  (``needed``);
* ``__init__(config, machine)``: build from its section and
  ``machine.program``;
* ``serve(wi, now)``: serve warp instruction ``wi`` at cycle ``now``; the cycle
  the result is back, or a simpy event to wait for before issuing again;
* ``idle_at()``: the cycle it has finished its work (passes are barriers);
* ``STATS`` and ``values(total_cycles)``: its declared stats (name, unit of
  measure, description) and their values per instance, which the run turns
  into one long table (unit path, stat, labels, value, unit).

Memory levels (gpusim.hw.memory) are units with a ``next`` level, chained in
``memory.levels`` order; they serve requests rather than instructions.

A worked example: a texture cache in front of the L2, as a memory level that
adds a fixed hit latency to every request (a module of its own)::

    from dataclasses import dataclass
    from gpusim.config import param
    from gpusim.hw.memory import MemoryLevel
    from gpusim.hw.unit import FP, register_unit

    @dataclass(frozen=True)
    class TextureCacheConfig:
        latency: int = param(20, unit="cycles", doc="lookup latency", min=0)

    @register_unit
    class TextureCache(MemoryLevel):
        name = "texture_cache"          # its TOML section: [texture_cache]
        Config = TextureCacheConfig

        def __init__(self, config, machine):
            super().__init__(machine)   # one instance per partition; self.next
            self.latency = config.latency

        def access(self, wi, arrive_fp, starts):
            self.requests[0] += 1
            return self.next.access(wi, arrive_fp + self.latency * FP, starts)

A GPU config then names it on the path, ``memory.levels = ["coalescer",
"texture_cache", "l2", "dram"]``, and may set ``[texture_cache] latency``;
nothing else changes. ``tests/test_hw_units.py`` adds such a level from the
test file alone.
"""

from gpusim.hw.gpu import DEFAULT_GPU, GpuConfig, gpu_presets, load_gpu
from gpusim.hw.lower import Workload
from gpusim.hw.thesis import THESIS_RULES, thesis_timing
from gpusim.hw.timing import FIDELITIES

__all__ = ["DEFAULT_GPU", "FIDELITIES", "GpuConfig", "THESIS_RULES", "Workload", "gpu_presets", "load_gpu",
           "thesis_timing"]
