"""Object-space reordering heuristics applied to a trace before a scheme sees it.

The k-buffer paper (seed 004 section 3.2) sorts primitives by centroid depth and
renders them in batches with a pipeline flush between. A trace has no vertices,
so a primitive's centroid depth here is the mean depth of its fragments (the
depth at the centroid of the samples it covers); fragments of a primitive keep
their order.
"""

from __future__ import annotations

import numpy as np

from gpusim.schemes.common.arrays import lex_order, unique_ids
from gpusim.trace import FragmentTrace


def centroid_order(trace: FragmentTrace) -> np.ndarray:
    """Fragment permutation: primitives front to back by centroid depth (ties: submission)."""
    n = len(trace)
    if n == 0:
        return np.zeros(0, np.int64)
    prims, first, inverse = unique_ids(trace.prim)
    depth_sum = np.bincount(inverse, weights=trace.z.astype(np.float64), minlength=len(prims))
    count = np.bincount(inverse, minlength=len(prims))
    prim_rank = np.empty(len(prims), np.int64)
    prim_rank[np.lexsort((first, depth_sum / count))] = np.arange(len(prims))
    return lex_order(prim_rank[inverse])


def submitted_primitives(trace: FragmentTrace) -> int:
    """Primitives the scene submitted: the trace's ``primitives`` metadata (the rasterizer's count, primitives
    that cover no pixel included) when it covers the primitive ids, else the highest id + 1."""
    seen = int(trace.prim.max()) + 1 if len(trace) else 0
    meta = trace.meta.get("primitives")
    return max(seen, int(meta)) if isinstance(meta, (int, np.integer)) and not isinstance(meta, bool) else seen


def batch_plan(trace: FragmentTrace, batch_size: int, centroid: bool) -> tuple[np.ndarray, np.ndarray]:
    """(batch of each fragment, primitives submitted in each batch): every submitted primitive in batches of
    ``batch_size`` (seed 004 section 5: "all the triangles ... 32 triangles per batch"), those that cover no
    pixel included. ``trace`` is in submission order: with ``centroid`` its fragments are grouped by primitive
    front to back (:func:`centroid_order`), and the primitives that cover no pixel, whose depth the trace does
    not hold, are spread evenly through that order; otherwise a primitive's batch is its id // ``batch_size``."""
    submitted = submitted_primitives(trace)
    n_batches = -(-submitted // batch_size)
    prims = np.minimum(batch_size, submitted - batch_size * np.arange(n_batches))
    if not len(trace):
        return np.zeros(0, np.int64), prims
    if centroid:
        prim = trace.prim
        rank = np.cumsum(np.r_[True, prim[1:] != prim[:-1]]) - 1      # among the primitives with fragments
        slot = rank * submitted // (int(rank[-1]) + 1)
    else:
        slot = trace.prim.astype(np.int64)
    return slot // batch_size, prims
