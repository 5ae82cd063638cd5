"""FreePipe's A-buffer scheme (seed 000 section 4.2; seed 001 "CUDP2").

A per-pixel 32-bit counter and a fixed array of ``layers`` entries per pixel.
Passes:

1. ``clear`` (a CUDA kernel, one thread per counter): store 0 in every counter.
2. ``capture`` (the geometry pass): each fragment ``atomic_inc`` s its pixel's
   counter, which returns its arrival rank k; if k < layers it stores its depth
   and colour in entry k (both stores depend on the returned k). A fragment with
   k >= layers is dropped (the counter still counts it).
3. ``resolve`` (one thread per pixel): load the counter, load min(n, layers)
   depths and colours into registers, sort them there (``sort``: insertion or
   bitonic, see gpusim.schemes.common.sorting) and composite front to back
   (ALU work timed from its compare-exchanges and fragments:
   gpusim.schemes.common.alu).

Footprint: ``counter`` (4 B per pixel), ``depth_array`` (``layers`` x 4 B per
pixel), ``colour_array`` (``layers`` x the colour format per pixel). FreePipe
section 5.2's 20 MB for 512x512 with 20 layers is the 32-bit ``depth_array``;
its "+1 MB" is the ``counter``.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

import numpy as np

from gpusim.config import param
from gpusim.opplan import OpPlan, Pass
from gpusim.schemes.base import Scheme, composite_stored, register
from gpusim.schemes.common.alu import COMPARE_EXCHANGE, COMPOSITE, UNPACK_RGBA8, sort_compares
from gpusim.schemes.common.arrays import Layout, entry_index
from gpusim.schemes.common.groups import PixelGroups
from gpusim.schemes.common.sorting import sort_runs
from gpusim.schemes.common.storage import COLOUR_BYTES, DEPTH_BYTES, POINTER_BYTES, ColourFormat
from gpusim.schemes.result import CapturedLists, SchemeResult, Stat, Structure


@register("freepipe-abuffer")
@dataclass(frozen=True)
class FreePipeABuffer(Scheme):
    summary = "FreePipe A-buffer: atomicInc counter + fixed per-pixel array, sorted in a resolve pass"

    layers: int = param(20, unit="entries/pixel", doc="array entries per pixel (fragments kept per pixel)", min=1)
    colour_format: ColourFormat = param("rgba8", doc="stored colour format (rgba8 = the paper's 32-bit colour)")
    sort: Literal["insertion", "bitonic"] = param("insertion", doc="register sort in the resolve pass")
    layout: Layout = param("pixel-major", doc="entry layout: pixel-major ([x][y][i]) or layer-major")

    def simulate(self, trace) -> SchemeResult:
        g = PixelGroups(trace)
        P, L, n = trace.pixel_count, self.layers, len(trace)
        cb = COLOUR_BYTES[self.colour_format]
        kept = g.arrival < L
        kept_idx = np.flatnonzero(kept)
        kept_n = np.minimum(g.count, L)

        passes = [Pass("clear", "clear", "entry"), Pass("capture", "geometry", "fragment", software=True),
                  Pass("resolve", "fullscreen", "pixel")]
        structures = ["counter", "depth_array", "colour_array"]
        plan = OpPlan(passes, structures)
        pix, arrival, layout = g.pix, g.arrival, self.layout
        pixels = P
        plan.add(0, "store", "counter", pixels, 1, lambda i, s: i * POINTER_BYTES, POINTER_BYTES)
        frags = n
        plan.add(1, "atomic_inc", "counter", frags, 1, lambda i, s: pix[i] * POINTER_BYTES, POINTER_BYTES)
        slot = lambda i, s: entry_index(pix[kept_idx[i]], arrival[kept_idx[i]], L, P, layout)  # noqa: E731
        plan.add(1, "store", "depth_array", kept_idx, 1, lambda i, s: slot(i, s) * DEPTH_BYTES, DEPTH_BYTES, dep=True)
        plan.add(1, "store", "colour_array", kept_idx, 1, lambda i, s: slot(i, s) * cb, cb, dep=True)
        plan.add(2, "load", "counter", pixels, 1, lambda i, s: i * POINTER_BYTES, POINTER_BYTES)
        res = lambda i, s: entry_index(i, s, L, P, layout)  # noqa: E731
        plan.add(2, "load", "depth_array", pixels, kept_n, lambda i, s: res(i, s) * DEPTH_BYTES, DEPTH_BYTES, dep=True)
        plan.add(2, "load", "colour_array", pixels, kept_n, lambda i, s: res(i, s) * cb, cb, dep=True)
        # in registers: sort the loaded list, then composite it front to back
        unpack = UNPACK_RGBA8 if self.colour_format == "rgba8" else 0
        plan.compute(2, pixels, sort_compares(kept_n, self.sort) * COMPARE_EXCHANGE
                     + kept_n * (COMPOSITE + unpack))

        # resolve: the kept fragments of each pixel in load (arrival) order, sorted in registers
        loaded, loaded_pix = g.first_arrivals(L)
        perm, compares = sort_runs(loaded_pix, g.key[loaded], self.sort)
        order = loaded[perm]                       # runs stay in place: loaded_pix is pix[order]
        image = composite_stored(trace, pix, order, self.colour_format, loaded_pix)

        covered = g.covered
        struct = [
            Structure("counter", POINTER_BYTES, P, covered, "fragment counter per pixel (atomicInc)"),
            Structure("depth_array", DEPTH_BYTES, P * L, len(kept_idx), "32-bit depth per entry"),
            Structure("colour_array", cb, P * L, len(kept_idx), f"{self.colour_format} colour per entry"),
        ]
        over = g.count > L
        return SchemeResult(
            self.name, self.params(), image, n, covered, struct, plan, geometry_passes=1,
            dropped_fragments=int((g.count - kept_n).sum()), overflowed_pixels=int(over.sum()),
            lists=CapturedLists(loaded_pix, order),
            stats={"sort_compares": Stat(compares, "compares", f"{self.sort} sort compare operations in the resolve"),
                   "max_fragments_per_pixel": Stat(int(g.count.max(initial=0)), "fragments",
                                                   "largest counter value reached")})
