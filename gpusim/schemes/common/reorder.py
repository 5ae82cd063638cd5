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


def batch_index(trace: FragmentTrace, order: np.ndarray, batch_size: int) -> np.ndarray:
    """Batch number of each fragment (in ``order``): batches of ``batch_size`` primitives in order."""
    prim = trace.prim[order]
    new_prim = np.r_[True, prim[1:] != prim[:-1]] if len(prim) else np.zeros(0, bool)
    prim_seq = np.cumsum(new_prim) - 1
    return prim_seq // batch_size


def batch_primitives(trace: FragmentTrace, batches: np.ndarray, n_batches: int) -> np.ndarray:
    """Primitives in each batch (``batches``: each fragment's batch, fragments in submission order)."""
    new_prim = np.r_[True, trace.prim[1:] != trace.prim[:-1]] if len(trace) else np.zeros(0, bool)
    return np.bincount(batches[new_prim], minlength=n_batches)


def permuted(trace: FragmentTrace, order: np.ndarray) -> FragmentTrace:
    """The trace with its fragments in ``order``."""
    return FragmentTrace(trace.x[order], trace.y[order], trace.z[order], trace.rgba[order],
                         trace.prim[order], trace.opaque[order], trace.width, trace.height,
                         dict(trace.meta), trace.source)
