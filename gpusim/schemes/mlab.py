"""Multi-layer alpha blending (Salvi & Vaidyanathan, I3D 2014), approximate past ``layers`` fragments.

Each pixel keeps an array of ``layers`` entries (depth, premultiplied colour, transmittance), nearest first,
cleared to (empty, black, 1). Every fragment, in submission order under pixel synchronisation, reads its
pixel's entries, inserts (z, a c, 1 - a) at its depth (behind stored entries of equal depth: the first
submitted stays nearer), and when that leaves ``layers`` + 1 occupied entries merges the two farthest, the
paper's merge: the nearer keeps its depth, its colour becomes rgb + rgb' T and its transmittance T T'.
The resolve composites the entries front to back over the background:
C = sum_i (prod_(j<i) T_j) rgb_i + (prod T_j) background. With at most ``layers`` fragments at a pixel
nothing merges and the image is the sorted composite (the exact reference, up to the storage format).
A fragment of alpha 0 is discarded by its shader (it would take an entry and force a merge while adding
nothing).

Storage (``colour_format``): the paper's layer is a 32-bit float depth and an RGBA8 word holding the
premultiplied colour and the transmittance (8 bytes; 2 layers 16 bytes per pixel, 4 layers 32): a
premultiplied colour and a transmittance are in [0, 1], so unorm8 holds them, and every value written (an
inserted fragment, a merge) is rounded to the format. ``rgba16f`` and ``rgba32f`` are wider alternatives.

Ordering (``hw``): the read-modify-write of a pixel's entries is ordered, never a hazard. ``blender``
models it as the ROP's programmable blender (``program_blend``: the fragment's insertion and merge run at
the ROP on the ``layers`` entries, committed in submission order, as the k-buffer's proposal 2; the
entries are then the pixel's record, adjacent, as a multisampled pixel's samples); ``rov``
as a rasterizer-ordered view on the SM (Intel's PixelSync, the paper's platform): the pixel's interlock
(the ``scoreboard`` operation holds a fragment while another of its pixel is in flight), then ``layers``
reads, the insertion and merge on the SM, and ``layers`` writes, an entry in each of ``layers`` render
targets (gpusim.schemes.common.arrays.record_layout).

The functional model places each pixel's first ``layers`` fragments with one sort (they never merge) and runs
every later one's insertion and merge in a compiled kernel (gpusim.jit) where numba is installed, else rank
by rank over the pixels in numpy (and always for ``rgba16f``: numba has no float16): the same results bit for
bit.

ALU work (gpusim.schemes.common.alu): the fragment's premultiplied outputs (``MLAB_FRAGMENT``); with
``rov`` also the insertion (``layers`` compare-exchanges of an entry) and the merge (``MLAB_MERGE``) on the
SM; the resolve composites the occupied entries (``COMPOSITE`` each).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

import numpy as np

from gpusim.config import param
from gpusim.jit import compiled_once
from gpusim.opplan import OpPlan, Pass
from gpusim.schemes.base import Scheme, register
from gpusim.schemes.common.alu import COMPOSITE, MLAB_FRAGMENT, MLAB_MERGE, compare_exchange
from gpusim.metrics.composite import runs_by_length
from gpusim.schemes.common.arrays import entry_index, lex_order, put_rows, rank_in_runs, record_layout, take_rows
from gpusim.schemes.common.groups import PixelGroups
from gpusim.schemes.common.storage import COLOUR_BYTES, DEPTH_BYTES, ColourFormat, rounder
from gpusim.schemes.result import SchemeResult, Stat, Structure

EMPTY = float(0xFFFFFFFF)    # depth key of an empty entry (behind every depth in [0, 1])


def insert_and_merge(keys: np.ndarray, values: np.ndarray, key: np.ndarray, value: np.ndarray,
                     rnd) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """One MLAB step on m pixels: entries ``keys`` (m, L) ascending (``EMPTY`` last) and ``values`` (m, L, 4)
    (premultiplied rgb, transmittance; float32) take the fragment (``key`` (m,), ``value`` (m, 4)) behind their
    entries of equal depth; where L + 1 entries are then occupied the two farthest merge. Returns the new
    (keys, values) and whether each pixel merged."""
    m, L = keys.shape
    pos = (keys <= key[:, None]).sum(axis=1)                      # entries at or in front of the fragment
    ext_k = np.empty((m, L + 1), keys.dtype)
    ext_v = np.empty((m, L + 1, 4), values.dtype)
    for j in range(L + 1):       # slot j: old entry j in front of the fragment, the fragment, old entry j - 1 behind
        behind_k, behind_v = (keys[:, j - 1], values[:, j - 1]) if j else (key, value)
        here_k, here_v = np.where(pos == j, key, behind_k), np.where((pos == j)[:, None], value, behind_v)
        if j < L:
            here_k, here_v = np.where(pos > j, keys[:, j], here_k), np.where((pos > j)[:, None], values[:, j], here_v)
        ext_k[:, j], ext_v[:, j] = here_k, here_v
    merged = ext_k[:, L] != EMPTY
    near, far = ext_v[:, L - 1], ext_v[:, L]
    mix = np.empty_like(near)
    mix[:, :3] = rnd(near[:, :3] + far[:, :3] * near[:, 3:4])
    mix[:, 3] = rnd(near[:, 3] * far[:, 3])
    ext_v[:, L - 1] = np.where(merged[:, None], mix, near)
    return ext_k[:, :L], ext_v[:, :L], merged


def _later_fragments(keys, vals, merges, covered, start, length, key, value, L, unorm8):
    """:func:`insert_and_merge` for every fragment past each pixel's first ``L``, pixel by pixel in arrival order
    (compiled with numba; pixels are independent, so the order across them changes nothing). ``unorm8``: round
    merged values to RGBA8 as :func:`~gpusim.schemes.common.storage.rounder` does, else keep float32."""
    zero, one, scale = np.float32(0.0), np.float32(1.0), np.float32(255.0)
    ext_k = np.empty(L + 1, np.float64)
    ext_v = np.empty((L + 1, 4), np.float32)
    for r in range(len(covered)):
        if length[r] <= L:
            break                                    # runs longest first
        p = covered[r]
        for j in range(L, length[r]):
            i = start[r] + j
            pos = 0
            for s in range(L):
                if keys[p, s] <= key[i]:
                    pos += 1
            for s in range(L + 1):
                if s < pos:
                    src = s
                elif s == pos:
                    src = -1
                else:
                    src = s - 1
                if src < 0:
                    ext_k[s] = key[i]
                    for c in range(4):
                        ext_v[s, c] = value[i, c]
                else:
                    ext_k[s] = keys[p, src]
                    for c in range(4):
                        ext_v[s, c] = vals[p, src, c]
            if ext_k[L] != EMPTY:                    # L + 1 entries: the two farthest merge
                for c in range(4):
                    mixed = ext_v[L - 1, c] * ext_v[L, 3] if c == 3 else \
                        ext_v[L - 1, c] + ext_v[L, c] * ext_v[L - 1, 3]
                    if unorm8:
                        mixed = np.rint(min(max(mixed, zero), one) * scale) / scale
                    ext_v[L - 1, c] = mixed
                merges[p] += 1
            for s in range(L):
                keys[p, s] = ext_k[s]
                for c in range(4):
                    vals[p, s, c] = ext_v[s, c]


_KERNEL: list = []     # [the compiled _later_fragments, or None], made on first use


def _compiled_later_fragments():
    return compiled_once(_KERNEL, _later_fragments)


def resolve_layers(values: np.ndarray, background: np.ndarray) -> np.ndarray:
    """Front-to-back composite of each pixel's entries (P, L, 4) over ``background`` (3,), float32: (P, 3)."""
    colour = np.zeros((len(values), 3), np.float32)
    trans = np.ones(len(values), np.float32)
    for j in range(values.shape[1]):
        colour += trans[:, None] * values[:, j, :3]
        trans *= values[:, j, 3]
    return colour + trans[:, None] * np.asarray(background, np.float32)


