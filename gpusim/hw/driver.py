"""The driver: the time between the passes it issues.

Each pass of a scheme is one draw call (a geometry pass, a full-screen quad,
a clear) or one kernel launch (a compute pass of a software pipeline), issued
by the CPU-side driver with the state changes around it (render targets,
shaders, a flush). ``driver.pass_us`` is that cost, paid once per pass before
its work starts; the GPU is idle meanwhile. A multi-pass scheme pays it per
pass, the k-buffer's batching heuristic twice per batch (the batch's draw
call and its flushing full-screen quad, which then drains the pipeline).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from gpusim.config import param
from gpusim.hw.unit import register_section


@dataclass(frozen=True)
class DriverConfig:
    """CPU-side cost of issuing passes."""

    pass_us: float = param(5.0, unit="microseconds", doc="time from one pass's end to the next pass's start: "
                           "the draw call or kernel launch and its state changes", min=0, max=1e6)


register_section("driver", DriverConfig)


def pass_overhead_cycles(gpu) -> int:
    """Cycles of the GPU's clock between passes (``driver.pass_us``)."""
    return math.ceil(gpu.driver.pass_us * gpu.core.clock_mhz)
