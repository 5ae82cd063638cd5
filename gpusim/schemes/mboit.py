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
from gpusim.metrics.composite import runs_by_length
from gpusim.schemes.common.groups import PixelGroups
from gpusim.schemes.common.arrays import put_rows
from gpusim.schemes.common.moments import (BATCH, CONFIGS, absorbance, factor, moment_terms, transmittance_rows,
                                           warp_depth)
from gpusim.schemes.common.storage import COLOUR_BYTES, effective_alpha, rounder
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


SMALL_BLOCK = 4096    # pixels: ranks with fewer have their transmittances computed together, rows gathered


class RankMajor:
    """The fragments of grouped runs (pixels) in rank-major order: every pixel's first fragment, then every
    second fragment, ... . Pixels are numbered longest run first (``pixel``: their ids), so the pixels with a
    fragment of rank j are a prefix 0 .. m_j - 1 and rank j's fragments are one contiguous block whose row i
    belongs to pixel i: a per-pixel fold in arrival order (ROP blending) adds block to prefix, no gathers."""

    def __init__(self, pix_sorted: np.ndarray):
        n = len(pix_sorted)
        empty = np.zeros(0, np.int64)
        start, _, active = runs_by_length(pix_sorted) if n else (empty, empty, empty)
        self.pixel = pix_sorted[start]
        self.pixels = len(start)
        self.active = active          # pixels with a fragment of rank j (non-increasing)
        self.position = np.empty(n, np.int64)         # rank-major position -> position in ``pix_sorted``
        for at, j, m in self._blocks():
            self.position[at:at + m] = start[:m] + j

    def _blocks(self):
        at = 0
        for j, m in enumerate(self.active.tolist()):
            yield at, j, m
            at += m

    def blocks(self):
        """(first rank-major position, pixels) of each rank's block."""
        return [(at, m) for at, _, m in self._blocks()]

    def rows(self) -> np.ndarray:
        """The pixel row of each rank-major position (its place in its rank's block)."""
        n = int(self.active.sum())
        return np.arange(n) - np.repeat(np.cumsum(self.active) - self.active, self.active)

    def fold(self, rows: np.ndarray, values: np.ndarray, step) -> np.ndarray:
        """``rows`` (pixels, ...) updated by ``rows[:m] = step(rows[:m], block)`` for each rank's block of
        ``values`` (rank-major)."""
        for at, m in self.blocks():
            rows[:m] = step(rows[:m], values[at:at + m])
        return rows

    def scatter(self, rows: np.ndarray, pixel_count: int) -> np.ndarray:
        """(pixel_count, ...) zeros with each pixel's row."""
        out = np.zeros((pixel_count,) + rows.shape[1:], rows.dtype)
        put_rows(out, self.pixel, rows)
        return out


def _scatter_rows(values: np.ndarray, mask: np.ndarray) -> np.ndarray:
    """Rows of ``values`` at the True places of ``mask``, zeros elsewhere."""
    out = np.zeros((len(mask),) + values.shape[1:], values.dtype)
    out[mask] = values
    return out


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
            Pass("moments", "geometry", "fragment", shading="alpha"), Pass("transmittance", "geometry", "fragment"),
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

        keep = blended[g.by_arrival]
        order = g.by_arrival[keep]                      # the blended fragments by pixel, in arrival order
        ranks = RankMajor(g.pix_by_arrival[keep])
        frag = order[ranks.position]                    # rank-major: every pixel's first fragment, then second...
        zw = warp_depth(trace.z[frag])
        rgba = np.take(trace.rgba, frag, axis=0)
        alpha = effective_alpha(rgba, trace.opaque[frag])
        zeroth_round, value_round, acc_round = rounder(zfmt), rounder(vfmt), rounder(self.accum_format)

        def add_moments(s, terms):
            out = s + terms
            if zfmt != "r32f":
                out[:, 0] = zeroth_round(out[:, 0])
            if vfmt != "r32f":
                out[:, 1:] = value_round(out[:, 1:])
            return out

        rows = ranks.fold(np.zeros((ranks.pixels, 1 + ms.reals), np.float32),
                          moment_terms(zw, absorbance(alpha), ms), add_moments)
        b0 = rows[:, 0]
        lit = b0 > 0                                    # b_0 = 0: nothing in front, T = 1
        all_lit = bool(lit.all())
        L, D = factor(b0 if all_lit else b0[lit], rows[:, 1:] if all_lit else rows[lit, 1:], ms, bias)
        if not all_lit:
            L, D = _scatter_rows(L, lit), _scatter_rows(D, lit)
        # each fragment's transmittance from its pixel's factors: a rank's block on the first rows of L and D
        # while blocks are large, then the small blocks' fragments together with their rows gathered (a pixel
        # 4,097 deep is 4,097 ranks: a call each would cost more than their work)
        T = np.empty(len(frag), np.float32)
        invalid = 0

        def put(at, stop, rows, L_, D_, b0_):
            nonlocal invalid
            t, bad = transmittance_rows(L_, D_, b0_, zw[at:stop], ms, self.overestimation)
            if not all_lit:
                dark = ~lit[rows]
                t[dark], bad[dark] = 1, False
            T[at:stop] = t
            invalid += int(np.count_nonzero(bad))

        small = len(frag)
        for at, m in ranks.blocks():
            if m < SMALL_BLOCK:
                small = at
                break
            put(at, at + m, slice(0, m), L[:m], D[:m], b0[:m])
        row_of = ranks.rows()
        for lo in range(small, len(frag), BATCH):
            row = row_of[lo:lo + BATCH]
            put(lo, lo + len(row), row, L[row], D[row], b0[row])
        weight = T * alpha
        out = np.empty((len(frag), 4), np.float32)
        out[:, :3] = rgba[:, :3] * weight[:, None]
        out[:, 3] = weight
        acc_rows = ranks.fold(np.zeros((ranks.pixels, 4), np.float32), out, lambda s, o: acc_round(s + o))
        state = ranks.scatter(rows, P)
        acc = ranks.scatter(acc_rows, P)

        with np.errstate(all="ignore"):
            total = np.exp(-state[:, 0]).astype(np.float32)
            colour = acc[:, :3] / np.maximum(acc[:, 3:4], np.float32(np.finfo(np.float32).tiny))
            image = colour * (np.float32(1.0) - total[:, None]) + base * total[:, None]
        finite = np.ones(ranks.pixels, bool)         # pixels without fragments keep finite zeros
        for column in (*rows.T, *acc_rows.T):
            finite &= np.isfinite(column)
        overflow = int(np.count_nonzero(~finite))
        touched = np.zeros(P, bool)
        touched[ranks.pixel] = True
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
            "invalid_reconstructions": Stat(invalid, "fragments",
                                            "fragments whose reconstruction gave a NaN (T = 0, as saturate)"),
            "accumulation_overflow": Stat(overflow, "pixels", "pixels whose moment or accumulation sums overflowed"),
            "zero_weight_pixels": Stat(zero_weight, "pixels", "pixels whose fragments' weights T a all summed to 0 "
                                       "while b_0 made them opaque in part (their colour reads as black)"),
            "culled_fragments": Stat(culled, "fragments", "transparent fragments behind an opaque one"),
        }
        return SchemeResult(self.name, self.params(), image.reshape(trace.height, trace.width, 3), n, g.covered,
                            struct, plan, geometry_passes=2, dropped_fragments=0, overflowed_pixels=0, stats=stats)
