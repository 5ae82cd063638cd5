"""The programmable blender at each ROP unit (k-buffer proposal 2, seed 004 section 3.1.2).

A ``program_blend`` operation runs the blending program on the pixel's
entries at the ROP unit of its address, in the ROP's commit order: it takes
``blender.cycles_per_op`` plus ``bytes / blender.bytes_per_cycle`` cycles of
that unit. The ROP unit (gpusim.hw.rop) orders the operations; the blender
says how long each one takes.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from gpusim.config import param
from gpusim.hw.unit import FP, Unit, interleave, occupancy_stats, register_unit


@dataclass(frozen=True)
class BlenderConfig:
    """Programmable blender at the ROP (k-buffer proposal 2, seed 004 section 3.1.2)."""

    cycles_per_op: int = param(8, unit="cycles", doc="program cycles per invocation (one fragment)", min=1)
    bytes_per_cycle: float = param(16.0, unit="bytes/cycle", doc="k-buffer data streamed through the "
                                   "blender per cycle", gt=0)


@register_unit
class Blender(Unit):
    """One blender per ROP unit."""

    name = "blender"
    Config = BlenderConfig
    reached = frozenset({"program_blend"})
    parent = "rop"
    STATS = occupancy_stats("cycles the blender ran programs", "invocations", "blending programs run")

    def __init__(self, config: BlenderConfig, machine):
        super().__init__(machine.gpu.rop.units)
        self.config = config
        self.interleave = machine.gpu.memory.interleave_bytes

    def service_fp(self, nbytes: np.ndarray, address: np.ndarray) -> np.ndarray:
        """Sub-cycles each invocation holds its ROP unit (``nbytes`` of entries each); counted as the blender's
        work on the unit of each ``address``."""
        c = self.config
        cost = c.cycles_per_op * FP + np.ceil(nbytes * FP / c.bytes_per_cycle).astype(np.int64)
        unit = interleave(address, self.interleave, self.instances)
        self.busy_fp = (np.asarray(self.busy_fp) + np.bincount(unit, weights=cost, minlength=self.instances)
                        ).astype(np.int64).tolist()
        self.requests = (np.asarray(self.requests) + np.bincount(unit, minlength=self.instances)).tolist()
        return cost
