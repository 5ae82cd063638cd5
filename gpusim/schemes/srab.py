"""Stencil-routed A-buffer (Myers & Bavoil 2007).

A multisample render target with k samples per pixel serves as k fragment
slots. A ``clear`` pass writes the routing values into the k stencil samples;
in the ``capture`` geometry pass each fragment is written to every sample with
the stencil test EQUAL and the stencil op "decrement always", so the j-th
fragment to reach a pixel (ROP order = submission order) lands in sample j:
k ``stencil`` operations per fragment and, for j < k, one ``store`` of depth
and colour. Fragments beyond the first k are dropped. The ``overflow`` geometry
pass (FreePipe Table 3 counts SRAB as 2 geometry passes) re-renders the scene
with one ``stencil`` test per fragment against the last sample, counted by an
occlusion query, to detect pixels that lost fragments. A full-screen
``resolve`` loads the captured samples, sorts them (bitonic, as in the sketch)
and composites front to back: per pixel the sort's compare-exchanges of its
min(n, k) samples (``sort_compares`` x ``compare_exchange`` of depth + colour)
and one ``COMPOSITE`` per sample (gpusim.schemes.common.alu; the samples are
read as a texture, which converts their format). Routing is the stencil unit's.

Footprint: ``samples`` (k x (4 B depth + colour) per pixel: 16 MiB for
512 x 512 with k = 8 and rgba8, FreePipe Table 3's 16 MB) and ``stencil``
(k x 1 B per pixel).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

import numpy as np

from gpusim.config import param
from gpusim.opplan import OpPlan, Pass
from gpusim.schemes.base import Scheme, composite_stored, register
from gpusim.schemes.common.alu import COMPOSITE, compare_exchange, sort_compares
from gpusim.schemes.common.arrays import entry_index
from gpusim.schemes.common.groups import PixelGroups
from gpusim.schemes.common.sorting import sort_runs
from gpusim.schemes.common.storage import COLOUR_BYTES, DEPTH_BYTES, ColourFormat
from gpusim.schemes.result import CapturedLists, SchemeResult, Stat, Structure

STENCIL_BYTES = 1


@register("stencil-routed-abuffer")
@dataclass(frozen=True)
class StencilRoutedABuffer(Scheme):
    summary = "stencil-routed A-buffer: first k fragments into k MSAA samples (Myers & Bavoil 2007)"

    samples: int = param(8, unit="samples/pixel", doc="MSAA samples = fragment slots per pixel", min=1, max=32)
    overflow_pass: bool = param(True, doc="second geometry pass detecting overflow (FreePipe Table 3: 2 passes)")
    colour_format: ColourFormat = param("rgba8", doc="sample colour format")
    sort: Literal["insertion", "bitonic"] = param("bitonic", doc="resolve sort")

    def simulate(self, trace) -> SchemeResult:
        g = PixelGroups(trace)
        n, P, k, pix = len(trace), trace.pixel_count, self.samples, g.pix
        sb = DEPTH_BYTES + COLOUR_BYTES[self.colour_format]
        passes = [Pass("clear", "clear", "entry"), Pass("capture", "geometry", "fragment")]
        if self.overflow_pass:
            passes.append(Pass("overflow", "geometry", "fragment", shading="none"))   # stencil and query only
        passes.append(Pass("resolve", "fullscreen", "pixel"))
        plan = OpPlan(passes, ["stencil", "samples"])
        plan.add(0, "store", "stencil", P * k, 1, lambda i, s: i * STENCIL_BYTES, STENCIL_BYTES)
        frags = n
        sample_at = lambda p, s: entry_index(p, s, k, P, "pixel-major")  # noqa: E731  (samples of a pixel adjacent)
        plan.add(1, "stencil", "stencil", frags, k, lambda i, s: sample_at(pix[i], s) * STENCIL_BYTES, STENCIL_BYTES)
        kept_idx = np.flatnonzero(g.arrival < k)
        plan.add(1, "store", "samples", kept_idx, 1,
                 lambda i, s: sample_at(pix[kept_idx[i]], g.arrival[kept_idx[i]]) * sb, sb, dep=True)
        if self.overflow_pass:
            plan.add(2, "stencil", "stencil", frags, 1, lambda i, s: sample_at(pix[i], k - 1) * STENCIL_BYTES,
                     STENCIL_BYTES)
        kept_n = np.minimum(g.count, k)
        plan.add(len(passes) - 1, "load", "samples", P, kept_n, lambda i, s: sample_at(i, s) * sb, sb)
        exchange = compare_exchange(COLOUR_BYTES[self.colour_format])
        plan.compute(len(passes) - 1, P, sort_compares(kept_n, self.sort) * exchange + kept_n * COMPOSITE)

        loaded, loaded_pix = g.first_arrivals(k)
        perm, compares = sort_runs(loaded_pix, g.key[loaded], self.sort)
        order = loaded[perm]                       # runs stay in place: loaded_pix is pix[order]
        struct = [Structure("stencil", STENCIL_BYTES, P * k, int(g.covered * k), "routing stencil per sample"),
                  Structure("samples", sb, P * k, len(kept_idx), f"depth + {self.colour_format} colour per sample")]
        over = g.count > k
        image = composite_stored(trace, pix, order, self.colour_format, loaded_pix)
        return SchemeResult(self.name, self.params(), image, n, g.covered,
                            struct, plan, geometry_passes=2 if self.overflow_pass else 1,
                            dropped_fragments=int(n - len(kept_idx)), overflowed_pixels=int(over.sum()),
                            lists=CapturedLists(loaded_pix, order),
                            stats={"sort_compares": Stat(compares, "compares", f"{self.sort} sort compares"),
                                   "overflow_query": Stat(int((g.count - kept_n).sum()), "fragments",
                                                          "fragments the overflow pass's occlusion query counts")})
