"""Chained per-pixel sections: how TFSS's T-buffer and WF's M-buffer place fragments.

A pixel's fragments fill a section of at most ``capacity`` fragments (and, with
leading-0s elimination, at most ``budget_bits`` bits) in arrival order; when
the next fragment does not fit, a new section is chained after it. A fragment
larger than a whole section can never be stored (``unfit``).

:func:`place` returns, for every fragment it is given, its position in the
pixel's chain of sections and its slot inside that section. With a bit budget
the packing is greedy and sequential per pixel; it is vectorised over pixels
with one step per arrival rank (see gpusim.schemes.common.fold).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from gpusim.metrics.composite import runs_by_length
from gpusim.schemes.common.arrays import lex_order, rank_in_runs


@dataclass(eq=False)
class Placement:
    """Where each fragment went; arrays are indexed by fragment (trace index)."""

    kept: np.ndarray          # bool: stored in some section
    chain: np.ndarray         # int64: 0-based position of its section in the pixel's chain (-1 if not kept)
    slot: np.ndarray          # int64: 0-based slot inside that section (-1 if not kept)
    bits_before: np.ndarray   # int64: bits of the earlier fragments in the same section (0 without a budget)
    early_breaks: int         # fragments that opened a section while the current one had free slots

    @property
    def opener(self) -> np.ndarray:
        """True for the fragment that allocated its section (the first one in it)."""
        return self.kept & (self.slot == 0)


def place(pix: np.ndarray, by_arrival: np.ndarray, n: int, capacity: int,
          bits: np.ndarray | None = None, budget_bits: int | None = None,
          pix_sorted: np.ndarray | None = None) -> Placement:
    """Place fragments ``by_arrival`` (grouped by pixel, arrival order) into chained sections.

    ``n`` is the trace length (result arrays are indexed by fragment). Without
    ``bits`` only the slot count limits a section. ``pix_sorted`` is ``pix[by_arrival]``
    when the caller has it.
    """
    pix_sorted = pix[by_arrival] if pix_sorted is None else pix_sorted
    kept = np.zeros(n, bool)
    chain = np.full(n, -1, np.int64)
    slot = np.full(n, -1, np.int64)
    before = np.zeros(n, np.int64)
    if budget_bits is None or bits is None:
        rank = rank_in_runs(pix_sorted)
        kept[by_arrival] = True
        chain[by_arrival] = rank // capacity
        slot[by_arrival] = rank % capacity
        return Placement(kept, chain, slot, before, 0)
    fits = bits[by_arrival] <= budget_bits
    order = by_arrival[fits]
    kept[order] = True
    if len(order) == 0:
        return Placement(kept, chain, slot, before, 0)
    start, _, active = runs_by_length(pix_sorted[fits])
    runs = len(start)
    used_slots = np.full(runs, capacity, np.int64)     # "full": the first fragment opens a section
    used_bits = np.zeros(runs, np.int64)
    cur_chain = np.full(runs, -1, np.int64)
    early = 0
    for j, m in enumerate(active):
        f = order[start[:m] + j]
        b = bits[f].astype(np.int64)
        opens = (used_slots[:m] >= capacity) | (used_bits[:m] + b > budget_bits)
        early += int(np.count_nonzero(opens & (used_slots[:m] < capacity)))
        cur_chain[:m] += opens
        used_slots[:m] = np.where(opens, 0, used_slots[:m])
        used_bits[:m] = np.where(opens, 0, used_bits[:m])
        chain[f] = cur_chain[:m]
        slot[f] = used_slots[:m]
        before[f] = used_bits[:m]
        used_slots[:m] += 1
        used_bits[:m] += b
    return Placement(kept, chain, slot, before, early)


class SectionIndex:
    """Look up the section id of (pixel, position in the pixel's chain).

    A pixel's chain positions are 0, 1, ..., so the sections sorted by (pixel, position) put
    (p, c) at ``first[p] + c``: a lookup is two gathers, whatever the order of the queries.
    """

    def __init__(self, pixel: np.ndarray, chain: np.ndarray, section: np.ndarray):
        order = lex_order(pixel, chain)
        pixel_sorted = np.asarray(pixel, np.int64)[order]
        if not np.array_equal(np.asarray(chain)[order], rank_in_runs(pixel_sorted)):
            raise ValueError("SectionIndex: a pixel's chain positions must be 0, 1, ... without gaps")
        counts = np.bincount(pixel_sorted)
        self.first = np.cumsum(counts) - counts
        self.ids = np.asarray(section, np.int64)[order]

    def __call__(self, pixel: np.ndarray, chain: np.ndarray) -> np.ndarray:
        return self.ids[self.first[pixel] + chain]


def read_runs(pix: np.ndarray, kept_by_arrival: np.ndarray, pixel_count: int, pix_sorted: np.ndarray | None = None
              ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Pixels holding fragments, where each one's run starts in ``kept_by_arrival``, and its length
    (``pix_sorted``: ``pix[kept_by_arrival]`` when the caller has it)."""
    counts = np.bincount(pix[kept_by_arrival] if pix_sorted is None else pix_sorted, minlength=pixel_count)
    pixels = np.flatnonzero(counts)
    start = np.cumsum(counts) - counts
    return pixels, start[pixels], counts[pixels]
