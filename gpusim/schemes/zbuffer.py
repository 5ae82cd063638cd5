"""The z-buffer: the hardware pipeline's opaque, depth-buffered pass (the reference of seed 000 Table 2).

One geometry pass. Every fragment goes through the ROP's depth test (LESS
against the depth buffer, cleared to the far plane); a fragment that passes
stores its colour to the framebuffer. Alpha is ignored: every fragment is
drawn as opaque, so the image is the nearest fragment's colour at each pixel
(the first submitted among fragments of equal depth), rounded to the
framebuffer format. On a trace whose fragments all have alpha 1 this is the
exact reference; on a transparent scene its error against the reference is
what rendering it opaque loses.

Seed 000 Table 2 times FreePipe's opaque rendering (``freepipe-mdts`` with
one layer and depth + colour packing: two atomics per fragment) against
OpenGL's, which is this pass. Colour stores are conditional, so their count
depends on submission order: a front-to-back order stores each pixel once.

ALU work: the fragment program only hands its colour to the ROP, as
``alpha-blend``'s does, so it declares none.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

import numpy as np

from gpusim.config import param
from gpusim.opplan import OpPlan, Pass
from gpusim.schemes.base import Scheme, register
from gpusim.schemes.blending import depth_tested_pass
from gpusim.schemes.common.groups import PixelGroups
from gpusim.schemes.common.storage import COLOUR_BYTES, DEPTH_BYTES, rounder
from gpusim.schemes.result import SchemeResult, Stat, Structure


@register("zbuffer")
@dataclass(frozen=True)
class ZBuffer(Scheme):
    summary = "opaque z-buffer: the nearest fragment per pixel, one pass (seed 000 Table 2's OpenGL)"

    framebuffer_format: Literal["rgba8", "rgba16f", "rgba32f"] = param("rgba8", doc="framebuffer format")

    def simulate(self, trace) -> SchemeResult:
        g = PixelGroups(trace)
        n, P = len(trace), trace.pixel_count
        cb = COLOUR_BYTES[self.framebuffer_format]
        plan = OpPlan([Pass("opaque", "geometry", "fragment")], ["depth_buffer", "framebuffer"])
        colour, _, _ = depth_tested_pass(trace, g, plan, 0, cb, rounder(self.framebuffer_format),
                                         np.ones(n, bool))
        stores = int(sum(gr.total for gr in plan.groups if gr.op == "store"))
        struct = [Structure("depth_buffer", DEPTH_BYTES, P, g.covered, "32-bit depth"),
                  Structure("framebuffer", cb, P, g.covered, f"{self.framebuffer_format} colour")]
        return SchemeResult(self.name, self.params(), colour.reshape(trace.height, trace.width, 3), n, g.covered,
                            struct, plan, geometry_passes=1, dropped_fragments=0, overflowed_pixels=0,
                            stats={"hidden_fragments": Stat(n - g.covered, "fragments",
                                                            "fragments behind the nearest one of their pixel"),
                                   "colour_stores": Stat(stores, "fragments",
                                                         "fragments that passed the depth test when they arrived "
                                                         "and stored their colour")})
