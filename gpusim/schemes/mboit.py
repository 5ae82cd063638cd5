"""Moment-based order-independent transparency (Münstermann, Krumpen, Klein, Peters 2018), approximate.

Pass 1 (``moments``, a geometry pass) adds each fragment's absorbance A = -ln(1 - a) and its moments of
warped depth into the pixel's moment render targets with additive blending: b_0 into ``zeroth_moment``
(one channel) and the ``moments`` configuration's values into ``moments`` (render targets of up to four
channels: ``power4`` one RGBA target, ``power6`` an RGBA and an RG target, ``trig4`` two RGBA targets),
each sum rounded to the target's format after every blend. Pass 2 (``transmittance``) renders every
fragment again: it reads its pixel's moments (texture fetches), reconstructs the transmittance T(z_f) in
front of its depth (gpusim.schemes.common.moments: bias, the moment matrix's L D L^H factorisation, the
kernel polynomial's roots, the canonical representation's weights, the paper's overestimation), and adds
(T a c, T a) into an ``accumulation`` target (additive blending, rounded per blend). The full-screen
``resolve`` pass normalises the colour so that the total opacity is the one b_0 gives:
C = accum.rgb / accum.a (1 - exp(-b_0)) + exp(-b_0) background.

Formats (``precision``): ``half`` stores each moment as a 16-bit float and b_0 as a 32-bit float (power4:
96 bits per pixel, power6: 128, trig4: 160), ``single`` every value as a 32-bit float (160, 224, 288) and
``half-all`` every value, b_0 too, as a 16-bit float (80, 112, 144). A half-float b_0 drifts: adding the same
absorbance rounds the same way every time (92 layers of alpha 0.5 end 0.6% low), which moves the total
transmittance and, on a narrow cluster of depths, pushes the normalised moments out of the moment space.
The bias (``BIAS``, per precision) was measured: the decade with the least image error on bundled scenes and
random pixels (docs/schemes.md).

Opaque fragments (``opaque = prepass``, as ``wboit``; a trace without opaque fragments gets no pre-pass): a
depth-tested pass draws the nearest opaque fragment of each pixel; transparent fragments behind it fail the
depth test in both geometry passes (``culled_fragments``) and the resolve blends over the opaque image. With
``opaque = blend`` they are moments like any other, of alpha 1 (clamped).

Depth is warped linearly from window depth (z' = 2 d - 1; the paper warps view depth logarithmically, which
a perspective window depth already resembles). Alpha is clamped to 1 - 0.5/256 so that A stays finite
(an opaque fragment blended as moments lets 0.2% through). The image is approximate: its total transmittance
is exact up to the clamp and the rounding of b_0, and each colour is a weighted average of the pixel's
colours; a fragment whose reconstruction gives a NaN (a shader would write saturate(NaN) = 0) gets T = 0 and
is counted (``invalid_reconstructions``).

ALU work (gpusim.schemes.common.alu): pass 1 evaluates the moments' terms (``MBOIT_GENERATE``); pass 2 the
reconstruction (``mboit_reconstruct``) and the premultiplied outputs (``PREMULTIPLY``); the resolve
``MBOIT_RESOLVE``, and without an opaque pre-pass also mixes in the background itself (``COMPOSITE``; with
one, the framebuffer's ``blend`` does).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

import numpy as np

from gpusim.config import param
from gpusim.opplan import OpPlan, Pass
from gpusim.schemes.base import Scheme, register
from gpusim.schemes.blending import OpaqueMode, composite_over, opaque_prepass, prepass_structures
from gpusim.schemes.common.alu import MBOIT_GENERATE, MBOIT_RESOLVE, PREMULTIPLY, mboit_reconstruct
from gpusim.schemes.common.fold import fold
from gpusim.schemes.common.groups import PixelGroups
from gpusim.schemes.common.moments import CONFIGS, absorbance, moment_terms, transmittance, warp_depth
from gpusim.schemes.common.storage import COLOUR_BYTES, rounder
from gpusim.schemes.result import SchemeResult, Stat, Structure

#: per precision: (bytes, render-target format) of b_0 and of each higher moment
VALUE = {"half": ((4, "r32f"), (2, "r16f")), "single": ((4, "r32f"), (4, "r32f")),
         "half-all": ((2, "r16f"), (2, "r16f"))}
#: the moment bias per precision (see docs/schemes.md: of the decades 5e-6 .. 5e-2 the one with the least mean
#: image error on bundled scenes and random pixels, for every configuration; none gives a NaN on the stress cases)
BIAS = {"half": 5e-3, "half-all": 5e-3, "single": 5e-6}


def target_channels(reals: int) -> list[int]:
    """Channels of each render target holding ``reals`` moment values (RGBA targets, the last RG or R)."""
    return [min(4, reals - at) for at in range(0, reals, 4)]


@register("mboit")
@dataclass(frozen=True)
class MomentBasedOIT(Scheme):
    summary = "moment-based OIT (Münstermann et al. 2018): moments of depth, two geometry passes, approximate"

    moments: Literal["power4", "power6", "trig4"] = param(
        "power4", doc="moments beyond b_0: 4 or 6 power moments, or 4 trigonometric (complex) moments")
    precision: Literal["half", "single", "half-all"] = param(
        "half", doc="storage: half (moments 16-bit floats, b_0 a 32-bit float), single (all 32-bit floats), half-all "
                    "(all 16-bit floats)")
    bias: float | None = param(None, doc="moment bias toward the inside of the moment space (default: the "
                               "precision's, BIAS)", min=0.0, max=0.5)
    overestimation: float = param(0.25, doc="share of the absorbance at the fragment's own depth counted in front "
                                  "(0: the lower bound, 1: the upper)", min=0.0, max=1.0)
    accum_format: Literal["rgba16f", "rgba32f"] = param("rgba16f", doc="pass 2's accumulation target format")
    opaque: OpaqueMode = param("prepass", doc="opaque fragments: depth-tested pre-pass, or blended with alpha 1")

    def simulate(self, trace) -> SchemeResult:
        g = PixelGroups(trace)
        n, P, pix = len(trace), trace.pixel_count, g.pix
        ms = CONFIGS[self.moments]
        (zb, zfmt), (vb, vfmt) = VALUE[self.precision]
        ab = COLOUR_BYTES[self.accum_format]
        bias = BIAS[self.precision] if self.bias is None else self.bias
        channels = target_channels(ms.reals)
        plane = np.r_[0, np.cumsum(channels)[:-1]] * vb * P        # each target's base in ``moments``
        tb = np.asarray(channels, np.int64) * vb                   # bytes of one texel of each target
        prepass = self.opaque == "prepass" and bool(trace.opaque.any())   # no opaque: nothing to pre-pass
        passes = ([Pass("opaque", "geometry", "fragment")] if prepass else []) + [
            Pass("moments", "geometry", "fragment"), Pass("transmittance", "geometry", "fragment"),
            Pass("resolve", "fullscreen", "pixel")]
        plan = OpPlan(passes, (["depth_buffer", "framebuffer"] if prepass else []) +
                      ["zeroth_moment", "moments", "accumulation"])
        p1 = len(passes) - 3
        base, blended, culled = opaque_prepass(trace, g, plan, prepass, (p1, p1 + 1))
        frags = np.flatnonzero(blended)
        at_target = lambda i, s: plane[s] + pix[frags[i]] * tb[s]  # noqa: E731
        at_zeroth = lambda i, s: pix[frags[i]] * zb  # noqa: E731
        plan.compute(p1, frags, MBOIT_GENERATE[self.moments], dep=prepass)
        plan.add(p1, "blend", "zeroth_moment", frags, 1, at_zeroth, zb)
        plan.add(p1, "blend", "moments", frags, len(channels), at_target, lambda i, s: tb[s])
        plan.add(p1 + 1, "load", "zeroth_moment", frags, 1, at_zeroth, zb, dep=prepass)
        plan.add(p1 + 1, "load", "moments", frags, len(channels), at_target, lambda i, s: tb[s])
        plan.compute(p1 + 1, frags, mboit_reconstruct(ms.kind, ms.count) + PREMULTIPLY)
        plan.add(p1 + 1, "blend", "accumulation", frags, 1, lambda i, s: pix[frags[i]] * ab, ab)
        pixels = P
        plan.add(p1 + 2, "load", "accumulation", pixels, 1, lambda i, s: i * ab, ab)
        plan.add(p1 + 2, "load", "zeroth_moment", pixels, 1, lambda i, s: i * zb, zb)
        # normalise and weigh by 1 - exp(-b_0); over the background here, or by the framebuffer's blend
        composite_over(plan, p1 + 2, pixels, MBOIT_RESOLVE, prepass)

        order = g.by_arrival[blended[g.by_arrival]]
        zw = warp_depth(trace.z)
        terms = np.take(moment_terms(zw, absorbance(g.alpha), ms), order, axis=0)   # in arrival order
        zeroth_round, value_round, acc_round = rounder(zfmt), rounder(vfmt), rounder(self.accum_format)

        def add_moments(s, i):
            out = s + np.take(terms, i, axis=0)
            out[:, 0] = zeroth_round(out[:, 0])
            out[:, 1:] = value_round(out[:, 1:])
            return out

        state = fold(pix, order, np.zeros((P, 1 + ms.reals), np.float32), add_moments)
        T = np.ones(n, np.float32)
        T[frags], invalid = transmittance(state[:, 0], state[:, 1:], pix[frags], zw[frags], ms, bias,
                                          self.overestimation)
        weight = T * g.alpha
        out = np.empty((n, 4), np.float32)
        out[:, :3] = trace.rgba[:, :3] * weight[:, None]
        out[:, 3] = weight
        out = np.take(out, order, axis=0)
        acc = fold(pix, order, np.zeros((P, 4), np.float32), lambda s, i: acc_round(s + np.take(out, i, axis=0)))

        with np.errstate(all="ignore"):
            total = np.exp(-state[:, 0]).astype(np.float32)
            colour = acc[:, :3] / np.maximum(acc[:, 3:4], np.float32(np.finfo(np.float32).tiny))
            image = colour * (np.float32(1.0) - total[:, None]) + base * total[:, None]
        overflow = int(np.count_nonzero(~np.isfinite(state).all(axis=1) | ~np.isfinite(acc).all(axis=1)))
        touched = np.bincount(pix[frags], minlength=P) > 0
        zero_weight = int(np.count_nonzero(touched & (acc[:, 3] == 0) & (total < 1)))
        # the displayed (unorm) value of an overflowed target: +inf saturates to 1, NaN reads as 0
        image = np.clip(np.nan_to_num(image, nan=0.0, posinf=1.0, neginf=0.0), 0.0, 1.0)
        lit = int(np.count_nonzero(touched))
        struct = [Structure("zeroth_moment", zb, P, lit, f"{zfmt} b_0: the sum of the absorbances"),
                  Structure("moments", vb * ms.reals, P, lit,
                            f"{ms.reals} {vfmt} values of {ms.count} {ms.kind} moments in {len(channels)} render "
                            "target(s)"),
                  Structure("accumulation", ab, P, lit, f"{self.accum_format} sum of T a c and T a")]
        if prepass:
            struct[:0] = prepass_structures(trace, pix)
        stats = {
            "moment_bits": Stat(8 * (zb + vb * ms.reals), "bits/pixel", "bits of b_0 and the moments per pixel"),
            "invalid_reconstructions": Stat(int(np.count_nonzero(invalid)), "fragments",
                                            "fragments whose reconstruction gave a NaN (T = 0, as saturate)"),
            "accumulation_overflow": Stat(overflow, "pixels", "pixels whose moment or accumulation sums overflowed"),
            "zero_weight_pixels": Stat(zero_weight, "pixels", "pixels whose fragments' weights T a all summed to 0 "
                                       "while b_0 made them opaque in part (their colour reads as black)"),
            "culled_fragments": Stat(culled, "fragments", "transparent fragments behind an opaque one"),
        }
        return SchemeResult(self.name, self.params(), image.reshape(trace.height, trace.width, 3), n, g.covered,
                            struct, plan, geometry_passes=2, dropped_fragments=0, overflowed_pixels=0, stats=stats)
