"""Per-pixel sorts of a resolve pass: insertion sort and bitonic sort, vectorised over pixels.

Both produce ascending depth order; they differ in what they do with *equal*
depths and in how many compare operations they cost:

* insertion sort is stable: equal depths keep the order they were loaded in.
  Compares for n keys = (n - 1) + inversions - (number of keys that move all
  the way to the front), counted exactly.
* bitonic sort is a fixed network on the next power of two m >= n (padding
  with +infinity): (m / 2) * log2(m) * (log2(m) + 1) / 2 compare-exchanges per
  pixel whatever the data. It is not stable; the order it gives equal depths is
  computed by running the network itself, so ties land where a GPU would put them.
  A pixel whose keys are all distinct comes out in the one ascending order, so
  the network runs only for the pixels with equal keys.

Pixels are processed in classes of equal padded size m, each as one (pixels, m) array.
"""

from __future__ import annotations

import numpy as np

from gpusim.metrics.composite import run_starts
from gpusim.schemes.common.arrays import sort_within_runs

_PAD = np.uint64(1) << np.uint64(40)


def _classes(pix: np.ndarray, only: np.ndarray | None = None):
    """Yield (m, run starts, run lengths, runs in the class) per power-of-two class of run length.

    ``only`` (a bool per run) keeps those runs in the starts and lengths; the count of runs
    in the class counts every run.
    """
    start = run_starts(pix)
    length = np.diff(np.r_[start, len(pix)])
    m = np.ones_like(length)
    big = length > 1
    m[big] = 1 << np.ceil(np.log2(length[big])).astype(np.int64)
    for size in np.unique(m):
        sel = m == size
        runs = int(np.count_nonzero(sel))
        if only is not None:
            sel &= only
        yield int(size), start[sel], length[sel], runs


def _matrix(values: np.ndarray, start: np.ndarray, length: np.ndarray, m: int, pad):
    cols = np.arange(m)
    valid = cols[None, :] < length[:, None]
    idx = np.where(valid, start[:, None] + cols[None, :], 0)
    mat = np.where(valid, values[idx], pad)
    return mat, valid, idx


def sort_runs(pix: np.ndarray, key: np.ndarray, method: str) -> tuple[np.ndarray, int]:
    """Permutation sorting each run of ``pix`` (grouped) by ``key``, and the compare count.

    ``key`` is uint32 depth keys in load order. Returns (``perm``, ``compares``):
    ``perm`` indexes the input so that ``key[perm]`` is ascending inside every run.
    """
    n = len(pix)
    if method == "insertion":
        perm = sort_within_runs(pix, key)   # stable: equal depths keep load order
        return perm, _insertion_compares(pix, key)
    if method != "bitonic":
        raise ValueError(f"unknown sort {method!r} (valid: insertion, bitonic)")
    perm = sort_within_runs(pix, key)           # the network's order wherever a run's keys are distinct
    ordered = key[perm]
    tie = np.flatnonzero((pix[1:] == pix[:-1]) & (ordered[1:] == ordered[:-1]))   # runs stay in place
    run = np.cumsum(np.r_[True, pix[1:] != pix[:-1]]) - 1 if n else np.zeros(0, np.int64)
    has_tie = np.zeros(int(run[-1]) + 1 if n else 0, bool)
    has_tie[run[tie]] = True
    compares = 0
    for m, start, length, runs in _classes(pix, has_tie):
        if m == 1:
            continue
        stages = int(np.log2(m)) * (int(np.log2(m)) + 1) // 2
        compares += runs * (m // 2) * stages
        if len(start) == 0:
            continue
        mat, valid, idx = _matrix(key.astype(np.uint64), start, length, m, _PAD)
        pos = np.broadcast_to(np.arange(m), mat.shape).copy()
        k = 2
        while k <= m:
            j = k // 2
            while j >= 1:
                i = np.arange(m)
                lo = i[(i ^ j) > i]
                hi = lo ^ j
                asc = (lo & k) == 0
                a, b = mat[:, lo], mat[:, hi]
                swap = np.where(asc[None, :], a > b, a < b)
                mat[:, lo], mat[:, hi] = np.where(swap, b, a), np.where(swap, a, b)
                pa, pb = pos[:, lo], pos[:, hi]
                pos[:, lo], pos[:, hi] = np.where(swap, pb, pa), np.where(swap, pa, pb)
                j //= 2
            k *= 2
        # padding sorts last (its key is above every depth key): the first `length` are real
        src = start[:, None] + pos
        perm_rows = np.where(valid, src, -1)
        dest = np.where(valid, idx, -1)
        perm[dest[valid]] = perm_rows[valid]
    return perm, compares


def _insertion_compares(pix: np.ndarray, key: np.ndarray) -> int:
    compares = 0
    top = np.iinfo(key.dtype).max if key.dtype.kind in "iu" else None
    # padding above every key is never greater than a later entry nor below an earlier one: no mask
    masked = top is None or (len(key) and key.max() == top)
    for m, start, length, _ in _classes(pix):
        if m == 1:
            continue
        mat, valid, _ = _matrix(key, start, length, m, key.dtype.type(0) if masked else key.dtype.type(top))
        inversions = 0
        for d in range(1, m):
            later = mat[:, :-d] > mat[:, d:]
            if masked:       # valid[:, :-d] is implied where the later one is valid
                later &= valid[:, d:]
            inversions += int(np.count_nonzero(later))
        # keys strictly below every earlier key walk to the front: their last compare is skipped
        prior_min = np.minimum.accumulate(mat, axis=1)[:, :-1]
        front = mat[:, 1:] < prior_min
        if masked:
            front &= valid[:, 1:]
        compares += int((length - 1).sum()) + inversions - int(np.count_nonzero(front))
    return compares
