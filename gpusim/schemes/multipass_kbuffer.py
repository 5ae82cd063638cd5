"""The multi-pass k-buffer (Liu, Wei, Xu: "Multi-layer depth peeling via fragment sort", Microsoft Research Asia
technical report, 2006; seed 000 Table 3's "Liu", 5-9 geometry passes, 20 MB).

Depth peeling that peels k layers per geometry pass: each ``peel`` pass captures the next k nearest fragments
of every pixel with the k-buffer's read-modify-write (gpusim.schemes.kbuffer in ``peel`` mode, the same
``hw`` choices: on current hardware k ``rmw_read`` and k ``rmw_write`` per fragment through the texture path,
with the same RMW hazards), then a full-screen ``resolve`` reads each pixel's k entries, composites them
under the colour accumulated so far (a ``blend`` into ``accumulation``, RGBA32F), stores the farthest as the
pixel's ``peel_depth`` and writes the k entries back empty for the next pass (an MRT output each). As depth
peeling's blend passes, a resolve counts the pixels its pass captured something at (the others have nothing
to do). From the second peel pass on every fragment loads its pixel's peel depth and goes on only when
strictly behind it (``PEEL_TEST``, as depth peeling). Passes go on until no fragment is left: with
``termination = known-layers`` the last one is the last to capture anything (ceil(L / k) passes for L
distinct depths), with ``occlusion-query`` one more runs whose query finds no fragment left.

Equal depths: inside a pass as the k-buffer (a fragment goes behind stored ones of equal depth, so the first
submitted is nearer); fragments of the depth a pass ended at that did not fit in its k entries are never
captured (the next pass takes only depths strictly behind): ``tie_losses``, the ``dropped_fragments``.

Entry formats (``entry``, ``uniform_alpha``) as the k-buffer's (gpusim.schemes.common.kbuffer_entries): with
``rgbz`` (16 B) each entry is one RGBA32F texel, with ``z`` (4 B) four entries share one, and every read, write
and store of the buffer moves one such texel; the resolve composites what the entries hold (RGB at the uniform
alpha, or the depth cue of Z-only entries, ``DEPTH_CUE`` an entry more). This is seed 004's multi-pass mode with
k layers peeled per pass; the paper's Table 1 "MP" column is traditional depth peeling, one layer a pass
(``depth-peeling`` with ``termination = fixed``).

The functional model is the hazard-free result. ``extras["rmw_replay"]`` replays each peel pass in the
timing model's event order (gpusim.schemes.common.kbuffer_replay), on the fragments the hazard-free pass had
that lie behind the depth the replayed previous pass ended at: a fragment a hazard loses is lost for good.
The timing is the hazard-free run's: its passes and their fragments do not follow the hazards.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import partial
from typing import Literal

import numpy as np

from gpusim.config import param
from gpusim.opplan import OpPlan, Pass
from gpusim.schemes.base import Scheme, register
from gpusim.schemes.common.alu import COMPOSITE, PEEL_TEST
from gpusim.schemes.common.arrays import entry_index, lex_order, record_layout
from gpusim.schemes.common.groups import PixelGroups
from gpusim.schemes.common.kbuffer_entries import (ENTRY_DOC, UNIFORM_ALPHA_DOC, EntryFormat, access_layout,
                                                   check_entry, entry_bytes, entry_image, per_access, resolve_alpha,
                                                   resolve_alu)
from gpusim.schemes.common.kbuffer_replay import make_multipass_replay
from gpusim.schemes.common.storage import DEPTH_BYTES, ColourFormat
from gpusim.schemes.kbuffer import FRAMEBUFFER_BYTES, add_rmw, entries_doc
from gpusim.schemes.result import CapturedLists, SchemeResult, Stat, Structure


def peel_in_passes(pix_sorted: np.ndarray, key_sorted: np.ndarray, k: int) -> tuple[np.ndarray, np.ndarray]:
    """The pass each fragment is captured or lost in, and whether it is captured, for fragments grouped by pixel
    nearest first (``pix_sorted``, ``key_sorted``: equal depths in submission order). A pass keeps the k nearest
    of its pixel's fragments strictly behind the depth the previous pass ended at; the rest of the depth it ends
    at are lost. A fragment takes part (passes the peel test) in every pass up to its own.

    A pass moves each pixel's start to the first fragment behind its end: a step per pixel still peeling, so the
    work grows with the fragments plus the pixels' passes, not with their product (stress-layers: 4,097 layers
    on a pixel)."""
    n = len(pix_sorted)
    new_pixel = np.r_[True, pix_sorted[1:] != pix_sorted[:-1]] if n else np.zeros(0, bool)
    boundary = new_pixel.copy()                    # the first fragment of each pass of each pixel
    packed = (pix_sorted.astype(np.uint64) << np.uint64(32)) | key_sorted.astype(np.uint64)
    begin = np.flatnonzero(new_pixel)
    end = np.r_[begin[1:], n]
    while len(begin):
        last = np.minimum(begin + k, end) - 1                      # the pass's farthest kept fragment
        begin = np.searchsorted(packed, packed[last], side="right")    # the first strictly behind it
        more = begin < end
        begin, end = begin[more], end[more]
        boundary[begin] = True
    index = np.arange(n)
    first = np.maximum.accumulate(np.where(boundary, index, 0))            # the first of each fragment's pass
    passes = np.cumsum(boundary) - 1                                        # passes counted over every pixel
    passes -= passes[np.maximum.accumulate(np.where(new_pixel, index, 0))]  # ... from the pixel's first
    return passes, index - first < k


@register("multipass-kbuffer")
@dataclass(frozen=True)
class MultipassKBuffer(Scheme):
    summary = "multi-pass k-buffer: k layers peeled per geometry pass through a k-entry RMW buffer (Liu et al. 2006)"

    k: int = param(8, unit="entries/pixel", doc="k-buffer entries per pixel: layers peeled per geometry pass",
                   min=1, max=64)
    colour_format: ColourFormat = param("rgba32f", doc="entry colour format")
    entry: EntryFormat = param("depth-colour", doc=ENTRY_DOC)
    uniform_alpha: float | None = param(None, unit="1", doc=UNIFORM_ALPHA_DOC, min=0.0, max=1.0)
    termination: Literal["known-layers", "occlusion-query"] = param(
        "known-layers", doc="stop after the last pass that captures anything, or run one more whose occlusion "
                            "query finds no fragment left")
    hw: Literal["texture-rmw", "scoreboard", "blender"] = param(
        "texture-rmw", doc="where the RMW runs (as the k-buffer's): texture reads in the shader, behind a "
                           "dispatch scoreboard, or in a programmable blender")

    def __post_init__(self) -> None:
        check_entry(self.entry, self.colour_format)

    def simulate(self, trace) -> SchemeResult:
        g = PixelGroups(trace)
        n, P, k, pix = len(trace), trace.pixel_count, self.k, g.pix
        fmt, cf = self.entry, self.colour_format
        slots, slot_bytes = access_layout(fmt, cf, k)      # k entries, or ceil(k / 4) texels of Z-only entries
        by_depth = g.by_depth
        pass_sorted, kept_sorted = peel_in_passes(g.pix_by_depth, g.key_by_depth, k)
        m = int(pass_sorted.max()) + 1 if n else 0
        total = m + (1 if self.termination == "occlusion-query" and n else 0)

        passes, peel_at, resolve_at = [Pass("clear", "clear", "entry")], [], []
        for p in range(max(total, 1)):
            peel_at.append(len(passes))
            passes.append(Pass(f"peel {p}", "geometry", "fragment", shading="none" if fmt == "z" else "colour"))
            if p < m:
                resolve_at.append(len(passes))
                passes.append(Pass(f"resolve {p}", "fullscreen", "pixel"))
        plan = OpPlan(passes, ["kbuffer", "peel_depth", "accumulation"])
        entries = lambda i, s: i * slot_bytes  # noqa: E731
        plan.add(0, "store", "kbuffer", P * slots, 1, entries, slot_bytes)
        plan.add(0, "store", "peel_depth", P, 1, lambda i, s: i * DEPTH_BYTES, DEPTH_BYTES)
        plan.add(0, "store", "accumulation", P, 1, lambda i, s: i * FRAMEBUFFER_BYTES, FRAMEBUFFER_BYTES)
        # every pass after the first: the pixel's peel depth, strictly behind it or discard
        later = np.asarray(peel_at[1:], np.int64)
        plan.add(0, "load", "peel_depth", n, total - 1, lambda i, s: pix[i] * DEPTH_BYTES, DEPTH_BYTES,
                 seq_pass=later)
        plan.compute(0, n, PEEL_TEST, count=max(total - 1, 0), seq_pass=later)
        # each fragment's RMW in every peel pass up to the one that captures or loses it: one group across passes
        takes_part = np.empty(n, np.int64)
        takes_part[by_depth] = pass_sorted + 1
        add_rmw(plan, peel_at[0], n, pix, P, k, fmt, cf, self.hw, count=takes_part,
                seq_pass=np.asarray(peel_at[:m], np.int64))
        # the pixels with entries, pass by pass: read, composite, blend in, keep the peel depth, empty the entries
        layout = record_layout(self.hw)
        captured = np.flatnonzero(kept_sorted)                              # positions in depth order
        by_pass = captured[lex_order(pass_sorted[captured])]                # pass by pass, each grouped by pixel
        cuts = np.searchsorted(pass_sorted[by_pass], np.arange(m + 1))
        for p in range(m):
            pk = g.pix_by_depth[by_pass[cuts[p]:cuts[p + 1]]]
            first = np.r_[True, pk[1:] != pk[:-1]] if len(pk) else np.zeros(0, bool)
            done = pk[first]
            stored = np.diff(np.r_[np.flatnonzero(first), len(pk)])
            r = resolve_at[p]
            slot = lambda i, s, d=done: entry_index(d[i], s, slots, P, layout) * slot_bytes  # noqa: E731
            plan.add(r, "load", "kbuffer", done, slots, slot, slot_bytes)
            plan.compute(r, done, stored * (COMPOSITE + resolve_alu(fmt)))
            plan.add(r, "blend", "accumulation", done, 1, lambda i, s, d=done: d[i] * FRAMEBUFFER_BYTES,
                     FRAMEBUFFER_BYTES, dep=True)
            plan.add(r, "store", "peel_depth", done, 1, lambda i, s, d=done: d[i] * DEPTH_BYTES, DEPTH_BYTES)
            plan.add(r, "store", "kbuffer", done, slots, slot, slot_bytes)

        order = by_depth[captured]               # pass by pass, each nearest first: depth order
        lost = n - len(order)
        kept_n = np.bincount(pix[order], minlength=P)
        struct = [Structure("kbuffer", entry_bytes(fmt, cf), P * slots * per_access(fmt), int(kept_n.clip(max=k).sum()),
                            f"{entries_doc(fmt, cf)} (emptied by each resolve)"),
                  Structure("peel_depth", DEPTH_BYTES, P, g.covered, "depth the pixel's previous pass ended at"),
                  Structure("accumulation", FRAMEBUFFER_BYTES, P, g.covered, "RGBA32F colour composited so far")]
        stats = {"tie_losses": Stat(int(lost), "fragments", "fragments at the depth a pass ended at that did "
                                    "not fit in its k entries: never captured"),
                 "layers": Stat(int(g.layers.max(initial=0)), "layers", "largest number of distinct depths of a "
                                "pixel")}
        extras = {}
        image_of = partial(entry_image, trace, pix, entry=fmt, colour_format=cf,
                           uniform_alpha=resolve_alpha(fmt, self.uniform_alpha, g))
        if self.hw != "blender":
            extras["rmw_replay"] = make_multipass_replay(P, pix, g.key, k, image_of, order)
        return SchemeResult(self.name, self.params(), image_of(order), n, g.covered,
                            struct, plan, geometry_passes=total, dropped_fragments=int(lost),
                            overflowed_pixels=int(np.count_nonzero(g.count > kept_n)),
                            lists=CapturedLists(pix[order], order), stats=stats, extras=extras)
