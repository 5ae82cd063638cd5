"""Primitive processing: the fixed-function rasterizer of the graphics pipeline.

A geometry pass of the graphics pipeline gets its fragments from the
rasterizer (``raster.triangles_per_cycle``): a warp starts once the triangles
of its fragments are rasterized, and the pass lasts at least as long as
rasterizing every triangle it submits (each depth-peeling pass pays the whole
scene again; a batch of the k-buffer's heuristic only its own). A software
rasterizer (the ``triangle`` thread mapping, FreePipe) instead runs in the
threads: lowering gives each warp a Compute instruction of
``raster.setup_instructions`` per triangle (gpusim.hw.lower).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from gpusim.config import param
from gpusim.hw.unit import FP, Unit, occupancy_stats, register_unit


@dataclass(frozen=True)
class RasterConfig:
    """Primitive processing: the fixed-function rasterizer, or a software one in the threads."""

    triangles_per_cycle: float = param(0.46, unit="triangles/cycle", doc="fixed-function setup and raster "
                                       "rate: a graphics-pipeline geometry pass sends every triangle through "
                                       "it, and a warp starts once its fragments' triangles are rasterized", gt=0)
    setup_instructions: int = param(40, unit="instructions", doc="per-triangle setup a software-rasterizer "
                                    "thread issues before its fragments (triangle thread mapping)", min=0)


@register_unit
class Rasterizer(Unit):
    """The fixed-function rasterizer; built when a pass's warps come from it."""

    name = "raster"
    Config = RasterConfig
    STATS = occupancy_stats("cycles spent rasterizing the submitted triangles", "triangles",
                            "triangles rasterized")

    def __init__(self, config: RasterConfig, machine):
        super().__init__(1)
        self.rate = config.triangles_per_cycle
        triangles = sum(p.triangles for p in machine.program.passes if p.warp_triangles is not None)
        self.requests = [triangles]
        self.busy_fp = [math.ceil(triangles * FP / self.rate)]

    @classmethod
    def needed(cls, program, gpu) -> bool:
        return any(p.warp_triangles is not None for p in program.passes)

    def warp_ready(self, p, start: int) -> list | None:
        """The cycle each warp of pass ``p`` may start (its fragments' triangles rasterized), or None when
        the pass does not come through the rasterizer."""
        if p.warp_triangles is None:
            return None
        return (start + np.ceil(p.warp_triangles / self.rate).astype(np.int64)).tolist()

    def pass_floor(self, p, start: int) -> int:
        """The earliest cycle pass ``p`` can end: every triangle it submits rasterized."""
        return start + math.ceil(p.triangles / self.rate) if p.warp_triangles is not None else start
