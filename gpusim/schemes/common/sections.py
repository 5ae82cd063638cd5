"""Chained per-pixel sections: how TFSS's T-buffer and WF's M-buffer place fragments.

A pixel's fragments fill a section of at most ``capacity`` fragments (and, with
leading-0s elimination, at most ``budget_bits`` bits) in arrival order; when
the next fragment does not fit, a new section is chained after it. A fragment
larger than a whole section can never be stored (``unfit``).

:func:`place_runs` returns, for every fragment it is given (grouped by pixel, in
arrival order), its position in the pixel's chain of sections and its slot inside
that section, in the order given; :func:`place` the same indexed by fragment. With a
bit budget the packing is greedy and sequential per pixel: one pass over the
fragments in a compiled kernel (gpusim.jit) where numba is installed, else
vectorised over pixels with one step per arrival rank; the same results.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from gpusim.jit import compiled_once
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


@dataclass(eq=False)
class RunPlacement:
    """:class:`Placement` of the fragments given to :func:`place_runs`, in the order given."""

    fits: np.ndarray | None   # bool: stored in some section (None: every one is)
    chain: np.ndarray         # int64: 0-based position of its section in the pixel's chain (-1 if not stored)
    slot: np.ndarray          # int64: 0-based slot inside that section (-1 if not stored)
    bits_before: np.ndarray | None   # int64: bits of the earlier fragments in its section (None: no budget, 0)
    early_breaks: int         # fragments that opened a section while the current one had free slots


def place(pix: np.ndarray, by_arrival: np.ndarray, n: int, capacity: int,
          bits: np.ndarray | None = None, budget_bits: int | None = None,
          pix_sorted: np.ndarray | None = None, bits_sorted: np.ndarray | None = None) -> Placement:
    """Place fragments ``by_arrival`` (grouped by pixel, arrival order) into chained sections.

    ``n`` is the trace length (result arrays are indexed by fragment). Without
    ``bits`` only the slot count limits a section. ``pix_sorted`` is ``pix[by_arrival]``
    when the caller has it, ``bits_sorted`` ``bits[by_arrival]``.
    """
    pix_sorted = pix[by_arrival] if pix_sorted is None else pix_sorted
    budget = budget_bits is not None and bits is not None
    if budget and bits_sorted is None:
        bits_sorted = bits[by_arrival]
    runs = place_runs(pix_sorted, capacity, bits_sorted if budget else None, budget_bits if budget else None)
    kept = np.zeros(n, bool)
    chain = np.full(n, -1, np.int64)
    slot = np.full(n, -1, np.int64)
    before = np.zeros(n, np.int64)
    kept[by_arrival if runs.fits is None else by_arrival[runs.fits]] = True
    chain[by_arrival] = runs.chain
    slot[by_arrival] = runs.slot
    if runs.bits_before is not None:
        before[by_arrival] = runs.bits_before
    return Placement(kept, chain, slot, before, runs.early_breaks)


def place_runs(pix_sorted: np.ndarray, capacity: int, bits_sorted: np.ndarray | None = None,
               budget_bits: int | None = None) -> RunPlacement:
    """:func:`place` for fragments grouped by pixel in arrival order, their pixel ids ``pix_sorted`` and stored
    bits ``bits_sorted``: the placement in that order. Without a budget only the slot count limits a section."""
    if budget_bits is None or bits_sorted is None:
        rank = rank_in_runs(pix_sorted)
        return RunPlacement(None, rank // capacity, rank % capacity, None, 0)
    bits_sorted = np.asarray(bits_sorted, np.int64)
    fits = bits_sorted <= budget_bits
    kernel = _compiled_budget_placement()
    if kernel is not None:
        chain, slot, before = (np.empty(len(pix_sorted), np.int64) for _ in range(3))
        early = int(kernel(np.asarray(pix_sorted, np.int64), bits_sorted, capacity, budget_bits, chain, slot,
                           before))
    else:
        chain, slot, before, early = _budget_placement_by_rank(pix_sorted, bits_sorted, fits, capacity,
                                                               budget_bits)
    return RunPlacement(fits, chain, slot, before, early)


def _budget_placement(pix_sorted, bits_sorted, capacity, budget_bits, chain, slot, before):
    """The greedy packing fragment by fragment (compiled with numba): fills ``chain``, ``slot`` and ``before``
    (-1, -1, 0 for a fragment larger than a section, which leaves its pixel's sections as they are) and
    returns the early breaks."""
    early = 0
    pixel = -1
    used_slots = capacity
    used_bits = 0
    current = -1
    for i in range(len(pix_sorted)):
        if pix_sorted[i] != pixel:            # a pixel's first fragment: no section yet ("full")
            pixel = pix_sorted[i]
            used_slots = capacity
            used_bits = 0
            current = -1
        b = bits_sorted[i]
        if b > budget_bits:
            chain[i] = -1
            slot[i] = -1
            before[i] = 0
            continue
        if used_slots >= capacity or used_bits + b > budget_bits:
            if used_slots < capacity:
                early += 1
            current += 1
            used_slots = 0
            used_bits = 0
        chain[i] = current
        slot[i] = used_slots
        before[i] = used_bits
        used_slots += 1
        used_bits += b
    return early


_KERNEL: list = []     # [the compiled _budget_placement, or None], made on first use


def _compiled_budget_placement():
    return compiled_once(_KERNEL, _budget_placement)


def _budget_placement_by_rank(pix_sorted: np.ndarray, bits_sorted: np.ndarray, fits: np.ndarray, capacity: int,
                              budget_bits: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, int]:
    """:func:`_budget_placement` in numpy, vectorised over the pixels with one step per arrival rank."""
    n = len(pix_sorted)
    chain = np.full(n, -1, np.int64)
    slot = np.full(n, -1, np.int64)
    before = np.zeros(n, np.int64)
    at_fit = np.flatnonzero(fits)
    if len(at_fit) == 0:
        return chain, slot, before, 0
    start, _, active = runs_by_length(pix_sorted[at_fit])
    # rank-major: every pixel's first fragment, then every second, ...: rank j's fragments are one block whose
    # row i belongs to run i, so each step reads and writes slices; one scatter at the end
    pos = np.concatenate([start[:m] + j for j, m in enumerate(active)])
    b_all = bits_sorted[at_fit][pos]
    chain_rm, slot_rm, before_rm = (np.empty(len(pos), np.int64) for _ in range(3))
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
    where = at_fit[pos]
    chain[where], slot[where], before[where] = chain_rm, slot_rm, before_rm
    return chain, slot, before, early


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
