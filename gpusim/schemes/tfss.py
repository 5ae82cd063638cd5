"""The Transparent Fragment Storage System (seed 003, chapter 3; Lin 2007).

Structures (Table 4-2, with N_S the number of sections actually allocated):

* ``ssa_table``: one start-section address per pixel, S_A x W x H bytes,
  cleared to NULL each frame.
* ``t_buffer``: sections of M_section bytes holding up to ``l_num`` fragments
  of one pixel; M_TFSS x N_S bytes. A section is allocated only when a pixel's
  transparent fragment needs one, so a pixel without transparent fragments has
  none and an all-opaque frame allocates no T-buffer at all.
* ``nsa_table``: one next-section address per allocated section, S_A x N_S.
* ``length_table`` (with leading-0s elimination, section 3.3): one entry per
  section holding ``l_num`` colour lengths.

Passes (phase 1 and 2 as in gpusim.schemes.common.early_z: opaque fragments go to the
z-buffer and frame buffer, never into the TFSS; a transparent fragment behind
the nearest opaque one so far is discarded on arrival; one occluded later is
read but not blended):

1. ``clear``: store NULL in every SSA entry.
2. ``capture`` (Figure 3-8): a stored fragment reads its pixel's SSA entry,
   follows the NSA chain to its pixel's last section (one NSA read per section
   passed), and writes itself there. When that section is full (``l_num``
   fragments, or fewer bytes free than the fragment needs) a new section is
   taken from the allocator (a register in the TFSS controller, handed out in
   submission order), linked from the SSA entry (first section) or from the
   previous section's NSA entry, and its own NSA entry set to NULL. Where the
   pixel's fill level lives the thesis does not say; the model keeps it beside
   the address (no extra access).
3. ``read`` (Figure 3-9): per pixel, read the SSA entry; per section of the
   chain read the NSA entry (simultaneously with the section, section 3.2.3.2)
   and each fragment in it; test them against the z-buffer (phase 2) and
   blend with the weight-factor equations (gpusim.schemes.common.weights) over the
   frame buffer's opaque colour. ``read_scan = "occupied"`` visits the pixels
   that have a start section (section 4.3.2 counts one SSA look-up per pixel
   with transparent fragments); ``"all"`` reads every SSA entry as Figure 3-9
   draws it.

Leading-0s elimination (gpusim.schemes.common.leading_zeros) compresses each stored
fragment's colour; a fragment then takes ``fragment_bytes`` minus the bits
saved, and a section holds fragments while both its ``l_num`` slots and its
``section_bytes`` last. Fragments that had to open a section early
(``section_breaks``) and fragments larger than a whole section
(``unfit_fragments``, dropped) are counted.

ALU work beyond each operation's own (gpusim.schemes.common.alu): with
leading-0s elimination every fragment that passes early z compresses its colour
and forms its Length-table field before it walks the chain (``LEADING_ZEROS``:
its size decides where it fits), and the read pass decodes each visible
fragment's colour (``LEADING_ZEROS_DECODE``). The read pass computes the
weight factors as Weight-Factor does (seed 003 section 4.3.2): each pair of a
pixel's m visible fragments compared once, m (m - 1) / 2 x
``WEIGHT_FACTOR_PAIR``, and each fragment blended with its weight
(``COMPOSITE``); m is each pixel's real count.

The model places the stored fragments by pixel in arrival order
(gpusim.schemes.common.sections.place_runs) and takes only the capture pass's
threads back to submission order; the section ids and T-buffer and Length Table
offsets are worked out when the plan is first expanded (a functional run needs
none of them).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import cached_property
from typing import Literal

import numpy as np

from gpusim.config import param
from gpusim.opplan import OpPlan, Pass
from gpusim.schemes.base import Scheme, register
from gpusim.schemes.common.alu import LEADING_ZEROS, LEADING_ZEROS_DECODE, weight_factor_work
from gpusim.schemes.common.early_z import (early_z, pipeline_buffers, pipeline_structures, resolve_writes,
                                           storage_bytes)
from gpusim.schemes.common.groups import PixelGroups
from gpusim.schemes.common.leading_zeros import LzeMode, length_field_bits
from gpusim.schemes.common.sections import RunPlacement, SectionIndex, place_runs, read_runs
from gpusim.schemes.common.storage import DEPTH_BYTES
from gpusim.schemes.common.weights import (Ties, check_fragment_bytes, stored_colours, unorm_rounder,
                                           weighted_image)
from gpusim.schemes.result import CapturedLists, SchemeResult, Stat, Structure

@register("tfss")
@dataclass(frozen=True)
class TFSS(Scheme):
    summary = "Transparent Fragment Storage System: SSA table, T-buffer sections, NSA table (seed 003)"

    l_num: int = param(2, unit="fragments/section", doc="L_num: fragments one T-buffer section holds", min=1,
                       max=65536)
    section_bytes: int = param(0, unit="bytes", doc="M_section, bytes per section; 0 = l_num x fragment_bytes",
                               min=0)
    fragment_bytes: int = param(8, unit="bytes", doc="uncompressed stored fragment: 32-bit depth + RGBA",
                                min=1)
    address_bytes: int = param(4, unit="bytes", doc="S_A: one SSA or NSA entry", min=1, max=8)
    leading_zero_elimination: LzeMode = param("off", doc="colour compression: off, fixed (thesis) or variable")
    colour_bits: int = param(8, unit="bits/channel", doc="colour component bit width", min=1, max=16)
    read_scan: Literal["occupied", "all"] = param("occupied", doc="read pass SSA look-ups: pixels with a "
                                                  "start section (section 4.3.2) or every pixel (Figure 3-9)")
    ties: Ties = param("arrival", doc="equal depths in the weights: arrival order, or Eq. 4 as printed")

    def __post_init__(self) -> None:
        check_fragment_bytes(self.fragment_bytes, self.colour_bits)

    @property
    def m_section(self) -> int:
        return self.section_bytes or self.l_num * self.fragment_bytes

    def simulate(self, trace) -> SchemeResult:
        g = PixelGroups(trace)
        n, P, pix = len(trace), trace.pixel_count, g.pix
        SA, M, L, bits = self.address_bytes, self.m_section, self.l_num, self.colour_bits
        lze = self.leading_zero_elimination
        fb_bytes = math.ceil(4 * bits / 8)
        passes = [Pass("clear", "clear", "entry"), Pass("capture", "geometry", "fragment"),
                  Pass("read", "fullscreen", "pixel")]
        names = pipeline_structures(trace, ["ssa_table", "t_buffer", "nsa_table"])
        names += ["length_table"] if lze != "off" else []
        plan = OpPlan(passes, names)
        plan.add(0, "store", "ssa_table", P, 1, lambda i, s: i * SA, SA)
        ez = early_z(trace, g, plan, 1, fb_bytes, unorm_rounder(bits))

        cand = np.flatnonzero(ez.stored)
        in_stored = ez.stored_by_arrival
        # the stored fragments by pixel in arrival order, and their colours: placement and the read pass take them
        # in this order, and only the capture pass's threads are taken back to submission order
        stored_order, stored_pix = g.by_arrival[in_stored], g.pix_by_arrival[in_stored]
        col = stored_colours(np.take(trace.rgba, stored_order, axis=0), bits, 8 * self.fragment_bytes, lze)
        exact_fit = lze == "off" and self.section_bytes in (0, L * self.fragment_bytes)
        pl = place_runs(stored_pix, L, None if exact_fit else col.bits, None if exact_fit else 8 * M)
        fits = None if pl.fits is None or pl.fits.all() else pl.fits     # None: every stored fragment is kept
        opens = pl.slot == 0                                # the fragment that allocated its section
        nsec = np.bincount(stored_pix[opens], minlength=P)
        if fits is None:
            kept, kept_by_arrival, read_pix, vis = cand, in_stored, stored_pix, ez.visible
        else:
            kept_mask = ez.stored.copy()
            kept_mask[stored_order[~fits]] = False
            kept, read_pix, vis = np.flatnonzero(kept_mask), stored_pix[fits], ez.visible & kept_mask
            kept_by_arrival = in_stored.copy()
            kept_by_arrival[in_stored] = fits
        # in submission order, one scatter: each kept fragment's chain position and whether it opened its section;
        # the openers in submission order are the allocation order, the first of a pixel's chain and the later
        code = np.empty(n, np.int64)
        code[stored_order] = 2 * pl.chain + ~opens
        kept_code = code[kept]
        kept_chain = kept_code >> 1
        opener = (kept_code & 1) == 0
        openers, opener_chain = kept[opener], kept_chain[opener]
        n_s = len(openers)
        is_later = opener_chain > 0
        first, later, later_chain = openers[~is_later], openers[is_later], opener_chain[is_later]
        at = _Addresses(n, stored_order, pl, fits, openers, nsec, col.bits, M, kept)
        lt_field = length_field_bits(bits, lze)
        lt_bytes = math.ceil(L * lt_field / 8)

        # capture (Figure 3-8), each stored fragment in program order; first its colour compressed
        if lze != "off":
            plan.compute(1, cand, LEADING_ZEROS)
        kept_pix = pix[kept]
        plan.add(1, "load", "ssa_table", kept, 1, lambda i, s: kept_pix[i] * SA, SA, dep=True)
        plan.add(1, "load", "nsa_table", kept, kept_chain,
                 lambda i, s: at.section(kept_pix[i], s) * SA, SA, dep=True)
        # the i-th section allocated is section i
        plan.add(1, "store", "nsa_table", openers, 1, lambda i, s: i * SA, SA, dep=True)
        plan.add(1, "store", "ssa_table", first, 1, lambda i, s: pix[first[i]] * SA, SA, dep=True)
        plan.add(1, "store", "nsa_table", later, 1,
                 lambda i, s: at.section(pix[later[i]], later_chain[i] - 1) * SA, SA, dep=True)
        plan.add(1, "store", "t_buffer", kept, 1, lambda i, s: at.t_off[at.kept_at[i]],
                 lambda i, s: at.t_bytes[at.kept_at[i]], dep=True)
        if lze != "off":
            plan.add(1, "store", "length_table", kept, 1, lambda i, s: at.section_of[at.kept_at[i]] * lt_bytes
                     + at.slot[at.kept_at[i]] * lt_field // 8, 1, dep=True)

        # read (Figure 3-9), one thread per pixel
        rpix, rstart, rcount = read_runs(pix, None, P, read_pix)
        read_per_pixel = np.zeros(P, np.int64)
        read_per_pixel[rpix] = rcount
        if self.read_scan == "all":
            plan.add(2, "load", "ssa_table", P, 1, lambda i, s: i * SA, SA)
        else:
            plan.add(2, "load", "ssa_table", rpix, 1, lambda i, s: rpix[i] * SA, SA)
        if ez.uses_z:   # phase 2: the stored fragments meet the final opaque depth
            plan.add(2, "load", "z_buffer", rpix, 1, lambda i, s: rpix[i] * DEPTH_BYTES, DEPTH_BYTES)
        plan.add(2, "load", "nsa_table", rpix, nsec[rpix], lambda i, s: at.section(rpix[i], s) * SA, SA, dep=True)
        if lze != "off":
            plan.add(2, "load", "length_table", rpix, nsec[rpix],
                     lambda i, s: at.section(rpix[i], s) * lt_bytes, lt_bytes, dep=True)
        plan.add(2, "load", "t_buffer", rpix, rcount, lambda i, s: at.t_off[at.read_at[rstart[i] + s]],
                 lambda i, s: at.t_bytes[at.read_at[rstart[i] + s]], dep=True)
        vis_by_arrival = ez.visible_by_arrival if fits is None else ez.visible_by_arrival & kept_by_arrival
        visible_count = np.bincount(g.pix_by_arrival[vis_by_arrival], minlength=P)
        m = visible_count[rpix]                             # visible fragments per pixel read
        plan.compute(2, rpix, weight_factor_work(m) + m * (LEADING_ZEROS_DECODE if lze != "off" else 0))
        blended = resolve_writes(plan, 2, pix, vis, P, fb_bytes, visible_count)
        image, order, order_pix = weighted_image(trace, g, vis, stored_order, col, ez.opaque_rgb, self.ties,
                                                 vis_by_arrival, ez.key_by_arrival, np.cumsum(in_stored) - 1,
                                                 with_pixels=True)

        stored_bits = int((col.bits if fits is None else col.bits[fits]).sum())
        unfit_pix = stored_pix[~fits] if fits is not None else stored_pix[:0]
        struct = [
            *pipeline_buffers(P, fb_bytes, bits, ez, blended > 0),
            Structure("ssa_table", SA, P, len(first), "start-section address per pixel (S_A x W x H)"),
            Structure("t_buffer", M, n_s, n_s, f"sections of M_section = {M} B, up to {L} fragments each"),
            Structure("nsa_table", SA, n_s, len(later), "next-section address per allocated section (S_A x N_S)"),
        ]
        if lze != "off":
            struct.append(Structure("length_table", lt_bytes, n_s, n_s,
                                    f"{L} x {lt_field}-bit colour lengths per section"))
        storage = storage_bytes(struct)
        stats = {
            "sections": Stat(n_s, "sections", "N_S: T-buffer sections allocated"),
            "storage_system_bytes": Stat(storage, "bytes", "Table 4-2 total: T-buffer + SSA + NSA "
                                                           "(+ Length Table with leading-0s elimination)"),
            "transparent_pixels": Stat(len(rpix), "pixels", "pixels with at least one stored fragment"),
            "stored_fragments": Stat(len(kept), "fragments", "transparent fragments written to the T-buffer"),
            **ez.stats(),
            "section_fill": Stat(round(stored_bits / (8 * M * n_s), 6) if n_s else 0.0, "fraction",
                                 "stored fragment bits / T-buffer bits"),
            "stored_bits_per_fragment": Stat(round(stored_bits / len(kept), 4) if len(kept) else 0.0, "bits",
                                             "mean stored size of a fragment after compression"),
            "section_breaks": Stat(pl.early_breaks, "fragments",
                                   "fragments that opened a new section because the current one lacked bytes"),
            "unfit_fragments": Stat(len(unfit_pix), "fragments",
                                    "fragments larger than a whole section (dropped)"),
        }
        return SchemeResult(
            self.name, self.params(), image, n, g.covered, struct, plan, geometry_passes=1,
            dropped_fragments=len(unfit_pix), overflowed_pixels=len(np.unique(unfit_pix)),
            lists=CapturedLists(order_pix, order), stats=stats,
            extras={"read_per_pixel": read_per_pixel})


class _Addresses:
    """Where the kept fragments' sections, T-buffer bytes and Length Table fields are: only an expansion of the
    plan (the timing model, the OpStream) reads them, so they are worked out on its first call, never in a
    functional run. Arrays of the stored fragments are in their order by pixel and arrival (``stored_order``)."""

    def __init__(self, n: int, stored_order: np.ndarray, placement: RunPlacement, fits: np.ndarray | None,
                 openers: np.ndarray, sections_per_pixel: np.ndarray, frag_bits: np.ndarray, m_section: int,
                 kept_threads: np.ndarray):
        self._n, self._stored_order, self._pl, self._fits = n, stored_order, placement, fits
        self._openers, self._nsec, self._frag_bits = openers, sections_per_pixel, frag_bits
        self._m, self._kept_threads = m_section, kept_threads

    @cached_property
    def _ids(self) -> np.ndarray:
        """Each section's id (allocation order: its opener's place in submission order), the sections in
        (pixel, chain position) order."""
        section_id = np.empty(self._n, np.int64)
        section_id[self._openers] = np.arange(len(self._openers))
        return section_id[self._stored_order[self._pl.slot == 0]]

    @cached_property
    def section(self) -> SectionIndex:
        """The section id of (pixel, chain position)."""
        return SectionIndex.grouped(self._nsec, self._ids)

    @cached_property
    def section_of(self) -> np.ndarray:
        """Each stored fragment's section id (-1: not kept)."""
        if len(self._ids) == 0:
            return np.full(len(self._stored_order), -1, np.int64)
        sec = self._ids[np.cumsum(self._pl.slot == 0) - 1]      # the last section opened at its pixel
        if self._fits is not None:
            sec[~self._fits] = -1
        return sec

    @property
    def slot(self) -> np.ndarray:
        """Each stored fragment's slot in its section (-1: not kept)."""
        return self._pl.slot

    @cached_property
    def t_off(self) -> np.ndarray:
        """Each stored fragment's T-buffer byte offset: its section's start plus the bytes of the fragments before
        it in the section (without a bit budget every fragment takes the same bytes, its slot's)."""
        before = self._pl.bits_before
        return self.section_of * self._m + (self._pl.slot * self.t_bytes if before is None else before // 8)

    @cached_property
    def t_bytes(self) -> np.ndarray:
        """Each stored fragment's T-buffer bytes."""
        return -(-self._frag_bits // 8)

    @cached_property
    def kept_at(self) -> np.ndarray:
        """The place among the stored fragments of each capture thread (a kept fragment, submission order)."""
        place = np.empty(self._n, np.int64)
        place[self._stored_order] = np.arange(len(self._stored_order))
        return place[self._kept_threads]

    @cached_property
    def read_at(self) -> np.ndarray:
        """The place among the stored fragments of each kept one, by pixel and arrival (the read pass's order)."""
        return np.arange(len(self._stored_order)) if self._fits is None else np.flatnonzero(self._fits)
