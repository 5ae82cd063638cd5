"""Front-to-back compositing of per-pixel fragment runs (shared by the reference and the schemes).

The fragments arrive grouped by pixel (each pixel's fragments contiguous, in the
order they are to be composited, nearest first). Per pixel:

    C = sum_i T_i * a_i * c_i,   T_0 = 1,   T_{i+1} = T_i * (1 - a_i),
    pixel = C + T_n * background

The loop runs over the position inside a run (vectorised over every pixel that
has at least that many fragments), so a pixel with thousands of layers costs
thousands of small vector steps, never a Python loop over fragments.
"""

from __future__ import annotations

import numpy as np


def run_starts(pix_sorted: np.ndarray) -> np.ndarray:
    """Start index of each run of equal values in a grouped pixel-id array (without ``np.r_``, whose
    per-call cost shows when the timing model's lowering calls this once per piece of thousands)."""
    if len(pix_sorted) == 0:
        return np.zeros(0, np.int64)
    change = np.empty(len(pix_sorted), bool)
    change[0] = True
    np.not_equal(pix_sorted[1:], pix_sorted[:-1], out=change[1:])
    return np.flatnonzero(change)


def runs_by_length(pix_sorted: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Runs of a grouped pixel-id array, longest first: (start, length, active).

    ``active[k]`` is the number of runs longer than k, so at rank k the runs
    ``0 .. active[k] - 1`` (a prefix) still have an element: ``start[:active[k]] + k``.
    Equal lengths keep ascending run order. ``pix_sorted`` must be non-empty.
    """
    start = run_starts(pix_sorted)
    length = np.diff(np.r_[start, len(pix_sorted)])
    by_length = np.argsort(-length, kind="stable")
    start, length = start[by_length], length[by_length]
    active = np.searchsorted(-length, -(np.arange(length[0]) + 1), side="right")
    return start, length, active


def composite_runs(pix: np.ndarray, rgb: np.ndarray, alpha: np.ndarray, pixel_count: int,
                   background, dtype=np.float64) -> np.ndarray:
    """Composite grouped runs front to back; returns (pixel_count, 3) in ``dtype``.

    ``pix`` (grouped, runs contiguous), ``rgb`` (N, 3) straight colour and
    ``alpha`` (N,) are in compositing order. Pixels without fragments show the
    background. ``dtype`` is the arithmetic precision (float32 models a GPU
    shader, float64 the reference).
    """
    bg = np.asarray(background, dtype=dtype)
    image = np.empty((pixel_count, 3), dtype=dtype)
    image[:] = bg
    if len(pix) == 0:
        return image
    alpha = np.asarray(alpha, dtype=dtype)
    weighted = np.asarray(rgb, dtype=dtype) * alpha[:, None]
    start, _, active = runs_by_length(pix)
    covered = pix[start]
    trans = np.ones(len(covered), dtype=dtype)
    colour = np.zeros((len(covered), 3), dtype=dtype)
    for k, m in enumerate(active):
        idx = start[:m] + k
        colour[:m] += trans[:m, None] * np.take(weighted, idx, axis=0)   # rows: faster than weighted[idx]
        trans[:m] *= 1 - alpha[idx]   # python scalar: stays in dtype
    image[covered] = colour + trans[:, None] * bg
    return image
