"""Timing models: *when* a scheme's operations happen (cycles).

Fidelity levels are selected by name (``gpusim replay --fidelity NAME``):

* ``thesis``: the execution-time model of seed 003 section 4.3.2 (one cycle per
  counted memory access plus the per-pixel compute cycles of [Amor06]), for
  the three schemes that thesis compares (gpusim.hw.thesis).
"""

from gpusim.hw.thesis import THESIS_RULES, thesis_timing

FIDELITIES = {"thesis": thesis_timing}

__all__ = ["FIDELITIES", "THESIS_RULES", "thesis_timing"]
