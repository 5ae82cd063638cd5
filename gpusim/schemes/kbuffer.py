"""The k-buffer (Bavoil et al., seed 004): k entries per pixel, read-modify-write per fragment.

Every fragment's program reads the pixel's k entries, modifies them and writes
them back (section 3: Read, Modify, Write). On current hardware (section 3.2)
the entries are MRT textures read through the texture path, so each fragment
issues an ``rmw_read`` and an ``rmw_write`` of each of its pixel's k entries;
the timing model finds the read-modify-write hazards between fragments of one
pixel from exactly these operations. This functional model is the hazard-free
result (fragments applied one at a time in submission order).

Entry formats (``entry``; gpusim.schemes.common.kbuffer_entries, Table 1's
"4 RGBZ" and "16 Z"): ``depth-colour`` (the default) a depth and a colour in
``colour_format`` (4 + 16 bytes at rgba32f), one access per entry; ``rgbz``
one RGBA32F texel of RGB + depth (16 B), one access per entry, composited at
``uniform_alpha`` (it stores no alpha); ``z`` the depth alone (4 B), four to an
RGBA32F texel, one access per texel (ceil(k / 4) of 16 B per fragment), its
image a depth cue (grey 1 - z at ``uniform_alpha``). The entry's bytes size the
buffer, its accesses and so the memory traffic the timing model moves.

Modes:

* ``peel`` (section 4.1): insertion sort keeps the k nearest fragments (an
  incoming fragment goes behind stored ones of equal depth); a full-screen
  resolve composites them. Fragments beyond the k nearest are dropped.
* ``sort-blend`` (section 4.3): when a fragment arrives at a full k-buffer the
  nearest of the k + 1 is composited front to back into an RGBA32F framebuffer
  (also read and written by every fragment, as an MRT) and leaves; the resolve
  composites what remains, nearest first. Exact for a k-nearly-sorted input;
  otherwise fragments are composited out of order (``misordered_pairs``;
  ``max_disorder``, Table 2's "Max Error": how far the composited sequence of
  a pixel strays from depth order, see :func:`max_disorder`).

Heuristics of section 3.2, applied to the trace first: ``order = centroid``
sorts primitives front to back by centroid depth (see gpusim.schemes.common.reorder);
``batch = N`` splits the primitives into batches of N with a pipeline flush
(a ``flush`` pass with no memory operations) between; every submitted primitive
counts, those that cover no pixel included (spread evenly through the centroid
order, whose depths the trace does not hold). Both leave this
functional result unchanged (peel) or improve it (sort-blend, by ordering);
their cost and their effect on hazards are the timing model's to measure.

Hardware (``hw``, section 3.1):

* ``texture-rmw`` (current hardware, section 3.2): k ``rmw_read`` and k
  ``rmw_write`` per fragment through the texture path; hazards possible.
* ``scoreboard`` (proposal 1): the same, behind a ``scoreboard`` dispatch
  operation that holds a fragment back while its pixel is in flight.
* ``blender`` (proposal 2): one ``program_blend`` per fragment at the ROP,
  reading and writing the pixel's k entries in submission order; the entries
  are then the pixel's record, adjacent (one access of all of them), and in
  ``sort-blend`` the colour the program emits goes through the ROP's ``blend``
  into the framebuffer.

ALU work beyond each operation's own (gpusim.schemes.common.alu): between its
reads and writes a fragment's program inserts itself into the k sorted entries,
k compare-exchanges of entries (``compare_exchange`` of what an entry holds
beside its depth: 11 instructions for depth + rgba32f colour, 9 for RGBZ, 3 for
a depth alone), and in ``sort-blend`` a fragment that finds the k entries full
composites the nearest of the k + 1 into the framebuffer (``COMPOSITE``, plus
``DEPTH_CUE`` for Z-only entries). With ``hw = blender`` that program runs in the
blender (``program_blend``), not on the SM. The resolve composites each pixel's
min(n, k) stored entries, already in depth order (Z-only entries shaded first,
``DEPTH_CUE`` each). The entries are textures (MRTs): the texture path converts
their format.

``extras["rmw_replay"]`` replays the program in the timing model's event order
(gpusim.schemes.common.kbuffer_replay) so the timed image shows the hazards' artifacts.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import partial
from typing import Literal

import numpy as np

from gpusim.config import param
from gpusim.opplan import OpPlan, Pass
from gpusim.schemes.base import Scheme, register
from gpusim.schemes.common.alu import COMPOSITE, compare_exchange
from gpusim.schemes.common.arrays import (entry_index, pixel_key, record_layout, smallest_per_pixel,
                                          sort_short_runs)
from gpusim.schemes.common.depth_filter import emit_order
from gpusim.schemes.common.groups import PixelGroups
from gpusim.schemes.common.kbuffer_entries import (ENTRY_DOC, UNIFORM_ALPHA_DOC, EntryFormat, access_layout,
                                                   check_entry, entry_bytes, entry_image, payload_bytes, per_access,
                                                   resolve_alpha, resolve_alu)
from gpusim.schemes.common.kbuffer_replay import make_replay
from gpusim.schemes.common.reorder import batch_plan, centroid_order
from gpusim.schemes.common.storage import ColourFormat
from gpusim.schemes.result import CapturedLists, SchemeResult, Stat, Structure

FRAMEBUFFER_BYTES = 16   # RGBA32F off-screen framebuffer (one MRT attachment)


@register("kbuffer")
@dataclass(frozen=True)
class KBuffer(Scheme):
    summary = "k-buffer: k-entry RMW pool per pixel (peel or sort-and-blend)"

    k: int = param(8, unit="entries/pixel", doc="k-buffer entries per pixel", min=1, max=64)
    mode: Literal["peel", "sort-blend"] = param("peel", doc="keep the k nearest, or blend a k-nearly-sorted stream")
    colour_format: ColourFormat = param("rgba32f", doc="entry colour format (the paper's FP32 MRTs)")
    entry: EntryFormat = param("depth-colour", doc=ENTRY_DOC)
    uniform_alpha: float | None = param(None, unit="1", doc=UNIFORM_ALPHA_DOC, min=0.0, max=1.0)
    order: Literal["submission", "centroid"] = param("submission", doc="primitive order (centroid: sort heuristic)")
    batch: int = param(0, unit="primitives", doc="primitives per batch with a flush between (0: no batching)", min=0)
    hw: Literal["texture-rmw", "scoreboard", "blender"] = param(
        "texture-rmw", doc="where the RMW runs: texture reads in the shader (current hardware), behind a "
                           "dispatch scoreboard (proposal 1), or in a programmable blender (proposal 2)")

    def __post_init__(self) -> None:
        check_entry(self.entry, self.colour_format)

    def simulate(self, trace) -> SchemeResult:
        n, P, k = len(trace), trace.pixel_count, self.k
        submission = centroid_order(trace) if self.order == "centroid" else np.arange(n)
        t = trace.subset(submission) if self.order == "centroid" else trace
        g = PixelGroups(t)
        pix = g.pix
        fmt, cf = self.entry, self.colour_format
        slots, slot_bytes = access_layout(fmt, cf, k)      # k entries, or ceil(k / 4) texels of Z-only entries
        blend = self.mode == "sort-blend"

        passes = [Pass("clear", "clear", "entry")]
        shading = "none" if fmt == "z" else "colour"       # Z-only entries: the fragment's colour is not needed
        if self.batch:
            batches, prims = batch_plan(t, self.batch, self.order == "centroid")
            n_batches = len(prims)
            for b in range(n_batches):
                if b:
                    passes.append(Pass(f"flush {b}", "flush", "none"))
                passes.append(Pass(f"capture batch {b}", "geometry", "fragment", primitives=int(prims[b]),
                                   shading=shading))
            frag_pass = 1 + 2 * batches
        else:
            n_batches = 1
            passes.append(Pass("capture", "geometry", "fragment", shading=shading))
            frag_pass = 1
        passes.append(Pass("resolve", "fullscreen", "pixel"))
        resolve = len(passes) - 1
        structures = ["kbuffer"] + (["framebuffer"] if blend else [])
        plan = OpPlan(passes, structures)
        plan.add(0, "store", "kbuffer", P * slots, 1, lambda i, s: i * slot_bytes, slot_bytes)
        if blend:
            plan.add(0, "store", "framebuffer", P, 1, lambda i, s: i * FRAMEBUFFER_BYTES,
                     FRAMEBUFFER_BYTES)
        shade = COMPOSITE + resolve_alu(fmt)                       # an entry's colour made and composited
        if blend:                                                   # a full buffer composites its nearest
            full = np.zeros(n, bool)
            full[g.by_arrival[g.arrival_by_arrival >= k]] = True
            composite = shade * full
        else:
            composite = 0
        add_rmw(plan, frag_pass, n, pix, P, k, fmt, cf, self.hw, framebuffer=blend, extra=composite)
        pixels = P
        plan.add(resolve, "load", "kbuffer", pixels, slots,
                 lambda i, s: entry_index(i, s, slots, P, record_layout(self.hw)) * slot_bytes, slot_bytes)
        if blend:
            plan.add(resolve, "load", "framebuffer", pixels, 1, lambda i, s: i * FRAMEBUFFER_BYTES,
                     FRAMEBUFFER_BYTES)
        plan.compute(resolve, pixels, np.minimum(g.count, k) * shade)   # the stored entries, nearest first

        stats: dict[str, Stat] = {"batches": Stat(n_batches, "batches", "geometry batches (flushes + 1)")}
        if blend:
            order, order_pix, order_key = emit_order(pix, g.key, g.by_arrival, k, return_keys=True)
            kept_count = n
            z = t.z[order]
            same = order_pix[1:] == order_pix[:-1]
            # z[i + 1] < z[i]: the float64 difference of two float32 depths has the sign of theirs
            stats["misordered_pairs"] = Stat(int(np.count_nonzero(same & (z[1:] < z[:-1]))), "fragment pairs",
                                             "consecutively composited fragments in the wrong depth order")
            stats["max_disorder"] = Stat(emitted_disorder(order_pix, order_key), "positions", MAX_DISORDER_DOC)
            used = int(np.minimum(g.count, k).sum())
        else:
            order = smallest_per_pixel(pix, g.key, k, order=g.by_depth)
            order_pix = pix[order]
            kept_count = len(order)
            used = kept_count
        image_of = partial(entry_image, t, pix, entry=fmt, colour_format=cf,
                           uniform_alpha=resolve_alpha(fmt, self.uniform_alpha, g))
        struct = [Structure("kbuffer", entry_bytes(fmt, cf), P * slots * per_access(fmt), used, entries_doc(fmt, cf))]
        if blend:
            struct.append(Structure("framebuffer", FRAMEBUFFER_BYTES, P, g.covered, "RGBA32F blend target (MRT)"))
        dropped = n - kept_count
        extras = {}
        if self.hw != "blender":
            extras["rmw_replay"] = make_replay(pix, g.key, k, blend, image_of, order)
        return SchemeResult(self.name, self.params(), image_of(order, order_pix=order_pix), n, g.covered, struct,
                            plan, geometry_passes=1, dropped_fragments=int(dropped),
                            overflowed_pixels=0 if blend else int(np.count_nonzero(g.count > k)),
                            lists=CapturedLists(order_pix, submission[order]), stats=stats,
                            submission=submission, extras=extras)


MAX_DISORDER_DOC = ("largest displacement of a composited fragment in its pixel's sequence from depth order "
                    "(seed 004 Table 2's Max Error): max over fragments of the distance from its composited "
                    "position to the range of positions its depth holds in the sorted sequence (equal depths "
                    "in any order are in place)")


def max_disorder(pix_sorted: np.ndarray, key_sorted: np.ndarray, pix_emitted: np.ndarray,
                 key_emitted: np.ndarray) -> int:
    """The largest number of positions a fragment is out of place in its pixel's composited sequence.

    ``pix_sorted``, ``key_sorted``: every fragment's pixel and depth key, grouped by pixel ascending, nearest
    first; ``pix_emitted``, ``key_emitted``: the same fragments in the order they were composited, grouped by
    pixel ascending (so a pixel's sequence starts at the same index in both). A fragment at position i of its
    pixel's composited sequence whose depth occupies positions lo..hi of the sorted sequence (lo fragments of
    the pixel strictly nearer, hi + 1 nearer or equal) is max(0, lo - i, i - hi) positions out of place: equal
    depths in any order count as in order. 0 for a sorted sequence, m - 1 for m distinct depths reversed.
    """
    if len(pix_emitted) != len(pix_sorted):
        raise ValueError(f"max_disorder: {len(pix_emitted)} composited fragments against {len(pix_sorted)} sorted; "
                         "pass the same fragments in both orders")
    if not len(pix_sorted):
        return 0
    sorted_words = pixel_key(pix_sorted, key_sorted)
    words = pixel_key(pix_emitted, key_emitted)
    position = np.arange(len(words), dtype=np.int64)
    lo = np.searchsorted(sorted_words, words, side="left").astype(np.int64)
    hi = np.searchsorted(sorted_words, words, side="right").astype(np.int64) - 1
    return int(np.maximum(np.maximum(lo - position, position - hi), 0).max())


def emitted_disorder(pix_emitted: np.ndarray, key_emitted: np.ndarray) -> int:
    """:func:`max_disorder` of fragments in the order they were composited (``pix_emitted`` grouped by pixel
    ascending, ``key_emitted`` their depth keys), without the sorted sequence: each pixel's keys are sorted
    in place (ties in composited order), so sorted position s holds composited position ``perm[s]``, whose
    depth occupies the positions of its run of equal keys."""
    n = len(pix_emitted)
    if not n:
        return 0
    perm = sort_short_runs(pix_emitted, key_emitted)
    key_sorted = key_emitted[perm]
    new = np.empty(n, bool)
    new[0] = True
    np.not_equal(key_sorted[1:], key_sorted[:-1], out=new[1:])
    new[1:] |= pix_emitted[1:] != pix_emitted[:-1]                      # the runs stay where they are
    first = np.flatnonzero(new)
    group = np.cumsum(new) - 1
    lo = first[group]
    hi = np.r_[first[1:], n][group] - 1
    return int(np.maximum(np.maximum(lo - perm, perm - hi), 0).max())


def entries_doc(entry: str, colour_format: str) -> str:
    """The k-buffer structure's description for entry format ``entry``."""
    return {"depth-colour": f"k entries of depth + {colour_format} colour",
            "rgbz": "k RGBA32F texels of RGB + depth (RGBZ)",
            "z": "k depths, four to an RGBA32F texel (Z-only)"}[entry]


