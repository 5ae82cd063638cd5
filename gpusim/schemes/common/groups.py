"""Per-pixel views of a trace that every scheme needs: arrival order and depth order.

All arrays are computed once, vectorised, and only when first asked for.
Fragments are numbered in submission order (the order the scheme sees them,
after any reordering it applies).
"""

from __future__ import annotations

from functools import cached_property

import numpy as np

from gpusim.schemes.common.arrays import lex_sorted, pixel_key, rank_in_runs
from gpusim.schemes.common.depthkey import depth_key
from gpusim.schemes.common.storage import effective_alpha
from gpusim.trace import FragmentTrace


class PixelGroups:
    """Arrival and depth order of the fragments of each pixel."""

    def __init__(self, trace: FragmentTrace):
        self.trace = trace
        self.n = len(trace)
        self.pixel_count = trace.pixel_count

    @cached_property
    def pix(self) -> np.ndarray:
        """Pixel id of each fragment (int64)."""
        return self.trace.pixel_ids()

    @cached_property
    def key(self) -> np.ndarray:
        """Ordered uint32 depth key of each fragment (gpusim.schemes.common.depthkey)."""
        return depth_key(self.trace.z)

    @cached_property
    def alpha(self) -> np.ndarray:
        return effective_alpha(self.trace.rgba, self.trace.opaque)

    @cached_property
    def count(self) -> np.ndarray:
        """Fragments per pixel, (pixel_count,) int64."""
        return np.bincount(self.pix, minlength=self.pixel_count)

    @cached_property
    def covered(self) -> int:
        return int(np.count_nonzero(self.count))

    @cached_property
    def by_arrival(self) -> np.ndarray:
        """Fragment indices grouped by pixel (ascending), submission order inside a pixel."""
        return self._arrival[0]

    @cached_property
    def pix_by_arrival(self) -> np.ndarray:
        """``pix[by_arrival]``: the pixel ids ascending."""
        return self._arrival[1]

    @cached_property
    def _arrival(self) -> tuple[np.ndarray, np.ndarray]:
        return lex_sorted(self.pix)

    @cached_property
    def arrival(self) -> np.ndarray:
        """0-based arrival rank of each fragment at its pixel (the j-1 of 'j-th fragment')."""
        rank = np.empty(self.n, np.int64)
        rank[self.by_arrival] = self.arrival_by_arrival
        return rank

    @cached_property
    def arrival_by_arrival(self) -> np.ndarray:
        """``arrival[by_arrival]``: 0, 1, ... through each pixel's fragments."""
        return rank_in_runs(self.pix_by_arrival)

    def first_arrivals(self, limit: int) -> tuple[np.ndarray, np.ndarray]:
        """Each pixel's first ``limit`` fragments, grouped by pixel in arrival order, and their pixel ids."""
        first = self.arrival_by_arrival < limit
        return self.by_arrival[first], self.pix_by_arrival[first]

    @cached_property
    def by_depth(self) -> np.ndarray:
        """Fragment indices grouped by pixel, nearest first, equal depths in submission order."""
        return self._depth[0]

    @cached_property
    def pix_by_depth(self) -> np.ndarray:
        """``pix[by_depth]``: the pixel ids ascending."""
        return self._depth[1]

    @cached_property
    def key_by_depth(self) -> np.ndarray:
        """``key[by_depth]``: each pixel's depth keys ascending."""
        return self.key[self.by_depth]

    @cached_property
    def _depth(self) -> tuple[np.ndarray, np.ndarray]:
        return lex_sorted(self.pix, self.key)

    @cached_property
    def rank_by_depth(self) -> np.ndarray:
        """Position of each fragment among its pixel's fragments in depth order, in ``by_depth`` order."""
        return rank_in_runs(self.pix_by_depth)

    @cached_property
    def distinct_rank(self) -> np.ndarray:
        """0-based rank of each fragment's depth among the distinct depths of its pixel."""
        rank = np.empty(self.n, np.int64)
        rank[self.by_depth] = self.distinct_rank_by_depth
        return rank

    @cached_property
    def distinct_rank_by_depth(self) -> np.ndarray:
        """``distinct_rank[by_depth]``."""
        return distinct_rank_in_runs(self.pix_by_depth, self.key_by_depth)

    @cached_property
    def layers(self) -> np.ndarray:
        """Distinct depths of each pixel, (pixel_count,) int64."""
        lay = np.zeros(self.pixel_count, np.int64)
        if self.n:
            pix_sorted = self.pix_by_depth
            last = np.r_[pix_sorted[1:] != pix_sorted[:-1], True]
            lay[pix_sorted[last]] = self.distinct_rank_by_depth[last] + 1
        return lay


def distinct_ids(pix_sorted: np.ndarray, key_sorted: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """For grouped runs with keys in order: a 0-based id of each distinct (pixel, key), ascending, and where
    each run starts."""
    if len(pix_sorted) == 0:
        return np.zeros(0, np.int64), np.zeros(0, np.int64)
    new_pixel = np.r_[True, pix_sorted[1:] != pix_sorted[:-1]]
    new_value = new_pixel | np.r_[True, key_sorted[1:] != key_sorted[:-1]]
    return np.cumsum(new_value) - 1, np.flatnonzero(new_pixel)


def distinct_rank_in_runs(pix_sorted: np.ndarray, key_sorted: np.ndarray) -> np.ndarray:
    """For grouped runs with keys in order: the 0-based rank of each key among its run's distinct keys."""
    if len(pix_sorted) == 0:
        return np.zeros(0, np.int64)
    steps, start = distinct_ids(pix_sorted, key_sorted)     # distinct values so far, global
    return steps - np.repeat(steps[start], np.diff(np.r_[start, len(pix_sorted)]))


def segment_running_min_before(pix_sorted: np.ndarray, key_sorted: np.ndarray) -> np.ndarray:
    """For grouped runs: the minimum key among the *earlier* entries of the same run.

    Returns uint64 with 2**32 where there is no earlier entry. Vectorised with
    one accumulate: larger pixel ids reset the running maximum of the inverted key.
    """
    inv = pixel_key(pix_sorted, np.uint64(0xFFFFFFFF) - key_sorted.astype(np.uint64))
    run_max = np.maximum.accumulate(inv)
    prev = np.r_[np.uint64(0), run_max[:-1]]
    same = np.r_[False, pix_sorted[1:] == pix_sorted[:-1]]
    best = np.uint64(0xFFFFFFFF) - (prev & np.uint64(0xFFFFFFFF))
    return np.where(same, best, np.uint64(1) << np.uint64(32))
