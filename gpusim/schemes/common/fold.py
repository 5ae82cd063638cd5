"""Per-pixel sequential updates in submission order (ROP blending), vectorised over pixels.

``fold`` applies ``step(state_rows, positions)`` once per arrival rank: at rank j
every pixel with more than j fragments updates its state with its j-th
fragment, found at those positions of the arrival order (``by_arrival[positions]``
are the fragments; a step reads arrays gathered into arrival order once, so a
trace in random order costs no random gather per step). This is how
fixed-function blending with per-step rounding (an RGBA8 framebuffer, an
RGBA16F accumulation target) is reproduced exactly without a Python loop over
fragments.
"""

from __future__ import annotations

from typing import Callable

import numpy as np

from gpusim.metrics.composite import runs_by_length
from gpusim.schemes.common.arrays import put_rows


def fold(pix: np.ndarray, by_arrival: np.ndarray, state: np.ndarray,
         step: Callable[[np.ndarray, np.ndarray], np.ndarray]) -> np.ndarray:
    """Update ``state`` (indexed by pixel id) with each pixel's fragments in arrival order.

    ``step(state_rows, positions)`` gets positions into ``by_arrival``, not fragment indices.
    """
    if len(by_arrival) == 0:
        return state
    pix_sorted = pix[by_arrival]
    start, _, active = runs_by_length(pix_sorted)
    covered = pix_sorted[start]
    for j, m in enumerate(active):
        rows = covered[:m]
        put_rows(state, rows, step(np.take(state, rows, axis=0), start[:m] + j))
    return state