def add_rmw(plan: OpPlan, pass_index: int, threads, pix: np.ndarray, pixel_count: int, k: int, entry: str,
            colour_format: str, hw: str, framebuffer: bool = False, extra=0, count=1, seq_pass=None) -> None:
    """Add each fragment thread's read-modify-write of its pixel's ``k`` entries (section 3.2) to pass
    ``pass_index`` of ``plan``.

    ``threads``: the fragment threads (an array, or n for 0..n-1); ``pix[i]`` the pixel of thread ``i``.
    ``hw`` as :class:`KBuffer`'s: an ``rmw_read`` of each of the pixel's k entries (of each of its ceil(k / 4)
    texels with ``entry = z``), the insertion into the k sorted entries (plus ``extra`` instructions per
    thread), as many ``rmw_write`` s, behind a ``scoreboard`` dispatch with ``scoreboard``, the entry texels in
    ``slots`` render targets; or with ``blender`` one ``program_blend`` on the pixel's record, its entry texels
    adjacent (:func:`gpusim.schemes.common.arrays.record_layout`). ``framebuffer``: sort-and-blend's RGBA32F
    target is read and written too (by the shader, or by the ROP's blend stage after the program).
    ``count`` and ``seq_pass``: thread ``i`` repeats its RMW in passes ``seq_pass[0 .. count[i] - 1]`` (the
    multi-pass k-buffer's peels), one group per entry texel, so the plan holds each thread once however many
    passes it takes part in.
    """
    slots, slot_bytes = access_layout(entry, colour_format, k)
    layout = record_layout(hw)
    at = lambda i, s: entry_index(pix[i], s, slots, pixel_count, layout) * slot_bytes  # noqa: E731

    def entries(op: str, dep: bool) -> None:
        """``op`` on each of the pixel's entry texels: ``slots`` ops a thread, or a group per texel across passes."""
        if seq_pass is None:
            plan.add(pass_index, op, "kbuffer", threads, slots, at, slot_bytes, dep=dep)
            return
        for texel in range(slots):
            plan.add(pass_index, op, "kbuffer", threads, count, lambda i, s, t=texel: at(i, t), slot_bytes, dep=dep,
                     seq_pass=seq_pass)

    fb = lambda i, s: pix[i] * FRAMEBUFFER_BYTES  # noqa: E731
    if hw == "blender":
        plan.add(pass_index, "program_blend", "kbuffer", threads, count, lambda i, s: at(i, 0), slots * slot_bytes,
                 seq_pass=seq_pass)      # the record from its first entry on
        if framebuffer:                  # the colour the program emits, blended into the target
            plan.add(pass_index, "blend", "framebuffer", threads, count, fb, FRAMEBUFFER_BYTES, seq_pass=seq_pass)
        return
    if hw == "scoreboard":
        plan.add(pass_index, "scoreboard", "kbuffer", threads, count, lambda i, s: pix[i] * slot_bytes, 0,
                 seq_pass=seq_pass)
    entries("rmw_read", hw == "scoreboard")
    if framebuffer:
        plan.add(pass_index, "rmw_read", "framebuffer", threads, count, fb, FRAMEBUFFER_BYTES, seq_pass=seq_pass)
    # modify: insert into the k sorted entries (a compare-exchange of the depth and what the entry holds beside it)
    plan.compute(pass_index, threads, k * compare_exchange(payload_bytes(entry, colour_format)) + extra,
                 count=count, seq_pass=seq_pass)
    entries("rmw_write", True)
    if framebuffer:
        plan.add(pass_index, "rmw_write", "framebuffer", threads, count, fb, FRAMEBUFFER_BYTES, dep=True,
                 seq_pass=seq_pass)