@register("mlab")
@dataclass(frozen=True)
class MultiLayerAlphaBlending(Scheme):
    summary = "multi-layer alpha blending (Salvi & Vaidyanathan 2014): per-pixel layers, merge on overflow"

    layers: int = param(4, unit="entries/pixel", doc="blending layers per pixel (the paper: 2 or 4)", min=1, max=64)
    colour_format: ColourFormat = param("rgba8", doc="a layer's premultiplied colour and transmittance (the "
                                        "paper's RGBA8, beside a 32-bit depth)")
    hw: Literal["blender", "rov"] = param("blender", doc="the ordered read-modify-write: the ROP's programmable "
                                          "blender, or a rasterizer-ordered view (interlock) on the SM")

    def simulate(self, trace) -> SchemeResult:
        g = PixelGroups(trace)
        n, P, pix, L = len(trace), trace.pixel_count, g.pix, self.layers
        cb = COLOUR_BYTES[self.colour_format]
        entry = DEPTH_BYTES + cb
        rnd = rounder(self.colour_format)
        kept = g.alpha > 0                          # alpha 0: the shader discards it
        frags = np.flatnonzero(kept)
        count = g.count if len(frags) == n else np.bincount(pix[frags], minlength=P)
        occupied = np.minimum(count, L)

        passes = [Pass("clear", "clear", "entry"), Pass("capture", "geometry", "fragment"),
                  Pass("resolve", "fullscreen", "pixel")]
        plan = OpPlan(passes, ["layers"])
        plan.add(0, "store", "layers", P * L, 1, lambda i, s: i * entry, entry)
        layout = record_layout(self.hw)
        entry_at = lambda i, s: entry_index(pix[frags[i]], s, L, P, layout) * entry  # noqa: E731
        plan.compute(1, frags, MLAB_FRAGMENT, dep=False)
        if self.hw == "blender":               # the program on the pixel's record: its L entries adjacent
            plan.add(1, "program_blend", "layers", frags, 1, lambda i, s: entry_at(i, 0), L * entry)
        else:
            plan.add(1, "scoreboard", "layers", frags, 1, lambda i, s: pix[frags[i]] * entry, 0)
            plan.add(1, "rmw_read", "layers", frags, L, entry_at, entry, dep=True)
            plan.compute(1, frags, L * compare_exchange(cb) + MLAB_MERGE)
            plan.add(1, "rmw_write", "layers", frags, L, entry_at, entry, dep=True)
        pixels = P
        plan.add(2, "load", "layers", pixels, L, lambda i, s: entry_index(i, s, L, P, layout) * entry, entry)
        plan.compute(2, pixels, occupied * COMPOSITE)

        arrival = g.by_arrival                              # kept fragments in arrival order
        arrival = arrival if len(frags) == n else arrival[kept[arrival]]
        a = g.alpha[arrival]
        value = np.empty((len(arrival), 4), np.float32)     # in arrival order, as ``ikey`` and ``key``
        value[:, :3] = rnd(take_rows(trace.rgba, arrival)[:, :3] * a[:, None])
        value[:, 3] = rnd(np.float32(1.0) - a)
        ikey = g.key[arrival]
        key = ikey.astype(np.float64)
        keys = np.full((P, L), EMPTY)
        vals = np.zeros((P, L, 4), np.float32)
        vals[:, :, 3] = 1.0
        merges = np.zeros(P, np.int64)
        if len(arrival):
            pix_sorted = pix[arrival]
            # a pixel's first L fragments fill its entries without a merge: their insertions leave them in depth
            # order, equal depths in arrival order (a stable sort), so they are placed at once
            first = np.flatnonzero(rank_in_runs(pix_sorted) < L)
            first = first[lex_order(pix_sorted[first], ikey[first])]
            at = pix_sorted[first] * L + rank_in_runs(pix_sorted[first])     # (pixel, slot) of a pixel's entries
            keys.reshape(-1)[at] = key[first]
            put_rows(vals.reshape(P * L, 4), at, take_rows(value, first))
            # every later fragment is one insertion and merge, in arrival order (rank by rank over the pixels)
            start, length, active = runs_by_length(pix_sorted)
            covered = pix_sorted[start]
            # compiled where numba is (not for rgba16f: numba has no float16), else rank by rank in numpy
            kernel = _compiled_later_fragments() if self.colour_format != "rgba16f" else None
            if kernel is not None:
                kernel(keys, vals, merges, covered, start, length, key, value, L, self.colour_format == "rgba8")
            else:
                flat = vals.reshape(P, L * 4)
                for j in range(L, len(active)):
                    rows, i = covered[:active[j]], start[:active[j]] + j
                    k, v, merged = insert_and_merge(take_rows(keys, rows), take_rows(flat, rows).reshape(-1, L, 4),
                                                    key[i], take_rows(value, i), rnd)
                    put_rows(keys, rows, k)
                    put_rows(flat, rows, v.reshape(-1, L * 4))
                    merges[rows] += merged
        # the resolve's output saturates to [0, 1] (rounded premultiplied colours and transmittances can sum past 1)
        image = np.clip(resolve_layers(vals, trace.background), 0.0, 1.0)
        struct = [Structure("layers", entry, P * L, int(occupied.sum()), f"{L} layers of 32-bit depth + "
                            f"{self.colour_format} premultiplied colour and transmittance")]
        stats = {"merges": Stat(int(merges.sum()), "fragments", "insertions that merged the two farthest entries"),
                 "merged_pixels": Stat(int(np.count_nonzero(merges)), "pixels", "pixels where entries merged"),
                 "discarded_fragments": Stat(int(n - len(frags)), "fragments", "fragments of alpha 0 discarded")}
        return SchemeResult(self.name, self.params(), image.reshape(trace.height, trace.width, 3), n, g.covered,
                            struct, plan, geometry_passes=1, dropped_fragments=0, overflowed_pixels=0, stats=stats)
