"""The one-pass blending baselines: unsorted alpha blending and weighted blended OIT.

``alpha-blend``: hardware "over" blending in submission order, no sorting, as
LucidRaster's baseline (seed 002): C = a c + (1 - a) C, rounded to the
framebuffer format after every blend (the ROP's ``blend`` operation).

``wboit``: McGuire & Bavoil 2013. One pass accumulates sum(w a c, w a) into an
accumulation target (additive blending) and prod(1 - a) into a revealage target
(multiplicative blending), each rounded to its format after every blend; a
full-screen pass composites C = accum.rgb / clamp(accum.a, 1e-4, 5e4) *
(1 - revealage) + revealage * background. Weight functions (the paper's
equations 7-10, clamps included) with view-space depth |z| and window depth d:

* eq7: a * clamp(10 / (1e-5 + (|z|/5)^2 + (|z|/200)^6), 1e-2, 3e3)
* eq8: a * clamp(10 / (1e-5 + (|z|/10)^3 + (|z|/200)^6), 1e-2, 3e3)
* eq9: a * clamp(0.03 / (1e-5 + (|z|/200)^4), 1e-2, 3e3)
* eq10: a * max(1e-2, 3e3 * (1 - d)^3)
* constant: a (plain weighted average)

|z| is recovered from window depth with the camera's near and far planes
(from the trace's scene metadata, or the ``near`` / ``far`` parameters).

Opaque fragments (``opaque = prepass``, the usual practice; a trace without
opaque fragments gets no pre-pass and no depth buffer): a depth-tested pass draws the nearest opaque fragment of each pixel (first submitted on equal
depth) and fills ``depth_buffer``; transparent fragments behind it fail the
depth test (``culled_fragments``) and the transparent result is blended over
the opaque image. With ``opaque = blend`` opaque fragments are blended like
any other with alpha 1.

ALU work beyond each operation's own (gpusim.schemes.common.alu): an
``alpha-blend`` fragment's program only hands its colour to the ROP, whose
``blend`` does the arithmetic, so it declares none. A ``wboit`` fragment
evaluates its weight function (``WBOIT_WEIGHT``) and premultiplies its colour
by a w (``PREMULTIPLY``); the composite pass divides and applies the revealage
per pixel (``WBOIT_RESOLVE``), and without an opaque pre-pass also mixes in the
background itself (``COMPOSITE``; with one, the framebuffer ``blend`` does).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

import numpy as np

from gpusim.config import param
from gpusim.errors import GpusimError
from gpusim.opplan import OpPlan, Pass
from gpusim.schemes.base import Scheme, register
from gpusim.schemes.common.alu import COMPOSITE, PREMULTIPLY, WBOIT_RESOLVE, WBOIT_WEIGHT
from gpusim.schemes.common.arrays import lex_sorted, put_rows
from gpusim.schemes.common.fold import fold
from gpusim.schemes.common.groups import PixelGroups, segment_running_min_before
from gpusim.schemes.common.storage import COLOUR_BYTES, DEPTH_BYTES, rounder
from gpusim.schemes.result import SchemeResult, Stat, Structure

OpaqueMode = Literal["prepass", "blend"]
REVEALAGE_BYTES = {"r8": 1, "r16f": 2, "r32f": 4}


def depth_tested_pass(trace, g: PixelGroups, plan: OpPlan, pass_index: int, colour_bytes: int,
                      colour_round, opaque: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray, int]:
    """Depth-tested opaque pass (depth test LESS, then a colour store) of the ``opaque`` fragments (default:
    the trace's): (colour image (P, 3), mask of transparent fragments it lets through, culled)."""
    P = trace.pixel_count
    opaque = trace.opaque if opaque is None else opaque
    op_idx = np.flatnonzero(opaque)
    pix = g.pix
    zbuf = np.full(P, np.uint64(1) << np.uint64(32))
    colour = np.empty((P, 3), np.float32)
    colour[:] = trace.background.astype(np.float32)
    if len(op_idx):
        perm, pix_sorted = lex_sorted(pix[op_idx])              # op_idx ascends: submission order per pixel
        by_pix = op_idx[perm]
        key_sorted = g.key[by_pix]
        # colour stores: opaque fragments that pass LESS against the earlier opaque ones
        passes = key_sorted < segment_running_min_before(pix_sorted, key_sorted)
        writes, write_pix, write_key = by_pix[passes], pix_sorted[passes], key_sorted[passes]
        # the last write at a pixel is its nearest opaque fragment (first submitted among equals)
        last = np.r_[write_pix[1:] != write_pix[:-1], True]
        winners, winner_pix = writes[last], write_pix[last]
        zbuf[winner_pix] = write_key[last]
        put_rows(colour, winner_pix, colour_round(np.take(trace.rgba[:, :3], winners, axis=0)))
    else:
        writes = op_idx
    plan.add(pass_index, "depth_test", "depth_buffer", op_idx, 1, lambda i, s: pix[op_idx[i]] * DEPTH_BYTES,
             DEPTH_BYTES)
    plan.add(pass_index, "store", "framebuffer", writes, 1, lambda i, s: pix[writes[i]] * colour_bytes,
             colour_bytes, dep=True)
    transparent = ~opaque & (g.key < zbuf[pix])
    culled = int(np.count_nonzero(~opaque & ~transparent))
    return colour, transparent, culled


def opaque_prepass(trace, g: PixelGroups, plan: OpPlan, prepass: bool,
                   transparent_passes) -> tuple[np.ndarray, np.ndarray, int]:
    """The opaque pre-pass as pass 0 (when ``prepass``: an rgba8 framebuffer) and the depth test of the
    transparent fragments in each of ``transparent_passes``: (the colour behind the transparent fragments
    (P, 3), the opaque image or the background; the mask of fragments to blend; transparent fragments culled)."""
    if not prepass:
        base = np.empty((trace.pixel_count, 3), np.float32)
        base[:] = trace.background.astype(np.float32)
        return base, np.ones(len(trace), bool), 0
    base, blended, culled = depth_tested_pass(trace, g, plan, 0, 4, rounder("rgba8"))
    t_idx, pix = np.flatnonzero(~trace.opaque), g.pix
    for p in transparent_passes:
        plan.add(p, "depth_test", "depth_buffer", t_idx, 1, lambda i, s: pix[t_idx[i]] * DEPTH_BYTES, DEPTH_BYTES)
    return base, blended, culled


def composite_over(plan: OpPlan, pass_index: int, pixels: int, instructions: int, prepass: bool) -> None:
    """A full-screen resolve's work per pixel: its ``instructions``, then over the background itself
    (``COMPOSITE``) or, after an opaque pre-pass, through the framebuffer's ``blend``."""
    plan.compute(pass_index, pixels, instructions + (0 if prepass else COMPOSITE))
    if prepass:
        plan.add(pass_index, "blend", "framebuffer", pixels, 1, lambda i, s: i * 4, 4, dep=True)


def prepass_structures(trace, pix: np.ndarray) -> list[Structure]:
    """The opaque pre-pass's depth buffer and rgba8 framebuffer, used where an opaque fragment lands."""
    P = trace.pixel_count
    opaque_px = int(np.count_nonzero(np.bincount(pix[trace.opaque], minlength=P)))
    return [Structure("depth_buffer", DEPTH_BYTES, P, opaque_px, "opaque depth (pre-pass)"),
            Structure("framebuffer", 4, P, opaque_px, "rgba8 opaque colour")]


@register("alpha-blend")
@dataclass(frozen=True)
class AlphaBlend(Scheme):
    summary = "unsorted hardware alpha blending in submission order (the baseline)"

    framebuffer_format: Literal["rgba8", "rgba16f", "rgba32f"] = param("rgba8", doc="framebuffer format")
    opaque: OpaqueMode = param("prepass", doc="opaque fragments: depth-tested pre-pass, or blended with alpha 1")

    def simulate(self, trace) -> SchemeResult:
        g = PixelGroups(trace)
        n, P, pix = len(trace), trace.pixel_count, g.pix
        cb = COLOUR_BYTES[self.framebuffer_format]
        rnd = rounder(self.framebuffer_format)
        prepass = self.opaque == "prepass" and bool(trace.opaque.any())   # no opaque: nothing to pre-pass
        passes = ([Pass("opaque", "geometry", "fragment")] if prepass else []) + \
            [Pass("transparent", "geometry", "fragment")]
        plan = OpPlan(passes, (["depth_buffer"] if prepass else []) + ["framebuffer"])
        if prepass:
            colour, blended, culled = depth_tested_pass(trace, g, plan, 0, cb, rnd)
            colour = rnd(colour)   # the cleared background is held in the framebuffer's format too
            t_idx = np.flatnonzero(~trace.opaque)
            plan.add(1, "depth_test", "depth_buffer", t_idx, 1, lambda i, s: pix[t_idx[i]] * DEPTH_BYTES, DEPTH_BYTES)
        else:
            colour = np.empty((P, 3), np.float32)
            colour[:] = rnd(trace.background.astype(np.float32))
            blended, culled = np.ones(n, bool), 0
        b_idx = np.flatnonzero(blended)
        plan.add(len(passes) - 1, "blend", "framebuffer", b_idx, 1, lambda i, s: pix[b_idx[i]] * cb, cb,
                 dep=prepass)
        order = g.by_arrival[blended[g.by_arrival]]
        rgb, alpha = np.take(trace.rgba[:, :3], order, axis=0), g.alpha[order]   # in arrival order

        def step(state, i):
            a = alpha[i][:, None]
            return rnd(a * np.take(rgb, i, axis=0) + (1 - a) * state)

        image = fold(pix, order, colour, step)
        struct = [Structure("framebuffer", cb, P, g.covered, f"{self.framebuffer_format} colour")]
        if prepass:
            opaque_px = int(np.count_nonzero(np.bincount(pix[trace.opaque], minlength=P)))
            struct.insert(0, Structure("depth_buffer", DEPTH_BYTES, P, opaque_px, "opaque depth (pre-pass)"))
        return SchemeResult(self.name, self.params(), image.reshape(trace.height, trace.width, 3), n, g.covered,
                            struct, plan, geometry_passes=1, dropped_fragments=0, overflowed_pixels=0,
                            stats={"culled_fragments": Stat(culled, "fragments",
                                                            "transparent fragments behind an opaque one")})


def _view_depth(d: np.ndarray, near: float, far: float) -> np.ndarray:
    """|z| in scene units from window depth d in [0, 1] under a perspective projection."""
    return near * far / (far - d.astype(np.float64) * (far - near))


@register("wboit")
@dataclass(frozen=True)
class WeightedBlendedOIT(Scheme):
    summary = "weighted blended OIT (McGuire & Bavoil 2013), one pass, approximate"

    weight: Literal["eq7", "eq8", "eq9", "eq10", "constant"] = param("eq10", doc="weight function (paper eq. 7-10)")
    accum_format: Literal["rgba16f", "rgba32f"] = param("rgba16f", doc="accumulation target format")
    revealage_format: Literal["r8", "r16f", "r32f"] = param("r16f", doc="revealage target format")
    opaque: OpaqueMode = param("prepass", doc="opaque fragments: depth-tested pre-pass, or blended with alpha 1")
    near: float | None = param(None, unit="scene units", doc="near plane for eq7-9 (default: the trace's camera)",
                               gt=0.0)
    far: float | None = param(None, unit="scene units", doc="far plane for eq7-9 (default: the trace's camera)",
                              gt=0.0)

    def _planes(self, trace) -> tuple[float, float]:
        cam = trace.meta.get("scene_config", {}).get("camera", {})
        near = self.near if self.near is not None else cam.get("near")
        far = self.far if self.far is not None else cam.get("far")
        if near is None or far is None:
            raise GpusimError(f"wboit weight {self.weight} needs view-space depth but the trace records no camera; "
                              "pass --param near=N --param far=F, or use --param weight=eq10")
        if not far > near:
            raise GpusimError(f"wboit: far ({far}) must be greater than near ({near})")
        return float(near), float(far)

    def weights(self, trace, alpha: np.ndarray) -> np.ndarray:
        d = trace.z.astype(np.float64)
        if self.weight == "constant":
            w = np.ones_like(d)
        elif self.weight == "eq10":
            w = np.maximum(1e-2, 3e3 * (1.0 - d) ** 3)
        else:
            z = _view_depth(d, *self._planes(trace))
            if self.weight == "eq7":
                w = 10.0 / (1e-5 + (z / 5.0) ** 2 + (z / 200.0) ** 6)
            elif self.weight == "eq8":
                w = 10.0 / (1e-5 + (z / 10.0) ** 3 + (z / 200.0) ** 6)
            else:
                w = 0.03 / (1e-5 + (z / 200.0) ** 4)
            w = np.clip(w, 1e-2, 3e3)
        return (alpha * w).astype(np.float32)

    def simulate(self, trace) -> SchemeResult:
        g = PixelGroups(trace)
        n, P, pix = len(trace), trace.pixel_count, g.pix
        ab, rb = COLOUR_BYTES[self.accum_format], REVEALAGE_BYTES[self.revealage_format]
        acc_round, rev_round = rounder(self.accum_format), rounder(self.revealage_format)
        prepass = self.opaque == "prepass" and bool(trace.opaque.any())   # no opaque: nothing to pre-pass
        passes = ([Pass("opaque", "geometry", "fragment")] if prepass else []) + \
            [Pass("transparent", "geometry", "fragment"), Pass("composite", "fullscreen", "pixel")]
        plan = OpPlan(passes, (["depth_buffer", "framebuffer"] if prepass else []) + ["accumulation", "revealage"])
        tp = len(passes) - 2
        base, blended, culled = opaque_prepass(trace, g, plan, prepass, (tp,))
        b_idx = np.flatnonzero(blended)
        # the weight w(z, a) and the premultiplied outputs (c a w, a w); the revealage output is a
        plan.compute(tp, b_idx, WBOIT_WEIGHT[self.weight] + PREMULTIPLY, dep=prepass)
        plan.add(tp, "blend", "accumulation", b_idx, 1, lambda i, s: pix[b_idx[i]] * ab, ab, dep=prepass)
        plan.add(tp, "blend", "revealage", b_idx, 1, lambda i, s: pix[b_idx[i]] * rb, rb, dep=prepass)
        pixels = P
        plan.add(tp + 1, "load", "accumulation", pixels, 1, lambda i, s: i * ab, ab)
        plan.add(tp + 1, "load", "revealage", pixels, 1, lambda i, s: i * rb, rb)
        # accum.rgb / clamp(accum.a) and 1 - revealage; over the background here, or by the framebuffer's blend
        composite_over(plan, tp + 1, pixels, WBOIT_RESOLVE, prepass)

        alpha = g.alpha
        w = self.weights(trace, alpha)
        premul = np.empty((n, 4), np.float32)
        premul[:, :3] = trace.rgba[:, :3] * (alpha * w)[:, None]
        premul[:, 3] = alpha * w
        state = np.zeros((P, 5), np.float32)
        state[:, 4] = 1.0

        order = g.by_arrival[blended[g.by_arrival]]
        premul, alpha = np.take(premul, order, axis=0), alpha[order]   # in arrival order

        def step(s, i):
            out = np.empty_like(s)
            out[:, :4] = acc_round(s[:, :4] + np.take(premul, i, axis=0))
            out[:, 4] = rev_round(s[:, 4] * (1 - alpha[i]))
            return out

        state = fold(pix, order, state, step)
        reveal = state[:, 4:5]
        overflow = int(np.count_nonzero(~np.isfinite(state[:, :4]).all(axis=1)))
        with np.errstate(invalid="ignore", over="ignore"):
            avg = state[:, :3] / np.clip(state[:, 3:4], 1e-4, 5e4)
            image = avg * (1 - reveal) + base * reveal
        # the displayed (unorm) value of an overflowed target: +inf saturates to 1, NaN reads as 0
        image = np.clip(np.nan_to_num(image, nan=0.0, posinf=1.0, neginf=0.0), 0.0, 1.0)
        struct = [Structure("accumulation", ab, P, g.covered, f"{self.accum_format} sum of w*a*c and w*a"),
                  Structure("revealage", rb, P, g.covered, f"{self.revealage_format} product of (1 - a)")]
        if prepass:
            struct[:0] = prepass_structures(trace, pix)
        return SchemeResult(self.name, self.params(), image.reshape(trace.height, trace.width, 3), n, g.covered,
                            struct, plan, geometry_passes=1, dropped_fragments=0, overflowed_pixels=0,
                            stats={"culled_fragments": Stat(culled, "fragments",
                                                            "transparent fragments behind an opaque one"),
                                   "accumulation_overflow": Stat(overflow, "pixels",
                                                                 "pixels whose accumulation target overflowed")})
