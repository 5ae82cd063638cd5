"""The Weight-Factor hardware-oriented algorithm (Amor et al. 2006, as in seed 003 section 2.5.2).

Structures (Table 4-2): ``m_buffer``, sections of ``d_avg`` fragments
(M_WF = d_avg x fragment_bytes): one static section per pixel (section i for
pixel i, W x H of them, allocated whether or not the pixel has transparent
fragments) plus N_A dynamically allocated sections for pixels with more than
``d_avg`` fragments; ``pointer_memory``, one S_A pointer per section
(S_A x (W x H + N_A)), NULL or the next section's index.

Phases 1 and 2 as in gpusim.schemes.common.early_z. ``capture``: a stored fragment
follows its pixel's pointer chain from section i (one pointer read per full
section passed) and writes itself in the first section with room; a pixel
needing another section takes the next dynamic one (indices from W x H up, in
submission order), links it from the last pointer and sets its own pointer to
NULL. ``clear`` sets the W x H static pointers to NULL. ``read`` (Figure 2-6):
per pixel with fragments, read each section's pointer (simultaneously with the
section, seed 003 section 4.3.2) and each fragment once; weight factors by
Eq. 2-4 (gpusim.schemes.common.weights) over the frame buffer's opaque colour.

ALU work beyond each operation's own (gpusim.schemes.common.alu): the read
pass compares each pair of a pixel's m visible fragments once, m (m - 1) / 2 x
``WEIGHT_FACTOR_PAIR`` (Figure 2-6's WEIGHT FACTOR COMPUTATION), and blends each
with its weight (``COMPOSITE``); m is each pixel's real count.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from gpusim.config import param
from gpusim.opplan import OpPlan, Pass
from gpusim.schemes.base import Scheme, register
from gpusim.schemes.common.alu import weight_factor_work
from gpusim.schemes.common.early_z import (early_z, pipeline_buffers, pipeline_structures, resolve_writes,
                                           storage_bytes)
from gpusim.schemes.common.groups import PixelGroups
from gpusim.schemes.common.sections import SectionIndex, place, read_runs
from gpusim.schemes.common.storage import DEPTH_BYTES
from gpusim.schemes.common.weights import (Ties, check_fragment_bytes, stored_colours, unorm_rounder,
                                           weighted_image)
from gpusim.schemes.result import CapturedLists, SchemeResult, Stat, Structure


@register("weight-factor")
@dataclass(frozen=True)
class WeightFactor(Scheme):
    summary = "Weight-Factor algorithm: per-pixel M-buffer sections + pointer memory (Amor 2006, seed 003)"

    d_avg: int = param(2, unit="fragments/section", doc="D_avg: fragments one M-buffer section holds", min=1,
                       max=65536)
    fragment_bytes: int = param(8, unit="bytes", doc="stored fragment: 32-bit depth + RGBA", min=1)
    address_bytes: int = param(4, unit="bytes", doc="S_A: one pointer-memory entry", min=1, max=8)
    colour_bits: int = param(8, unit="bits/channel", doc="colour component bit width", min=1, max=16)
    ties: Ties = param("arrival", doc="equal depths in the weights: arrival order, or Eq. 4 as printed")

    def __post_init__(self) -> None:
        check_fragment_bytes(self.fragment_bytes, self.colour_bits)

    def simulate(self, trace) -> SchemeResult:
        g = PixelGroups(trace)
        n, P, pix = len(trace), trace.pixel_count, g.pix
        SA, D, FB, bits = self.address_bytes, self.d_avg, self.fragment_bytes, self.colour_bits
        M = D * FB
        fb_bytes = math.ceil(4 * bits / 8)
        passes = [Pass("clear", "clear", "entry"), Pass("capture", "geometry", "fragment"),
                  Pass("read", "fullscreen", "pixel")]
        plan = OpPlan(passes, pipeline_structures(trace, ["m_buffer", "pointer_memory"]))
        plan.add(0, "store", "pointer_memory", P, 1, lambda i, s: i * SA, SA)
        ez = early_z(trace, g, plan, 1, fb_bytes, unorm_rounder(bits))

        in_stored = ez.stored[g.by_arrival]
        stored_order, stored_pix = g.by_arrival[in_stored], g.pix_by_arrival[in_stored]
        pl = place(pix, stored_order, n, D, pix_sorted=stored_pix)
        dynamic = np.flatnonzero(pl.opener & (pl.chain > 0))    # submission order = allocation order
        n_a = len(dynamic)
        static = np.flatnonzero(pl.opener & (pl.chain == 0))
        section = SectionIndex(np.r_[pix[static], pix[dynamic]], np.r_[np.zeros(len(static), np.int64),
                                                                       pl.chain[dynamic]],
                               np.r_[pix[static], P + np.arange(n_a)])
        kept = np.flatnonzero(ez.stored)                          # every stored fragment fits
        sec_of = np.full(n, -1, np.int64)
        sec_of[kept] = section(pix[kept], pl.chain[kept])
        m_off = sec_of * M + pl.slot * FB

        kept_pix = pix[kept]
        plan.add(1, "load", "pointer_memory", kept, pl.chain[kept],
                 lambda i, s: section(kept_pix[i], s) * SA, SA, dep=True)
        plan.add(1, "store", "pointer_memory", dynamic, 1, lambda i, s: sec_of[dynamic[i]] * SA, SA, dep=True)
        plan.add(1, "store", "pointer_memory", dynamic, 1,
                 lambda i, s: section(pix[dynamic[i]], pl.chain[dynamic[i]] - 1) * SA, SA, dep=True)
        plan.add(1, "store", "m_buffer", kept, 1, lambda i, s: m_off[kept[i]], FB, dep=True)

        rpix, rstart, rcount = read_runs(pix, stored_order, P, stored_pix)
        nsec = -(-rcount // D)
        if ez.uses_z:   # phase 2: the stored fragments meet the final opaque depth
            plan.add(2, "load", "z_buffer", rpix, 1, lambda i, s: rpix[i] * DEPTH_BYTES, DEPTH_BYTES)
        plan.add(2, "load", "pointer_memory", rpix, nsec, lambda i, s: section(rpix[i], s) * SA, SA)
        plan.add(2, "load", "m_buffer", rpix, rcount, lambda i, s: m_off[stored_order[rstart[i] + s]], FB,
                 dep=True)
        plan.compute(2, rpix, weight_factor_work(np.bincount(pix[ez.visible], minlength=P)[rpix]))
        blended = resolve_writes(plan, 2, pix, ez.visible, P, fb_bytes)
        col = stored_colours(np.take(trace.rgba, kept, axis=0), bits, 8 * FB, "off")
        image, order = weighted_image(trace, g, ez.visible, kept, col, ez.opaque_rgb, self.ties)

        sections = P + n_a
        struct = [
            *pipeline_buffers(P, fb_bytes, bits, ez, blended > 0),
            Structure("m_buffer", M, sections, len(static) + n_a,
                      f"W x H static + N_A dynamic sections of D_avg = {D} fragments"),
            Structure("pointer_memory", SA, sections, n_a, "next-section pointer per section"),
        ]
        storage = storage_bytes(struct)
        stats = {
            "dynamic_sections": Stat(n_a, "sections", "N_A: sections allocated beyond the W x H static ones"),
            "storage_system_bytes": Stat(storage, "bytes", "Table 4-2 total: M-buffer + pointer memory"),
            "transparent_pixels": Stat(len(rpix), "pixels", "pixels with at least one stored fragment"),
            "stored_fragments": Stat(len(kept), "fragments", "transparent fragments written to the M-buffer"),
            **ez.stats(),
            "section_fill": Stat(round(len(kept) / (D * sections), 6), "fraction",
                                 "stored fragments / M-buffer slots"),
        }
        return SchemeResult(
            self.name, self.params(), image, n, g.covered, struct, plan, geometry_passes=1,
            dropped_fragments=0, overflowed_pixels=0, lists=CapturedLists(pix[order], order), stats=stats,
            extras={"read_per_pixel": np.bincount(pix[kept], minlength=P)})
