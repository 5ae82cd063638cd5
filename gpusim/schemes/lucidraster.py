"""LucidRaster's two-stage sort (seed 002 section 2, stage 3; Jakubowski).

Stage 1 (setup) stores per-triangle data for every triangle with samples on
screen; stage 2 (binning) lists, per 32x32 bin, the triangles covering it and
classifies bins as empty, low (fewer than ``high_bin_triangles`` triangles) or
high; a low bin with a block of more than ``low_block_triangles`` tri-blocks
is passed on to the high rasterizer (``promoted``). Binning workgroups take
batches of ``BINNING_BATCH`` triangles and count them per bin with
shared-memory atomics; each batch adds its count of a bin to the global counter
once, and reserves its run of the bin's list once.

Stage 3 runs as two dispatches, ``raster-low`` and ``raster-high``: a
workgroup per bin (256 and 1,024 threads) whose lanes take the bin's items
round robin (gpusim.schemes.common.workgroups), the sort and the depth filter
as ALU work shared by the lanes.

Stage 3, per bin: per 8x8 block, the tri-blocks (a triangle's samples in that
block) are sorted front to back by the depth at the centroid of their samples,
as a 32-bit word of 22 depth bits over 10 index bits (ties: the triangle listed
first, i.e. submitted first). Window depth is affine in screen space on a
planar triangle, so the depth at the centroid equals the mean of the samples'
depths; the 22 bits are the top of the float's ordered bit pattern
(gpusim.schemes.common.depthkey). Each pixel then receives its samples in that order
and passes them through a depth filter, a fixed-size priority queue of
``depth_filter`` entries from which the nearest sample falls out and is
blended front to back (gpusim.schemes.common.depth_filter).

A pixel is **invalid** (the paper's count) when a sample falls out nearer than
one already blended: the two-stage sort failed there. The true image error
against the exact reference is reported beside it by ``replay``.

``alpha_threshold``: shading of a half-block stops once every pixel in it has
accumulated alpha >= 1 - 1/128, checked after each segment of 256 samples
(samples ordered by tri-half-block, then row by row from the top-left); the
samples not shaded are counted (``skipped_samples``).

ALU work beyond each operation's own (gpusim.schemes.common.alu), per bin
thread in the raster pass: phase 2's bitonic sorts of single-word keys
(``bitonic_compares`` x ``KEY_COMPARE_EXCHANGE``) of each block's tri-blocks
(low rasterizer) or each half-block's tri-half-blocks (high rasterizer, which
sorts them directly), at their real lengths; phase 3's depth filter per shaded
sample, ``depth_filter`` compare-exchanges of depth-colour pairs
(``COMPARE_EXCHANGE``), and its blend (``COMPOSITE``). Samples skipped by the
alpha threshold cost neither.

Footprint: per-triangle data (84 B: normal, barycentric and depth edge
functions, scanline data), per-bin triangle counts, offsets and lists, the
scratch buffers of ``workgroups`` persistent workgroups (low rasterizer 128 KiB:
4 x 1024 tri-block-rows of 16 B and 16 x 256 x 2 tri-half-blocks of 8 B; high
rasterizer 768 KiB, only when a bin needs it) and the framebuffer.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from gpusim.config import param
from gpusim.metrics.composite import composite_runs, runs_by_length
from gpusim.opplan import OpPlan, Pass
from gpusim.schemes.base import Scheme, register
from gpusim.schemes.common.alu import (COMPARE_EXCHANGE, COMPOSITE, KEY_COMPARE_EXCHANGE, SHARED_ATOMIC,
                                       bitonic_compares)
from gpusim.schemes.common.arrays import lex_order, rank_in_runs, unique_ids
from gpusim.schemes.common.depth_filter import emit_order
from gpusim.schemes.common.depthkey import depth_key
from gpusim.schemes.common.groups import PixelGroups
from gpusim.schemes.common.lucid_bins import Grid, grouped, pairs
from gpusim.schemes.common.workgroups import Spread
from gpusim.schemes.result import CapturedLists, SchemeResult, Stat, Structure

TRI_DATA_BYTES = 84          # 4 (normal) + 32 (barycentric edges) + 16 (depth edge, ids) + 32 (scanline)
TRI_BLOCK_ROW_BYTES = 16     # < 128 bits: 80 bits of row intervals, 4 bits of columns, 24-bit triangle
TRI_HALF_BLOCK_BYTES = 8     # 24-bit coverage, 24-bit triangle, 12-bit sample prefix sum
LOW_SCRATCH = 4 * 1024 * TRI_BLOCK_ROW_BYTES + 16 * 256 * 2 * TRI_HALF_BLOCK_BYTES   # 128 KiB per workgroup
HIGH_SCRATCH = 768 * 1024
SEGMENT = 256                # samples per segment in phase 3
LOW_WORKGROUP = 256          # threads of a low-rasterizer workgroup (section 2, stage 3)
BINNING_BATCH = 2048         # triangles per binning batch: a setup chunk of 1,024 quads (section 2, stage 1)
HIGH_WORKGROUP = 1024        # threads of a high-rasterizer workgroup
DEPTH_BITS = 22
TRANSMITTANCE_LIMIT = np.float32(1.0 / 128)   # a pixel is opaque once blended alpha reaches 1 - 1/128


def sorted_arrival(pix, centroid_key, tb_block, tb_tri, tb_of_frag):
    """Per-block rank of each tri-block (front to back) and the pixel arrival order it gives."""
    order = lex_order(tb_block, centroid_key, tb_tri)
    rank = np.empty(len(order), np.int64)
    rank[order] = rank_in_runs(tb_block[order])
    frag_rank = rank[tb_of_frag]
    return frag_rank, lex_order(pix, frag_rank)


def crossing_arrival(pix, emitted, steps, alpha, count):
    """Per pixel: the arrival rank whose arrival made blended alpha reach 1 - 1/128 (-1: never)."""
    out = np.full(len(count), -1, np.int64)
    if len(emitted) == 0:
        return out
    start, _, active = runs_by_length(pix[emitted])
    covered = pix[emitted][start]
    alpha = alpha[emitted]                  # in emission order
    trans = np.ones(len(start), np.float32)
    done = np.zeros(len(start), bool)
    limit = TRANSMITTANCE_LIMIT
    for k, m in enumerate(active):
        idx = start[:m] + k
        trans[:m] *= np.float32(1.0) - alpha[idx]
        hit = ~done[:m] & (trans[:m] <= limit) & (steps[idx] < count[covered[:m]])
        out[covered[:m][hit]] = steps[idx][hit]
        done[:m] |= trans[:m] <= limit
    return out


@register("lucidraster")
@dataclass(frozen=True)
class LucidRaster(Scheme):
    summary = "LucidRaster: sort-middle bins, per-block centroid depth sort + per-pixel depth filter (seed 002)"

    depth_filter: int = param(3, unit="samples", doc="DF: entries of the per-pixel depth filter", min=1, max=4096)
    alpha_threshold: bool = param(False, doc="stop shading a half-block once all its pixels reach alpha 1 - 1/128")
    high_bin_triangles: int = param(1024, unit="triangles", doc="a bin with at least this many is high-density",
                                    min=1)
    low_block_triangles: int = param(256, unit="triangles", doc="low rasterizer's limit per 8x8 block", min=1)
    workgroups: int = param(1, unit="workgroups", doc="bins rasterized at once (each owns a scratch buffer)",
                            min=1)

    def simulate(self, trace) -> SchemeResult:
        g = PixelGroups(trace)
        n, P, pix = len(trace), trace.pixel_count, g.pix
        grid = Grid(trace.width, trace.height)
        tri = trace.prim.astype(np.int64)
        tris = int(tri.max(initial=-1)) + 1
        half_block = grid.half_block_of_pixel(trace.x, trace.y)
        # (region, triangle) pairs, finest first: tri-half-blocks, tri-blocks, tri-block-rows, bin lists
        thb_region, thb_tri, thb_of = pairs(half_block, tri, tris)
        tb_block, tb_tri, thb_to_tb = pairs(grid.block_of_half_block(thb_region), thb_tri, tris)
        tbr_region, tbr_tri, _ = pairs(grid.block_row_of_block(tb_block), tb_tri, tris)
        pb_bin, pb_tri, _ = pairs(grid.bin_of_block_row(tbr_region), tbr_tri, tris)
        tb_of = thb_to_tb[thb_of]
        mean_z = np.bincount(tb_of, weights=trace.z.astype(np.float64)) / np.bincount(tb_of)
        ckey = depth_key(np.clip(mean_z, 0.0, 1.0).astype(np.float32)) >> np.uint32(32 - DEPTH_BITS)
        frag_rank, by_arrival = sorted_arrival(pix, ckey, tb_block, tb_tri, tb_of)
        emitted, steps, ep, ek = emit_order(pix, g.key, by_arrival, self.depth_filter, return_steps=True,
                                            return_keys=True)

        skipped = np.zeros(n, bool)
        if self.alpha_threshold and n:
            skipped = self._threshold_skips(trace, g, grid, half_block, frag_rank, by_arrival, emitted, steps)
            if skipped.any():
                by_arrival = by_arrival[~skipped[by_arrival]]
                emitted, ep, ek = emit_order(pix, g.key, by_arrival, self.depth_filter, return_keys=True)
        descent = np.zeros(len(ep), bool)
        descent[1:] = (ep[1:] == ep[:-1]) & (ek[1:] < ek[:-1])
        invalid = ep[descent]                     # pixels ascending
        invalid_pixels = int(len(invalid) and 1 + np.count_nonzero(invalid[1:] != invalid[:-1]))

        rgb = np.take(trace.rgba[:, :3], emitted, axis=0)
        image = composite_runs(ep, rgb, g.alpha[emitted], P, trace.background,
                               np.float32).reshape(trace.height, trace.width, 3)

        # bin classification
        B = grid.bins
        bin_tris = np.bincount(pb_bin, minlength=B)
        block_tris = np.bincount(tb_block)
        crowded = np.zeros(B, bool)
        crowded[grid.bin_of_block(np.flatnonzero(block_tris > self.low_block_triangles))] = True
        high = bin_tris >= self.high_bin_triangles
        promoted = ~high & (bin_tris > 0) & crowded
        low = (bin_tris > 0) & ~high & ~promoted
        counts = {"tbr": np.bincount(grid.bin_of_block_row(tbr_region), minlength=B),
                  "tb": np.bincount(grid.bin_of_block(tb_block), minlength=B),
                  "thb_bin": grid.bin_of_half_block(thb_region), "thb_tri": thb_tri,
                  "covered": np.flatnonzero(g.count), "block_tris": block_tris, "thb_region": thb_region,
                  "shaded": self._per_bin(grid, g.count if not skipped.any()
                                          else np.bincount(pix[~skipped], minlength=P))}
        plan, struct, overflow = self._plan(trace, grid, tri, tris, pb_bin, pb_tri, bin_tris, counts, high | promoted)
        covered_bins = int(np.count_nonzero(bin_tris))
        stats = {
            "invalid_pixels": Stat(invalid_pixels, "pixels", "pixels where a sample left the depth filter nearer "
                                                              "than one already blended"),
            "invalid_share": Stat(round(invalid_pixels / P, 8), "fraction", "invalid pixels / screen pixels"),
            "invalid_samples": Stat(int(descent.sum()), "samples", "samples blended after a farther one"),
            "bins": Stat({"empty": B - covered_bins, "low": int(low.sum()), "high": int(high.sum()),
                          "promoted": int(promoted.sum())}, "bins",
                         "bins by category (promoted: low by count, over a per-block limit)"),
            "tri_blocks": Stat(len(tb_block), "tri-blocks", "(8x8 block, triangle) pairs sorted in phase 2"),
            "tri_half_blocks": Stat(len(thb_tri), "tri-half-blocks", "(8x4 half-block, triangle) pairs"),
            "samples_per_tri_half_block": Stat(round(n / len(thb_tri), 4) if len(thb_tri) else 0.0, "samples",
                                               "S/THB as in the paper's tables"),
            "skipped_samples": Stat(int(skipped.sum()), "samples", "samples not shaded after the alpha threshold"),
            "scratch_overflow_bins": Stat(overflow, "bins", "bins whose tri-block-rows or tri-half-blocks "
                                                            "exceed their half of the scratch buffer"),
            "max_block_triangles": Stat(int(block_tris.max(initial=0)), "triangles", "most tri-blocks in a block"),
        }
        return SchemeResult(
            self.name, self.params(), image, n, g.covered, struct, plan, geometry_passes=1,
            dropped_fragments=int(skipped.sum()),
            overflowed_pixels=int(np.count_nonzero(np.bincount(pix[skipped], minlength=P))),
            lists=CapturedLists(ep, emitted),
            stats=stats)

    @staticmethod
    def _per_bin(grid, per_pixel: np.ndarray) -> np.ndarray:
        """Sum of a per-pixel count over each bin (int64)."""
        weights = per_pixel.astype(np.float64)     # exact: counts far below 2**53
        return np.bincount(grid.bin_of_pixel(np.arange(len(per_pixel))), weights=weights,
                           minlength=grid.bins).astype(np.int64)

    def _threshold_skips(self, trace, g, grid, half_block, frag_rank, by_arrival, emitted, steps) -> np.ndarray:
        """Samples never shaded because their half-block reached the alpha threshold first."""
        n, pix = len(trace), g.pix
        # position of each sample in its half-block's processing order
        hb_order = lex_order(half_block, frag_rank, -trace.y.astype(np.int64), trace.x)
        pos = np.empty(n, np.int64)
        pos[hb_order] = rank_in_runs(half_block[hb_order])
        cross = crossing_arrival(pix, emitted, steps, g.alpha, g.count)
        first = np.cumsum(g.count) - g.count
        has = cross >= 0
        cross_pos = np.full(g.pixel_count, np.iinfo(np.int64).max)
        cross_pos[has] = pos[by_arrival[first[has] + cross[has]]]
        # every on-screen pixel of the half-block must have crossed (a pixel without samples never does)
        allp = np.arange(g.pixel_count)
        hb_of_pixel = grid.half_block_of_pixel(allp % trace.width, allp // trace.width)
        stop = np.zeros(int(hb_of_pixel.max()) + 1, np.int64)
        np.maximum.at(stop, hb_of_pixel, cross_pos)
        never = stop == np.iinfo(np.int64).max
        limit = np.where(never, np.iinfo(np.int64).max, (stop // SEGMENT + 1) * SEGMENT)
        return pos >= limit[half_block]

    def _plan(self, trace, grid, tri, tris, pb_bin, pb_tri, bin_tris, counts, to_high):
        """The memory operations of the three stages, and the structures they touch."""
        B, WG = grid.bins, self.workgroups
        bins = np.flatnonzero(bin_tris)
        uses_high = bool(to_high[bins].any())
        uses_low = bool((~to_high[bins]).any())
        passes = [Pass("setup", "geometry", "entry"), Pass("bin-count", "geometry", "entry"),
                  Pass("bin-offsets", "fullscreen", "entry"), Pass("bin-write", "geometry", "entry"),
                  Pass("raster-low", "fullscreen", "entry"), Pass("raster-high", "fullscreen", "entry")]
        names = ["tri_data", "bin_counts", "bin_offsets", "bin_tri_lists"]
        names += (["scratch_low"] if uses_low else []) + (["scratch_high"] if uses_high else []) + ["framebuffer"]
        plan = OpPlan(passes, names)
        has_samples = np.zeros(max(tris, 1), bool)
        has_samples[pb_tri] = True
        visible_tris = np.flatnonzero(has_samples)
        n_vis, T = len(visible_tris), TRI_DATA_BYTES
        tri_pos = np.cumsum(has_samples) - 1
        # stage 1 and 2 (one thread per triangle, per (bin, triangle) pair, per bin)
        plan.add(0, "store", "tri_data", n_vis, 1, lambda i, s: i * T, T)
        # binning: persistent workgroups take batches of BINNING_BATCH triangles, count each (bin, triangle) pair
        # with a shared-memory atomic, then add each batch's count of a bin to the global counter once; the
        # write pass reserves each batch's run of a bin's list the same way, then stores the pairs
        batch_bin, leader, _ = unique_ids(pb_tri // BINNING_BATCH * B + pb_bin)
        plan.compute(1, len(pb_bin), SHARED_ATOMIC)
        plan.add(1, "atomic_inc", "bin_counts", leader, 1, lambda i, s: batch_bin[i] % B * 4, 4, dep=True)
        plan.add(2, "load", "bin_counts", B, 1, lambda i, s: i * 4, 4)
        plan.add(2, "store", "bin_offsets", B, 1, lambda i, s: i * 4, 4, dep=True)
        plan.compute(3, len(pb_bin), SHARED_ATOMIC)
        plan.add(3, "atomic_inc", "bin_offsets", leader, 1, lambda i, s: batch_bin[i] % B * 4, 4, dep=True)
        plan.add(3, "store", "bin_tri_lists", len(pb_bin), 1, lambda i, s: i * 4, 4, dep=True)
        # stage 3: a workgroup per non-empty bin (low: 256 threads, high: 1024), its lanes taking the bin's
        # items round robin (gpusim.schemes.common.workgroups); low and high bins run as two dispatches
        first = np.cumsum(bin_tris) - bin_tris
        tbr, tb, thb_tri = counts["tbr"], counts["tb"], counts["thb_tri"]
        thb = np.bincount(counts["thb_bin"], minlength=B)
        thb_order, thb_first = grouped(counts["thb_bin"], B)
        covered = counts["covered"]
        cov_bin = grid.bin_of_pixel(covered)
        cov_order, cov_first = grouped(cov_bin, B)
        px = np.bincount(cov_bin, minlength=B)
        # phase 2's sorts per bin: each block's tri-blocks (low), each half-block's tri-half-blocks (high)
        sorts = {}
        for name, tris_in, bin_of in (("block", counts["block_tris"], grid.bin_of_block),
                                      ("half", np.bincount(counts["thb_region"]), grid.bin_of_half_block)):
            sorts[name] = np.zeros(B, np.int64)
            np.add.at(sorts[name], bin_of(np.arange(len(tris_in))), bitonic_compares(tris_in))
        sort_work = np.where(to_high, sorts["half"], sorts["block"]) * KEY_COMPARE_EXCHANGE
        shade_work = counts["shaded"] * (self.depth_filter * COMPARE_EXCHANGE + COMPOSITE)
        slot = np.arange(len(bins)) % WG                                      # persistent workgroup of each bin
        overflow = 0
        for p, name, size, sel, lanes in ((4, "scratch_low", LOW_SCRATCH, ~to_high[bins], LOW_WORKGROUP),
                                          (5, "scratch_high", HIGH_SCRATCH, to_high[bins], HIGH_WORKGROUP)):
            b, base, half = bins[sel], slot[sel] * size, size // 2
            if len(b) == 0:
                continue

            def spread(op, structure, count, offset, nbytes, dep=False, b=b, lanes=lanes, p=p):
                """Bin ``b[i]``'s ``count[i]`` operations ``offset(i, s)``, dealt over its workgroup's lanes."""
                sp = Spread(b, count, lanes, HIGH_WORKGROUP)
                plan.add(p, op, structure, sp.threads, sp.counts, lambda i, s: offset(*sp.item(i, s)), nbytes,
                         dep=dep)

            def work(instructions, b=b, lanes=lanes, p=p):
                """ALU work of each bin, shared evenly by its workgroup's lanes."""
                used = np.minimum(instructions, lanes)            # lanes with work: one share each
                sp = Spread(b, used, lanes, HIGH_WORKGROUP)
                plan.compute(p, sp.threads, (-(-instructions // np.maximum(used, 1)))[sp.owner_index])

            overflow += int(np.count_nonzero((tbr[b] * TRI_BLOCK_ROW_BYTES > half)
                                             | (thb[b] * TRI_HALF_BLOCK_BYTES > half)))
            spread("load", "bin_offsets", np.ones(len(b), np.int64), lambda i, s, b=b: b[i] * 4, 4)
            spread("load", "bin_tri_lists", bin_tris[b], lambda i, s, b=b: (first[b[i]] + s) * 4, 4, dep=True)
            spread("load", "tri_data", bin_tris[b],                               # scanline data (last 32 B)
                   lambda i, s, b=b: tri_pos[pb_tri[first[b[i]] + s]] * T + T - 32, 32, dep=True)
            rows = lambda i, s, base=base, half=half: base[i] + (s * TRI_BLOCK_ROW_BYTES) % half  # noqa: E731
            halves = lambda i, s, base=base, half=half: (base[i] + half  # noqa: E731
                                                         + (s * TRI_HALF_BLOCK_BYTES) % half)
            spread("store", name, tbr[b], rows, TRI_BLOCK_ROW_BYTES)
            spread("load", name, tb[b], rows, TRI_BLOCK_ROW_BYTES, dep=True)
            work(sort_work[b])
            spread("store", name, thb[b], halves, TRI_HALF_BLOCK_BYTES)
            spread("load", name, thb[b], halves, TRI_HALF_BLOCK_BYTES, dep=True)
            spread("load", "tri_data", thb[b],                                    # shading data per tri-half-block
                   lambda i, s, b=b: tri_pos[thb_tri[thb_order[thb_first[b[i]] + s]]] * T + 4, 32, dep=True)
            # phase 3: every shaded sample passes the pixel's depth filter and is blended
            work(shade_work[b])
            spread("store", "framebuffer", px[b], lambda i, s, b=b: covered[cov_order[cov_first[b[i]] + s]] * 4, 4,
                   dep=True)
        low_b, high_b = bins[~to_high[bins]], bins[to_high[bins]]
        peak = lambda b: int(np.maximum(tbr[b] * TRI_BLOCK_ROW_BYTES, 0).max(initial=0)  # noqa: E731
                             + (thb[b] * TRI_HALF_BLOCK_BYTES).max(initial=0))
        struct = [
            Structure("tri_data", T, n_vis, n_vis, "per-triangle setup data (84 B) of triangles with samples"),
            Structure("bin_counts", 4, B, len(bins), "32-bit triangle count per 32x32 bin"),
            Structure("bin_offsets", 4, B, len(bins), "prefix-sum offset of each bin's list"),
            Structure("bin_tri_lists", 4, len(pb_bin), len(pb_bin), "32-bit triangle index per (bin, triangle)"),
        ]
        if uses_low:
            struct.append(Structure("scratch_low", 1, WG * LOW_SCRATCH, min(peak(low_b), WG * LOW_SCRATCH),
                                    f"{WG} x 128 KiB low-rasterizer scratch (used: the largest bin's need)"))
        if uses_high:
            struct.append(Structure("scratch_high", 1, WG * HIGH_SCRATCH, min(peak(high_b), WG * HIGH_SCRATCH),
                                    f"{WG} x 768 KiB high-rasterizer scratch (used: the largest bin's need)"))
        struct.append(Structure("framebuffer", 4, trace.pixel_count, len(covered), "RGBA8 per pixel"))
        return plan, struct, overflow
