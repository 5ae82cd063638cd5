"""Depth peeling (Everitt 2001) and dual depth peeling (Bavoil & Myers 2008).

``depth-peeling``: geometry pass p renders every fragment; from pass 1 on each
fragment ``load`` s the previous pass's depth (``peel_depth``) and is kept only
if strictly farther; kept fragments go through the ROP ``depth_test`` (LESS,
with a conditional depth + colour write) against ``depth_buffer``. Pass p thus
peels the p-th nearest *distinct* depth of each pixel; of several fragments at
exactly that depth, the first submitted wins the depth test and the others are
never peeled (``tie_losses``, counted in ``dropped_fragments``). A full-screen
``blend`` pass after each peel composites the layer under the accumulation.

``dual-depth-peeling``: pass 0 MAX-blends (-z, z) into ``minmax_depth``; pass
k >= 1 loads the previous min/max; fragments at the previous min are blended
(in submission order, front to back) into ``front_colour``, those at the
previous max into ``back_colour`` (back to front, so among equal depths the
later submitted ends nearer), and those strictly between MAX-blend the next
min/max. Each pass peels two layers; equal depths are never lost.

Pass counts follow FreePipe Table 3 (``termination = known-layers``): depth
peeling needs L geometry passes and dual depth peeling ceil(L / 2) + 1, where L
is the largest number of distinct depths of a pixel. With ``termination =
occlusion-query`` depth peeling runs one more pass, the one whose query finds
no fragment left (dual depth peeling's last pass already finds its inner
range empty). ``max_passes`` caps the peel passes; deeper layers are dropped.
With ``termination = fixed`` depth peeling always runs ``max_passes`` passes,
those past the scene's layers peeling nothing (seed 004 Table 1's multi-pass
mode, whose time grows with k).
Accumulation arithmetic is float32; stored layer colours use ``colour_format``.

ALU work beyond each operation's own (gpusim.schemes.common.alu): in every
pass that reads the previous depth(s), each fragment tests itself against them
(``PEEL_TEST``; dual: against the min and max, ``DUAL_PEEL_TEST``) before its
depth test or blends. Depth peeling's per-layer ``blend`` passes and dual depth
peeling's front and back accumulations are ROP blends (no shader arithmetic);
dual depth peeling's ``final`` pass composites the back colour behind the front
one per pixel (``COMPOSITE``).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

import numpy as np

from gpusim.config import param
from gpusim.errors import GpusimError
from gpusim.opplan import OpPlan, Pass
from gpusim.schemes.base import Scheme, composite_stored, register
from gpusim.schemes.common.alu import COMPOSITE, DUAL_PEEL_TEST, PEEL_TEST
from gpusim.schemes.common.arrays import reversed_runs
from gpusim.schemes.common.groups import PixelGroups
from gpusim.schemes.common.storage import COLOUR_BYTES, DEPTH_BYTES, ColourFormat
from gpusim.schemes.result import CapturedLists, SchemeResult, Stat, Structure

Termination = Literal["known-layers", "occlusion-query", "fixed"]


@register("depth-peeling")
@dataclass(frozen=True)
class DepthPeeling(Scheme):
    summary = "depth peeling: one geometry pass per layer (Everitt 2001)"

    max_passes: int = param(0, unit="passes", doc="cap on peel passes (0: as many as the scene needs)", min=0)
    termination: Termination = param("known-layers", doc="pass count as FreePipe Table 3, +1 occlusion-query "
                                     "pass, or fixed: always max_passes passes (an application peeling k layers, "
                                     "seed 004 Table 1's MP)")
    colour_format: ColourFormat = param("rgba8", doc="format of the peeled layer's colour")

    def simulate(self, trace) -> SchemeResult:
        g = PixelGroups(trace)
        n, P = len(trace), trace.pixel_count
        pix, d = g.pix, g.distinct_rank
        lay = g.layers
        need = int(lay.max(initial=0))
        if self.termination == "fixed" and not self.max_passes:
            raise GpusimError("depth-peeling: termination = 'fixed' runs max_passes passes; set max_passes >= 1 "
                              "(e.g. --param max_passes=4)")
        peels = self.max_passes if self.termination == "fixed" else min(need, self.max_passes) if self.max_passes \
            else need
        query = self.termination == "occlusion-query" and peels == need
        total = peels + (1 if query and n else 0)
        passes = []
        for p in range(total):
            passes.append(Pass(f"peel {p}", "geometry", "fragment"))
            if p < peels:
                passes.append(Pass(f"blend {p}", "fullscreen", "pixel"))
        passes = passes or [Pass("peel 0", "geometry", "fragment")]
        cb = COLOUR_BYTES[self.colour_format]
        plan = OpPlan(passes, ["depth_buffer", "peel_depth", "layer_colour", "accumulation"])
        frags, pixels = n, P
        at = lambda size: (lambda i, s: pix[i] * size)  # noqa: E731
        plan.add(0, "load", "peel_depth", frags, max(total - 1, 0), at(DEPTH_BYTES), DEPTH_BYTES,
                 seq_pass=2 * np.arange(1, max(total, 1)))
        # each pass after the first: strictly behind the peeled depth, or discard
        plan.compute(0, frags, PEEL_TEST, count=max(total - 1, 0), seq_pass=2 * np.arange(1, max(total, 1)))
        plan.add(0, "depth_test", "depth_buffer", frags, np.minimum(d + 1, peels), at(DEPTH_BYTES),
                 DEPTH_BYTES, dep=True, seq_pass=2 * np.arange(peels))
        peeled = np.minimum(lay, peels)
        plan.add(0, "load", "layer_colour", pixels, peeled, lambda i, s: i * cb, cb, seq_pass=2 * np.arange(peels) + 1)
        plan.add(0, "blend", "accumulation", pixels, peeled, lambda i, s: i * cb, cb, dep=True,
                 seq_pass=2 * np.arange(peels) + 1)

        order, ps, ks = g.by_depth, g.pix_by_depth, g.key_by_depth
        first_of_depth = np.r_[True, (ps[1:] != ps[:-1]) | (ks[1:] != ks[:-1])][:n]   # [:n]: no entry when n = 0
        keep = first_of_depth & (g.distinct_rank_by_depth < peels)
        lost = ps[~keep]                           # pixels of tie losses and layers past the cap, ascending
        overflowed = int(len(lost) and 1 + np.count_nonzero(lost[1:] != lost[:-1]))
        order, ps = order[keep], ps[keep]
        ties = int(n - np.count_nonzero(first_of_depth))
        struct = [Structure("depth_buffer", DEPTH_BYTES, P, g.covered, "depth of the layer being peeled"),
                  Structure("peel_depth", DEPTH_BYTES, P, g.covered, "depth peeled by the previous pass"),
                  Structure("layer_colour", cb, P, g.covered, f"{self.colour_format} colour of the peeled layer"),
                  Structure("accumulation", cb, P, g.covered, "front-to-back accumulated colour")]
        image = composite_stored(trace, pix, order, self.colour_format, ps)
        return SchemeResult(self.name, self.params(), image, n, g.covered,
                            struct, plan, geometry_passes=total, dropped_fragments=int(n - len(order)),
                            overflowed_pixels=overflowed,
                            lists=CapturedLists(ps, order),
                            stats={"tie_losses": Stat(ties, "fragments", "fragments never peeled: equal depth to a "
                                                      "fragment submitted earlier"),
                                   "layers": Stat(need, "layers", "largest number of distinct depths of a pixel")})


@register("dual-depth-peeling")
@dataclass(frozen=True)
class DualDepthPeeling(Scheme):
    summary = "dual depth peeling: nearest and farthest layer per pass (Bavoil & Myers 2008)"

    max_passes: int = param(0, unit="passes", doc="cap on peel passes after the first (0: as many as needed)", min=0)
    colour_format: ColourFormat = param("rgba8", doc="format of the front and back accumulation colours")

    def simulate(self, trace) -> SchemeResult:
        g = PixelGroups(trace)
        n, P = len(trace), trace.pixel_count
        pix, d = g.pix, g.distinct_rank
        lay = g.layers
        e = lay[pix] - 1 - d                      # distinct rank from the back
        m = np.minimum(d, e)                      # peeled in pass m + 1
        need = -(-int(lay.max(initial=0)) // 2)
        peels = min(need, self.max_passes) if self.max_passes else need
        passes = [Pass("init", "geometry", "fragment", shading="none")] + [Pass(f"peel {k}", "geometry", "fragment")
                                                          for k in range(1, peels + 1)]
        passes.append(Pass("final", "fullscreen", "pixel"))
        cb, mm = COLOUR_BYTES[self.colour_format], 2 * DEPTH_BYTES
        plan = OpPlan(passes, ["minmax_depth", "front_colour", "back_colour"])
        frags, pixels = n, P
        # two ping-pong min/max textures: pass k reads texture (k-1) % 2 and writes k % 2
        tex = lambda i, s, k: ((k % 2) * P + pix[i]) * mm  # noqa: E731
        plan.add(0, "blend", "minmax_depth", frags, 1, lambda i, s: tex(i, s, 0), mm)
        plan.add(0, "load", "minmax_depth", frags, peels, lambda i, s: tex(i, s, s), mm,
                 seq_pass=np.arange(1, peels + 1))
        # at the previous min (front), at its max (back), or strictly inside
        plan.compute(0, frags, DUAL_PEEL_TEST, count=peels, seq_pass=np.arange(1, peels + 1))
        inside = np.minimum(m, peels)
        plan.add(0, "blend", "minmax_depth", frags, inside, lambda i, s: tex(i, s, s + 1), mm, dep=True,
                 seq_pass=np.arange(1, peels + 1))
        peeled = m < peels
        front = peeled & (d <= e)
        for name, sel in (("front_colour", front), ("back_colour", peeled & ~front)):
            who = np.flatnonzero(sel)
            plan.add(0, "blend", name, who, 1, lambda i, s, who=who: pix[who[i]] * cb, cb, dep=True,
                     pass_fn=lambda i, s, who=who: m[who[i]] + 1)
        final = len(passes) - 1
        plan.add(final, "load", "front_colour", pixels, 1, lambda i, s: i * cb, cb)
        plan.add(final, "load", "back_colour", pixels, 1, lambda i, s: i * cb, cb)
        plan.compute(final, pixels, COMPOSITE)      # the back accumulation behind the front one

        # composite order: front layers by depth (ties: submission), then back layers by depth
        # with ties reversed (back-to-front 'over' blending makes the later one nearer); read off
        # the depth order, where a tie group (one pixel, one depth) is all front or all back
        ps, ks, ds = g.pix_by_depth, g.key_by_depth, g.distinct_rank_by_depth
        es = lay[ps] - 1 - ds
        sel = np.minimum(ds, es) < peels
        ps, ks, back = ps[sel], ks[sel], (ds > es)[sel]
        tie_group = np.cumsum(np.r_[True, (ps[1:] != ps[:-1]) | (ks[1:] != ks[:-1])][:len(ps)])
        order = g.by_depth[sel][np.where(back, reversed_runs(tie_group), np.arange(len(ps)))]
        struct = [Structure("minmax_depth", mm, 2 * P, 2 * g.covered, "two ping-pong RG32F (-min, max) textures"),
                  Structure("front_colour", cb, P, g.covered, "front-to-back accumulated colour"),
                  Structure("back_colour", cb, P, g.covered, "back-to-front accumulated colour")]
        image = composite_stored(trace, pix, order, self.colour_format, ps)
        return SchemeResult(self.name, self.params(), image, n, g.covered,
                            struct, plan, geometry_passes=1 + peels, dropped_fragments=int(n - len(order)),
                            overflowed_pixels=int(np.count_nonzero(-(-lay // 2) > peels)),
                            lists=CapturedLists(ps, order),
                            stats={"layers": Stat(int(lay.max(initial=0)), "layers",
                                                  "largest number of distinct depths of a pixel")})
