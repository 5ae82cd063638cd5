"""Per-pixel sequential updates in submission order (ROP blending), vectorised over pixels.

``fold`` applies ``step(state_rows, fragments)`` once per arrival rank: at rank j
every pixel with more than j fragments updates its state with its j-th
fragment. This is how fixed-function blending with per-step rounding (an RGBA8
framebuffer, an RGBA16F accumulation target) is reproduced exactly without a
Python loop over fragments.
"""

from __future__ import annotations

from typing import Callable

import numpy as np

from gpusim.metrics.composite import runs_by_length


def fold(pix: np.ndarray, by_arrival: np.ndarray, state: np.ndarray,
         step: Callable[[np.ndarray, np.ndarray], np.ndarray]) -> np.ndarray:
    """Update ``state`` (indexed by pixel id) with each pixel's fragments in arrival order."""
    if len(by_arrival) == 0:
        return state
    pix_sorted = pix[by_arrival]
    start, _, active = runs_by_length(pix_sorted)
    covered = pix_sorted[start]
    for j, m in enumerate(active):
        rows = covered[:m]
        state[rows] = step(state[rows], by_arrival[start[:m] + j])
    return state


def rounder(fmt: str) -> Callable[[np.ndarray], np.ndarray]:
    """Round float32 values to what a render target of format ``fmt`` stores."""
    if fmt in ("rgba8", "r8"):
        return lambda v: (np.rint(np.clip(v, 0, 1) * np.float32(255.0)) / np.float32(255.0)).astype(np.float32)
    if fmt in ("rgba16f", "r16f"):
        def half(v):
            with np.errstate(over="ignore"):        # past 65504 a half target holds +inf, as hardware does
                return v.astype(np.float16).astype(np.float32)
        return half
    if fmt in ("rgba32f", "r32f"):
        return lambda v: v.astype(np.float32)
    raise ValueError(f"unknown render-target format {fmt!r}")
