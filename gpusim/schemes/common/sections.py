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
    #: ``kept`` and ``slot`` in the order of the fragments given to :func:`place` (with a bit budget)
    kept_given: np.ndarray | None = None
    slot_given: np.ndarray | None = None

    @property
    def opener(self) -> np.ndarray:
        """True for the fragment that allocated its section (the first one in it)."""
        return self.kept & (self.slot == 0)


def place(pix: np.ndarray, by_arrival: np.ndarray, n: int, capacity: int,
          bits: np.ndarray | None = None, budget_bits: int | None = None,
          pix_sorted: np.ndarray | None = None, bits_sorted: np.ndarray | None = None) -> Placement:
    """Place fragments ``by_arrival`` (grouped by pixel, arrival order) into chained sections.

    ``n`` is the trace length (result arrays are indexed by fragment). Without
    ``bits`` only the slot count limits a section. ``pix_sorted`` is ``pix[by_arrival]``
    when the caller has it, ``bits_sorted`` ``bits[by_arrival]``.
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
    bits_sorted = bits[by_arrival] if bits_sorted is None else bits_sorted
    fits = bits_sorted <= budget_bits
    order = by_arrival[fits]
    kept[order] = True
    if len(order) == 0:
        return Placement(kept, chain, slot, before, 0)
    start, _, active = runs_by_length(pix_sorted[fits])
    # rank-major: every pixel's first fragment, then every second, ...: rank j's fragments are one block whose
    # row i belongs to run i, so each step reads and writes slices; one scatter at the end
    pos = np.concatenate([start[:m] + j for j, m in enumerate(active)])
    frag = order[pos]
    b_all = bits_sorted[fits][pos].astype(np.int64)
    chain_rm, slot_rm, before_rm = (np.empty(len(frag), np.int64) for _ in range(3))
    runs = len(start)
    used_slots = np.full(runs, capacity, np.int64)     # "full": the first fragment opens a section
    used_bits = np.zeros(runs, np.int64)
    cur_chain = np.full(runs, -1, np.int64)
    early = 0
    at = 0
    for m in active.tolist():
        b = b_all[at:at + m]
        opens = (used_slots[:m] >= capacity) | (used_bits[:m] + b > budget_bits)
        early += int(np.count_nonzero(opens & (used_slots[:m] < capacity)))
        cur_chain[:m] += opens
        used_slots[:m][opens] = 0
        used_bits[:m][opens] = 0
        chain_rm[at:at + m] = cur_chain[:m]
        slot_rm[at:at + m] = used_slots[:m]
        before_rm[at:at + m] = used_bits[:m]
        used_slots[:m] += 1
        used_bits[:m] += b
        at += m
    chain[frag], slot[frag], before[frag] = chain_rm, slot_rm, before_rm
    slot_fit = np.empty(len(order), np.int64)
    slot_fit[pos] = slot_rm
    slot_given = np.full(len(by_arrival), -1, np.int64)
    slot_given[fits] = slot_fit
    return Placement(kept, chain, slot, before, early, fits, slot_given)


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

    @classmethod
    def grouped(cls, sections_per_pixel: np.ndarray, ids: np.ndarray) -> "SectionIndex":
        """The index from the sections already in (pixel, position) order: ``sections_per_pixel`` (per pixel id)
        and their ids in that order."""
        self = cls.__new__(cls)
        self.first = np.cumsum(sections_per_pixel) - sections_per_pixel
        self.ids = np.asarray(ids, np.int64)
        return self

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
