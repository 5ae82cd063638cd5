"""FreePipe's multi-depth test scheme, MDTS (seed 000 section 4.1; seed 001 "CUDP1").

A fixed array of ``layers`` 32-bit values per pixel, cleared to the maximum
integer (``direction = min``; 0 for ``max``). Each fragment walks its pixel's
array with ``atomicMin`` (Table 1 of seed 000): it stops at the first empty
entry; otherwise it carries max(new, old) to the next entry, and whatever is
carried past the last entry is discarded. Whatever the interleaving, each
pixel ends with its ``layers`` smallest values in ascending order, and the j-th
fragment to reach a pixel makes min(j, layers) atomic operations (every atomic
depends on the value the previous one returned).

Colour (the array holds depths only):

* ``packing = false``: a second geometry pass captures colour, as the paper
  suggests ("an additional pass ... performance will be halved"). Each fragment
  loads the array until it finds its own depth and stores its colour in the
  same entry of ``colour_array``. Fragments of *equal* depth find the same first
  entry: the later one's colour wins and the other entry keeps the cleared
  colour (transparent black), counted as ``colour_collisions``.
* ``packing = true`` (section 4.1.2): one pass; depth is mapped to [0.5, 1), 20
  bits kept, and the 24-bit RGB colour split into two 12-bit halves stored in
  the free low bits of two copies (``depth_array`` and ``colour_array``), each
  updated by its own atomic chain. The colour has no alpha: ``alpha`` (or the
  trace's single alpha) is used for every fragment. Colour mismatches (halves
  from different fragments) and order inversions are measured, not assumed.

* ``colour = "none"``: depths only, one geometry pass and no colour array, as
  a translucency effect that needs only the thickness between layers (seed
  000 Table 3, whose 20 MB is the depth array alone); the image shows each
  kept depth's own fragment colour.

Passes: ``clear`` (one store per entry of each array), ``capture``, (``colour``),
``resolve`` (one thread per pixel: loads entries until the first empty one,
then composites them front to back; the array is already in depth order).

ALU work beyond each operation's own (gpusim.schemes.common.alu): an atomic
iteration's ``max(new, old)`` and compare are the operation's; with packing a
fragment packs its two words before the chains (``PACK_DEPTH_COLOUR`` each);
the resolve unpacks each stored entry's colour (``UNPACK_RGBA8`` for an rgba8
``colour_array``; with packing ``UNPACK_SPLIT_RGB24``, the 12-bit halves
re-joined) and composites it (``COMPOSITE``).
With ``direction = max`` the arrays hold the *farthest* ``layers`` values in
descending order, and a value equal to 0 (the empty value) cannot be stored.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

import numpy as np

from gpusim.config import param
from gpusim.errors import GpusimError
from gpusim.opplan import OpPlan, Pass
from gpusim.schemes.base import Scheme, composite_image, register
from gpusim.schemes.common.alu import COMPOSITE, PACK_DEPTH_COLOUR, UNPACK_RGBA8, UNPACK_SPLIT_RGB24
from gpusim.schemes.common.arrays import (Layout, count_before_in_pixel, entry_index, put_rows, rank_in_runs,
                                          reversed_runs, smallest_per_pixel)
from gpusim.schemes.common.depthkey import EMPTY, colour24, colour24_rgb, packed_depth
from gpusim.schemes.common.groups import PixelGroups, distinct_ids
from gpusim.schemes.common.storage import COLOUR_BYTES, DEPTH_BYTES, ColourFormat, store_colour
from gpusim.schemes.result import CapturedLists, SchemeResult, Stat, Structure


@register("freepipe-mdts")
@dataclass(frozen=True)
class FreePipeMDTS(Scheme):
    summary = "FreePipe multi-depth test: per-pixel arrays filled by atomicMin chains"

    layers: int = param(20, unit="entries/pixel", doc="array entries per pixel (nearest fragments kept)", min=1)
    direction: Literal["min", "max"] = param("min", doc="atomicMin (ascending) or atomicMax (descending)")
    packing: bool = param(False, doc="pack depth + colour into two 32-bit copies (section 4.1.2), one pass")
    alpha: float | None = param(None, unit="1", doc="constant alpha for packing (default: the trace's single alpha)",
                                min=0.0, max=1.0)
    colour_format: ColourFormat = param("rgba8", doc="colour_array format without packing")
    colour: Literal["pass", "none"] = param("pass", doc="without packing, how colour is captured: a second "
                                            "geometry pass (pass), or not at all (none: depths only, one pass, "
                                            "as a translucency effect that needs only the thickness between "
                                            "layers, seed 000 Table 3)")
    layout: Layout = param("pixel-major", doc="entry layout: pixel-major ([x][y][i]) or layer-major")

    def simulate(self, trace) -> SchemeResult:
        g = PixelGroups(trace)
        P, L, n = trace.pixel_count, self.layers, len(trace)
        pix, layout = g.pix, self.layout
        atomic = "atomic_min" if self.direction == "min" else "atomic_max"
        empty = EMPTY if self.direction == "min" else np.uint32(0)
        if self.packing:
            alpha = self._packing_alpha(trace, g)
            hi_lo = colour24(trace.rgba[:, :3])
            depth20 = packed_depth(trace.z)
            values = {"depth_array": depth20 | (hi_lo >> np.uint32(12)),
                      "colour_array": depth20 | (hi_lo & np.uint32(0xFFF))}
        else:
            values = {"depth_array": g.key}
        cb = 4 if self.packing else COLOUR_BYTES[self.colour_format]
        depth_only = not self.packing and self.colour == "none"

        # the capture pass needs the colour only where it packs it with the depth; a colour pass shades otherwise
        passes = [Pass("clear", "clear", "entry"),
                  Pass("capture", "geometry", "fragment", software=True, shading="colour" if self.packing else "none")]
        if not self.packing and not depth_only:
            passes.append(Pass("colour", "geometry", "fragment", software=True))
        passes.append(Pass("resolve", "fullscreen", "pixel"))
        resolve_pass = len(passes) - 1
        structures = ["depth_array"] if depth_only else ["depth_array", "colour_array"]
        plan = OpPlan(passes, structures)
        entries = P * L
        plan.add(0, "store", "depth_array", entries, 1, lambda i, s: i * DEPTH_BYTES, DEPTH_BYTES)
        if not depth_only:
            plan.add(0, "store", "colour_array", entries, 1, lambda i, s: i * cb, cb)

        kept: dict[str, np.ndarray] = {}
        kept_pix: dict[str, np.ndarray] = {}
        frags = n
        if self.packing:   # depth and a colour half packed into each of the two words
            plan.compute(1, frags, len(values) * PACK_DEPTH_COLOUR, dep=False)
        for name, value in values.items():
            storable = value != empty
            sort_value = value if self.direction == "min" else np.uint32(0xFFFFFFFF) - value
            every = bool(storable.all())
            nearest = every and not self.packing and self.direction == "min"    # sort_value is the depth key
            if nearest:
                near = g.rank_by_depth < L                                     # each pixel's nearest L
                kept[name], kept_pix[name] = g.by_depth[near], g.pix_by_depth[near]
            else:
                kept[name], kept_pix[name] = smallest_per_pixel(pix, sort_value, L, None if every
                                                                else np.flatnonzero(storable), with_pixels=True)
            # a chain ends at the first empty entry: one atomic per entry filled before it + 1, at most L
            before = g.arrival if every else count_before_in_pixel(pix, g.by_arrival, storable)
            filled_before = np.minimum(before, L)
            chain = np.minimum(filled_before + 1, L)
            size = DEPTH_BYTES if name == "depth_array" else cb
            plan.add(1, atomic, name, frags, chain,
                     lambda i, s: entry_index(pix[i], s, L, P, layout) * size, size, dep=True)

        kd = kept["depth_array"]
        kept_n = np.bincount(kept_pix["depth_array"], minlength=P)
        stats: dict[str, Stat] = {}
        if self.packing:
            order, rgba, stats = self._resolve_packed(trace, values, kept, kept_pix, alpha, hi_lo)
        elif depth_only:                 # the effect shades each layer itself: the image shows its fragment's colour
            order, rgba = kd, store_colour(trace.rgba[kd], self.colour_format)
            rgba[trace.opaque[kd], 3] = 1.0
        else:
            order, rgba, stats = self._colour_pass(trace, g, plan, kd, nearest)
        res = lambda i, s: entry_index(i, s, L, P, layout)  # noqa: E731
        sentinel = kept_n + (kept_n < L)          # the load that finds the first empty entry ends the walk
        pixels = P
        plan.add(resolve_pass, "load", "depth_array", pixels, sentinel,
                 lambda i, s: res(i, s) * DEPTH_BYTES, DEPTH_BYTES)
        if not depth_only:
            plan.add(resolve_pass, "load", "colour_array", pixels, kept_n, lambda i, s: res(i, s) * cb, cb)
        # in registers: unpack each loaded entry's colour and composite it (the array is in depth order)
        unpack = (UNPACK_SPLIT_RGB24 if self.packing else 0 if depth_only
                  else UNPACK_RGBA8 if self.colour_format == "rgba8" else 0)
        plan.compute(resolve_pass, pixels, kept_n * (COMPOSITE + unpack))

        if self.direction == "max":      # entries descend: the resolve reads them back to front
            order, rgba = self._reverse_runs(pix, order, rgba)
        order_pix = pix[order]
        image = composite_image(trace, order_pix, rgba, rgba[:, 3])
        struct = [Structure("depth_array", DEPTH_BYTES, P * L, len(kd),
                            "32-bit depth per entry" + (" (20-bit depth + 12 colour bits)" if self.packing else ""))]
        if not depth_only:
            struct.append(Structure("colour_array", cb, P * L, len(kept["colour_array"]) if self.packing else len(kd),
                                    "20-bit depth + 12 colour bits per entry" if self.packing
                                    else f"{self.colour_format} colour per entry (second pass)"))
        accesses = plan.accesses()
        atomics = int(accesses.get("depth_array", {}).get(atomic, 0))
        stats["atomic_operations"] = Stat(sum(v.get(atomic, 0) for v in accesses.values()), "operations",
                                          f"{atomic} operations in the capture pass (all arrays)")
        stats["depth_chain_atomics"] = Stat(atomics, "operations", f"{atomic} operations on depth_array")
        return SchemeResult(self.name, self.params(), image, n, g.covered, struct, plan,
                            geometry_passes=1 if self.packing or depth_only else 2,
                            dropped_fragments=int(n - len(kd)),
                            overflowed_pixels=int(np.count_nonzero(g.count > kept_n)),
                            lists=CapturedLists(order_pix, order), stats=stats)

    # ---------------------------------------------------------------- colour
    def _colour_pass(self, trace, g, plan, kd, nearest: bool):
        """Second geometry pass: find own depth in the final array, store colour there."""
        P, L, n, pix = trace.pixel_count, self.layers, len(trace), g.pix
        cb = COLOUR_BYTES[self.colour_format]
        if nearest:
            found, slot, winner = self._find_nearest(g, len(kd))
        else:
            found, slot, winner = self._find(g, kd)
        layout = self.layout
        plan.add(2, "load", "depth_array", n, slot + 1,
                 lambda i, s: entry_index(pix[i], s, L, P, layout) * DEPTH_BYTES, DEPTH_BYTES)
        writers = np.flatnonzero(found)
        plan.add(2, "store", "colour_array", writers, 1,
                 lambda i, s: entry_index(pix[writers[i]], slot[writers[i]], L, P, layout) * cb, cb, dep=True)
        rgba = np.zeros((len(kd), 4), np.float32)          # cleared colour: transparent black
        has = winner >= 0
        put_rows(rgba, np.flatnonzero(has), store_colour(np.take(trace.rgba, winner[has], axis=0), self.colour_format))
        rgba[has & trace.opaque[np.maximum(winner, 0)], 3] = 1.0
        stats = {"colour_collisions": Stat(int(len(writers) - has.sum()), "fragments",
                                           "colour stores overwritten by an equal-depth fragment's store")}
        return kd, rgba, stats

    def _find(self, g, kd):
        """Each fragment's own value in the final arrays: (found, slot of its walk's last load, the last
        writer of each entry (submission order) or -1)."""
        n, L = g.n, self.layers
        slot_of_kept = rank_in_runs(g.pix[kd])
        value = np.empty(n, np.int64)          # id of each fragment's (pixel, depth) value
        value[g.by_depth] = distinct_ids(g.pix_by_depth, g.key_by_depth)[0]
        # equal values sit next to each other in the array: the first occurrence is the lowest slot
        kept_value = value[kd]
        first = np.flatnonzero(np.r_[True, kept_value[1:] != kept_value[:-1]]) if len(kd) else kd
        entry_of_value = np.full(n, -1, np.int64)
        entry_of_value[kept_value[first]] = first
        entry = entry_of_value[value]          # the entry holding the fragment's value, or -1
        found = entry >= 0
        # loads: walk until own value (slot + 1 loads) or to the end of the array (L loads)
        slot = np.where(found, slot_of_kept[np.maximum(entry, 0)] if len(kd) else 0, L - 1)
        writers = np.flatnonzero(found)
        winner = np.full(len(kd), -1, np.int64)
        np.maximum.at(winner, entry[writers], writers)
        return found, slot, winner

    def _find_nearest(self, g, kept: int):
        """:meth:`_find` when the arrays hold each pixel's nearest fragments: in depth order, where a value's
        fragments sit together (submission order) and the arrays hold each pixel's first ``layers``."""
        n, L, order = g.n, self.layers, g.by_depth
        rank = g.rank_by_depth
        ids = distinct_ids(g.pix_by_depth, g.key_by_depth)[0]
        first = np.flatnonzero(np.r_[True, ids[1:] != ids[:-1]][:n])     # each value's first fragment
        last = np.append(first[1:], n)[:len(first)] - 1                     # ... and its last: the winner
        stored = rank[first] < L                # the value's first fragment took an entry: its slot
        entry = np.where(stored, np.cumsum(rank < L)[first] - 1, -1)
        found, slot = np.empty(n, bool), np.empty(n, np.int64)
        found[order] = stored[ids]
        slot[order] = np.where(stored, rank[first], L - 1)[ids]
        winner = np.full(kept, -1, np.int64)
        winner[entry[stored]] = order[last[stored]]
        return found, slot, winner

    # ---------------------------------------------------------------- packing
    def _packing_alpha(self, trace, g) -> float:
        if self.alpha is not None:
            return float(self.alpha)
        if len(trace) == 0:
            return 1.0
        lo, hi = float(g.alpha.min()), float(g.alpha.max())
        if lo != hi:
            raise GpusimError(f"packing stores no alpha (seed 000 section 4.1.2 assumes a constant one) but this "
                              f"trace's alpha ranges {lo:g}..{hi:g} (opaque = 1); pass --param alpha=VALUE to use one")
        return lo

    def _resolve_packed(self, trace, values, kept, kept_pix, alpha, true24):
        kd, kc = kept["depth_array"], kept["colour_array"]
        pd_, pc = kept_pix["depth_array"], kept_pix["colour_array"]
        # the resolve reads entry i of both arrays; use the slots both arrays filled
        both = np.minimum(np.bincount(pd_, minlength=trace.pixel_count), np.bincount(pc, minlength=trace.pixel_count))
        in_both = rank_in_runs(pd_) < both[pd_]
        kd, pd_ = kd[in_both], pd_[in_both]
        kc = kc[rank_in_runs(pc) < both[pc]]
        depth_word = values["depth_array"][kd]
        c24 = ((depth_word & np.uint32(0xFFF)) << np.uint32(12)) | (values["colour_array"][kc] & np.uint32(0xFFF))
        rgba = np.empty((len(kd), 4), np.float32)
        rgba[:, :3] = colour24_rgb(c24)
        rgba[:, 3] = alpha
        true24 = true24[kd]
        z = trace.z[kd]
        same_pixel = pd_[1:] == pd_[:-1]
        step = np.diff(z) if self.direction == "min" else -np.diff(z)
        inversions = int(np.count_nonzero(same_pixel & (step < 0)))
        d20 = depth_word >> np.uint32(12)
        collisions = int(np.count_nonzero(same_pixel & (d20[1:] == d20[:-1]) & (z[1:] != z[:-1])))
        stats = {
            "packing_colour_mismatches": Stat(int(np.count_nonzero(c24 != true24)), "entries",
                                              "entries whose reassembled colour is not their depth's fragment's"),
            "packing_order_inversions": Stat(inversions, "entry pairs",
                                             "adjacent entries stored in the wrong true-depth order"),
            "packing_depth_collisions": Stat(collisions, "entry pairs",
                                             "adjacent entries whose distinct depths share a 20-bit packed depth"),
        }
        return kd, rgba, stats

    @staticmethod
    def _reverse_runs(pix, order, rgba):
        key = reversed_runs(pix[order])
        return order[key], np.take(rgba, key, axis=0)
