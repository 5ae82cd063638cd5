"""LucidRaster (seed 002; Jakubowski): a sort-middle software rasterizer, its functional model and its plan.

The functional model: per 32x32 bin and 8x8 block, the tri-blocks (a triangle's
samples in that block) are sorted front to back by the depth at the centroid of
their samples, as a 32-bit word of 22 depth bits over 10 index bits (ties: the
triangle listed first, i.e. submitted first). Window depth is affine in screen
space on a planar triangle, so the depth at the centroid equals the mean of the
samples' depths; the 22 bits are the top of the float's ordered bit pattern
(gpusim.schemes.common.depthkey). Each pixel then receives its samples in that
order and passes them through a depth filter, a fixed-size priority queue of
``depth_filter`` entries from which the nearest sample falls out and is blended
front to back (gpusim.schemes.common.depth_filter). A pixel is **invalid** (the
paper's count) when a sample falls out nearer than one already blended: the
two-stage sort failed there; the true image error against the exact reference is
reported beside it by ``replay``. ``alpha_threshold``: shading of a half-block
stops once every pixel in it has accumulated alpha >= 1 - 1/128, checked after
each segment of 256 samples (samples ordered by tri-half-block, then row by row
from the top-left); the samples not shaded are counted (``skipped_samples``).
The ``bins`` stat classifies bins by the triangles with samples in them (empty,
low below ``high_bin_triangles``, high; promoted: low with a block of more than
``low_block_triangles`` tri-blocks).

The plan follows the public shaders (nadult/lucid, data/shaders; dispatched in
src/lucid_renderer.cpp) stage by stage, one pass per dispatch group:

* ``setup`` (quad_setup.glsl): a lane per input quad (two consecutive triangles,
  all the scene submits), 1,024-quad chunks per workgroup: its indices and 4
  vertices, the culling tests, projection, clip masks, AABBs; visible quads (a
  triangle with samples) are compacted, small (AABB of at most 4 bins) before
  large, and each set-up triangle's storages written (normal 4 B, depth equation
  16 B, barycentric edges 32 B, scanline edges 32 B), each quad's AABB word.
* binning, three dispatches: ``bin-count`` (bin_counter.glsl: persistent
  workgroups take batches of 4,096 small quads or 512 large ones; a shared atomic
  per bin of a small quad's AABB, per bin row of a large triangle's scanline; the
  workgroup's counts saved and added to the global ones), ``bin-offsets``
  (bin_categorizer.glsl: prefix sums into list offsets; the low and high lists,
  a quad counting as 2 triangles) and ``bin-write`` (bin_dispatcher.glsl: each
  workgroup reserves its runs of the lists with one atomic per bin it touched,
  then writes its entries; large triangles' rows balanced over the subgroup).
* ``raster-low`` and ``raster-high`` (raster_low.glsl, raster_high.glsl,
  shared/raster.glsl, shared/shading.glsl): a workgroup per bin (256 and 1,024
  lanes; the shader's persistent workgroups take the bins in turn). Phase 1
  generateRowTris: each listed triangle's scanline rows into tri-block-rows (low:
  8-pixel block-rows; high: 4-pixel half-block rows) in the scratch buffer.
  Phase 2, low: a subgroup per block tests its block-row's list, takes each
  tri-block's centroid depth, sorts the keys (bitonic, subgroup shuffles; only
  when the block holds more tri-blocks than the depth filter) and stores two
  tri-half-blocks each; high: per half-block a group of 32 x 2^k lanes does the
  same, every half-block sorted to the bin's largest count. Phase 3, a subgroup
  per half-block: segments of 256 samples unpacked, shaded 32 at a time (the
  triangle's depth equation, barycentric edges, instance colour and normal
  loaded per sample; shadeSample's lighting and sRGB conversions), each pixel's
  samples through the depth filter (reduceSample loops while any lane has one),
  then every pixel of the half-block written. A bin promoted by the low
  rasterizer does phases 1-2 there, then all of it in the high one.

The instruction counts are gpusim.schemes.common.alu's, each named by its shader
function; a loop over a shared list gives lane ``l`` the items ``l, l + size, ...``;
work a subgroup does in step (sorting, shading, blending) is charged to each of its
lanes, as long as its busiest lane needs. Traces carry fragments, not vertices: the
work items are derived from the samples (gpusim.schemes.common.lucid_bins). The
timing model has no L1: loads the shader makes of one span (a quad's 4 indices, a
vertex's 3 floats, the two halves of a uvec4[2]) are one load, the others' issue
slots ALU work (``L1_SPAN_LOADS``).

Footprint: the scene's index and vertex buffers, instance records, the counters,
the per-triangle and per-quad storages, per-bin counts, offsets, level lists and
the binning workgroups' saved counts, the bin lists, the scratch buffers of
``workgroups`` persistent workgroups (low rasterizer 128 KiB: 4 x 1024
tri-block-rows of 16 B and 32 x 256 tri-half-blocks of 8 B; high rasterizer
768 KiB, only when a bin needs it) and the framebuffer.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from gpusim.config import param
from gpusim.metrics.composite import composite_runs, runs_by_length
from gpusim.opplan import OpPlan, Pass
from gpusim.schemes.base import Scheme, register
from gpusim.schemes.common.alu import (
    BIN_BALANCE_ENTRY, BIN_BALANCE_ROW, BIN_BATCH, BIN_BATCH_LANE, BIN_CLEAR_STEP, BIN_COPY_STEP, BIN_OFFSET_STEP,
    BIN_QUAD, BIN_QUAD_BIN, BIN_ROW_PREFIX, BIN_TRI, BIN_TRI_ROW, BLOCK_ROW_HIT, BLOCK_ROW_TEST, BLOCK_SCAN,
    BLOCK_SETUP, CATEGORIZE_BIN, CATEGORIZE_OFFSET, CATEGORIZE_SCAN, CATEGORIZE_TOTALS, HALF_BLOCK_START,
    L1_SPAN_LOADS, RASTER_BIN_FETCH, RASTER_BIN_LANE, RASTER_STATS, RBLOCK_COUNT, RBLOCK_DEPTH, RBLOCK_GROUPS,
    RBLOCK_GROUPS_LEAD, RBLOCK_PREFIX, RBLOCK_SETUP, RBLOCK_STORE, REDUCE_SWAP, REDUCE_THRESHOLD, ROW_QUAD_ENTRY,
    ROW_STEP_HIGH, ROW_STEP_LOW, ROW_STORE_HIGH, ROW_STORE_LOW, ROW_TRI_ENTRY, ROW_TRI_SETUP, SETUP_AABB,
    SETUP_BACKFACE, SETUP_CHUNK_LANE, SETUP_CHUNK_LEAD, SETUP_COMPACT, SETUP_PROJECT, SETUP_QUAD_INPUT,
    SETUP_QUAD_STORE, SETUP_TRI, SETUP_TRI_ENTRY, SHADE_SAMPLE, SHADE_STEP, SHARED_ATOMIC, TRI_BLOCK_DEPTH,
    TRI_HALF_BLOCKS, UNPACK_BITS, UNPACK_BIT_SAMPLE, UNPACK_ROWS, UNPACK_ROW_SAMPLE, UNPACK_SEGMENT, finish_work,
    lucid_sort_work, reduce_step)
from gpusim.schemes.common.arrays import lex_order, rank_in_runs, unique_ids
from gpusim.schemes.common.depth_filter import emit_order
from gpusim.schemes.common.depthkey import depth_key
from gpusim.schemes.common.groups import PixelGroups
from gpusim.schemes.common.lucid_bins import (
    BIN,
    BLOCK,
    HALF_BLOCK_H,
    Grid,
    aabb_bins,
    pairs,
    quad_aabbs,
    row_spans,
    rows_in_bins,
)
from gpusim.schemes.common.reorder import submitted_primitives
from gpusim.schemes.common.workgroups import Lanes, thread_totals
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
MAX_DISPATCHES = 256         # lucid_renderer.cpp: persistent workgroups on a GPU of 4 GB or more
SETUP_CHUNK = 1024           # quad_setup.glsl: quads per setup workgroup (MAX_INSTANCE_QUADS), its threads
BIN_WORKGROUP = 1024         # bin_counter / bin_dispatcher threads (BIN_DISPATCHER_LSIZE with 32x32 bins)
SMALL_BATCH = 4096           # small quads per batch (LSIZE * SMALL_BATCH_STEPS)
LARGE_BATCH = 512            # large quads per batch (LSIZE / 2: a lane per triangle)
SMALL_QUAD_BINS = 4          # a quad whose bin AABB holds more bins is large
SUBGROUP = 32                # raster.glsl HALFGROUP_SIZE: a half-block's 32 pixels, an NVidia subgroup
MAX_BLOCK_ROW_TRIS = 1024    # raster_low.glsl: tri-block-rows per block-row
MAX_BLOCK_TRIS = 256         # raster_low.glsl: tri-half-blocks per half-block
MAX_HBLOCK_ROW_TRIS = 16384  # raster_high.glsl: tri-half-block-rows per half-block row
MAX_HBLOCK_TRIS = 4096       # raster_high.glsl: tri-half-blocks per half-block (256 x MAX_GROUP_SIZE)
MAX_GROUP = 16               # raster_high.glsl MAX_GROUP_SIZE: subgroups per half-block
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
        overflow = self._scratch_overflow(grid, bin_tris, tbr_region, thb_region, high | promoted)
        frag_rank_tb = np.zeros(len(tb_block), np.int64)
        frag_rank_tb[tb_of] = frag_rank
        thb_rank = np.empty(len(thb_tri), np.int64)
        o = lex_order(thb_region, frag_rank_tb[thb_to_tb])
        thb_rank[o] = rank_in_runs(thb_region[o]) if len(o) else o
        plan, struct = self._plan(trace, g, grid, _Functional(
            tri, half_block, thb_region, thb_tri, thb_of, tb_block, tb_tri, thb_to_tb, tbr_region, tbr_tri,
            pb_bin, pb_tri, frag_rank, frag_rank_tb, thb_rank, skipped))
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
    def _scratch_overflow(grid, bin_tris, tbr_region, thb_region, to_high) -> int:
        """Bins (non-empty, by their triangles with samples) whose tri-block-rows or tri-half-blocks exceed their
        half of the low (128 KiB) or high (768 KiB) rasterizer's scratch buffer."""
        B = grid.bins
        bins = np.flatnonzero(bin_tris)
        tbr = np.bincount(grid.bin_of_block_row(tbr_region), minlength=B)[bins]
        thb = np.bincount(grid.bin_of_half_block(thb_region), minlength=B)[bins]
        half = np.where(to_high[bins], HIGH_SCRATCH // 2, LOW_SCRATCH // 2)
        return int(np.count_nonzero((tbr * TRI_BLOCK_ROW_BYTES > half) | (thb * TRI_HALF_BLOCK_BYTES > half)))

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

    def _plan(self, trace, g, grid, f: _Functional):
        """The memory operations and ALU work of the three stages, and the structures they touch."""
        return _LucidPlan(self, trace, g, grid, f).build()


@dataclass
class _Functional:
    """What the functional model found that the plan follows: the (region, triangle) pairs at each level
    (gpusim.schemes.common.lucid_bins.pairs, sorted by region then triangle), each sample's tri-half-block and
    its tri-block's rank in its block's depth order, the samples the alpha threshold skips."""

    tri: np.ndarray
    half_block: np.ndarray
    thb_region: np.ndarray
    thb_tri: np.ndarray
    thb_of: np.ndarray
    tb_block: np.ndarray
    tb_tri: np.ndarray
    thb_to_tb: np.ndarray
    tbr_region: np.ndarray
    tbr_tri: np.ndarray
    pb_bin: np.ndarray
    pb_tri: np.ndarray
    frag_rank: np.ndarray
    frag_rank_tb: np.ndarray      # each tri-block's rank in its block's depth order
    thb_rank: np.ndarray          # each tri-half-block's rank in its half-block (by its tri-block's rank)
    skipped: np.ndarray


# lucid_info (structures.glsl LucidInfo): byte offsets of the counters the stages touch
INFO_INPUT_QUADS, INFO_VISIBLE_QUADS, INFO_COUNTED_QUADS, INFO_LEVEL_COUNTS = 0, 4, 12, 20
INFO_SMALL_BINS, INFO_HIGH_BINS, INFO_SETUP_GROUPS, INFO_DISPATCHES = 40, 44, 48, 56
INFO_REJECTED, INFO_STATS, INFO_DISPATCHER = 192, 224, 1024
INFO_BYTES = INFO_DISPATCHER + 2 * 2 * 4 * 256          # dispatcher_first_batch and _num_batches [2][256]
# tri_data: the per-triangle storages of quad_setup.glsl storeTri, one array each (structure of arrays)
BARY_BYTES, SCAN_BYTES, DEPTH_BYTES, NORMAL_BYTES = 32, 32, 16, 4
INSTANCE_BYTES = 16 + 4      # InstanceData (16 B) and the instance colour (g_instance_colors)


def _culls(trace) -> bool:
    """Whether the scene was drawn with back-face culling (the trace's scene config; off when unknown)."""
    cfg = trace.meta.get("scene_config") if isinstance(trace.meta, dict) else None
    raster = cfg.get("raster") if isinstance(cfg, dict) else None
    return isinstance(raster, dict) and raster.get("cull", "none") not in (None, "none")


def _steps(total: int, lanes: int) -> np.ndarray:
    """Iterations of each of ``lanes`` lanes in a loop ``for (i = lane; i < total; i += lanes)``."""
    return np.maximum(-(-(total - np.arange(lanes)) // lanes), 0)


def _next_pow2(n: np.ndarray, least: int) -> np.ndarray:
    n = np.maximum(np.asarray(n, np.int64), 1)
    return np.maximum(1 << np.ceil(np.log2(n)).astype(np.int64), least)


def _rank_in_groups(key: np.ndarray) -> np.ndarray:
    """Position of each element among the elements of equal ``key`` (in index order)."""
    if len(key) == 0:
        return np.zeros(0, np.int64)
    order = lex_order(key)
    rank = np.empty(len(key), np.int64)
    rank[order] = rank_in_runs(key[order])
    return rank


def _lookup(keys: np.ndarray, wanted: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Index of each ``wanted`` in the sorted unique ``keys``, and whether it is there."""
    at = np.searchsorted(keys, wanted)
    at = np.minimum(at, max(len(keys) - 1, 0))
    found = (keys[at] == wanted) if len(keys) else np.zeros(len(wanted), bool)
    return at, found


class _LucidPlan:
    """LucidRaster's OpPlan, stage by stage, as its shaders (nadult/lucid data/shaders) do the work.

    Threads are the lanes of each dispatch's workgroups: the setup's ``chunk * 1024 + lane`` (a lane per
    input quad), binning's ``workgroup * 1024 + lane``, the rasterizers' ``bin * 1024 + lane`` (256 or 1,024
    lanes: a workgroup per bin; the shader's persistent workgroups take the bins in turn). ALU work is the
    instruction counts of gpusim.schemes.common.alu on the lanes that run it; a loop over a shared list gives
    lane ``l`` its items ``l, l + size, ...``; work a subgroup does in step (sorting, shading, blending) is
    charged to each of its lanes."""

    def __init__(self, scheme, trace, g, grid, f: _Functional):
        self.s, self.trace, self.g, self.grid, self.f = scheme, trace, g, grid, f
        self.DF = scheme.depth_filter

    # ------------------------------------------------------------------ work items (no plan yet)
    def build(self):
        self._quads()
        self._bin_lists()
        self._bins()
        self._structures()
        self.plan = OpPlan([Pass("setup", "geometry", "entry"), Pass("bin-count", "geometry", "entry"),
                            Pass("bin-offsets", "fullscreen", "entry"), Pass("bin-write", "geometry", "entry"),
                            Pass("raster-low", "fullscreen", "entry"), Pass("raster-high", "fullscreen", "entry")],
                           [st.name for st in self.struct])
        self._setup(0)
        self._bin_count(1)
        self._bin_offsets(2)
        self._bin_write(3)
        self._raster(4, high=False)
        self._raster(5, high=True)
        return self.plan, self.struct

    def _quads(self):
        """quad_setup.glsl: every input quad (two consecutive triangles) is tested; the visible ones (a
        triangle with samples) are compacted, small (bin AABB of at most 4 bins) before large."""
        f, grid = self.f, self.grid
        T = max(submitted_primitives(self.trace), int(f.tri.max(initial=-1)) + 1)
        Q = -(-T // 2)
        self.T, self.Q = T, Q
        has = np.zeros(2 * Q, bool)
        has[f.pb_tri] = True
        self.cull = _culls(self.trace)
        aabb = quad_aabbs(grid.bins_x, f.pb_bin, f.pb_tri, Q)
        vis = aabb[:, 0] >= 0
        nab = np.where(vis, (aabb[:, 2] - aabb[:, 0] + 1) * (aabb[:, 3] - aabb[:, 1] + 1), 0)
        large = vis & (nab > SMALL_QUAD_BINS)
        small = vis & ~large
        exists = np.arange(2 * Q) < T
        # a triangle is set up unless the quad's culling flag marks it (no samples with back-face culling on; a
        # quad of one triangle has its second flagged)
        self.setup_tri = (has if self.cull else np.repeat(vis, 2)) & exists
        self.qs, self.ql = np.flatnonzero(small), np.flatnonzero(large)
        self.qslot = np.full(Q, -1, np.int64)
        self.qslot[self.qs] = np.arange(len(self.qs))
        self.qslot[self.ql] = len(self.qs) + np.arange(len(self.ql))
        self.NV = len(self.qs) + len(self.ql)
        self.vis, self.large, self.aabb, self.nab = vis, large, aabb, nab
        self.chunks = -(-Q // SETUP_CHUNK)
        # the vertex grid a quad's corners come from: 2 vertices in its row, 2 in the next
        self.row = max(1, int(np.ceil(np.sqrt(max(Q, 1)))))
        self.vertices = Q + self.row + 2

    def _bin_lists(self):
        """bin_dispatcher.glsl: a small quad is listed in every bin of its AABB (g_bin_quads), a large quad's
        triangles in the bins of each row they span (g_bin_tris)."""
        f, bx = self.f, self.grid.bins_x
        B = self.grid.bins
        owner, qbin = aabb_bins(self.aabb[self.qs], bx)
        self.sq_slot, self.sq_bin = owner, qbin                     # small slot (index into qs) of each entry
        keep = np.zeros(2 * self.Q, bool)
        lq = np.zeros(self.Q, bool)
        lq[self.ql] = True
        keep[:] = np.repeat(lq, 2) & self.setup_tri
        self.lt_tri, self.lt_bin, self.lt_row, self.lt_rows = row_spans(bx, f.pb_bin, f.pb_tri, keep)
        self.nq = np.bincount(qbin, minlength=B)
        self.nt = np.bincount(self.lt_bin, minlength=B)
        # each bin's list: entries by bin, then by slot (quads) or triangle (large triangles)
        self.q_order = lex_order(qbin, owner)
        self.q_pos = np.empty(len(qbin), np.int64)
        self.q_pos[self.q_order] = rank_in_runs(qbin[self.q_order])
        self.q_first = np.cumsum(self.nq) - self.nq
        lt_slot = 2 * self.qslot[self.lt_tri // 2] + self.lt_tri % 2
        self.t_order = lex_order(self.lt_bin, lt_slot)
        self.t_pos = np.empty(len(self.lt_bin), np.int64)
        self.t_pos[self.t_order] = rank_in_runs(self.lt_bin[self.t_order])
        self.t_first = np.cumsum(self.nt) - self.nt
        # batches: bin_counter.glsl's workgroups take small quads 4,096 and large quads 512 at a time
        self.nbs, self.nbl = -(-len(self.qs) // SMALL_BATCH), -(-len(self.ql) // LARGE_BATCH)
        self.D = int(np.clip(self.nbs + self.nbl, 4, MAX_DISPATCHES))

    def _bins(self):
        """bin_categorizer.glsl: a bin is low below ``high_bin_triangles`` (a quad counts as 2), high at or
        above; raster_low.glsl promotes a bin with a block over ``low_block_triangles`` tri-blocks to high."""
        f, grid, B = self.f, self.grid, self.grid.bins
        ntri = 2 * self.nq + self.nt
        high = ntri >= self.s.high_bin_triangles
        low = (ntri > 0) & ~high
        self.block_tris = np.bincount(f.tb_block, minlength=grid.blocks_x * -(-self.trace.height // BLOCK))
        crowded = np.zeros(B, bool)
        crowded[grid.bin_of_block(np.flatnonzero(self.block_tris > self.s.low_block_triangles))] = True
        self.promoted = low & crowded
        self.low_bins = np.flatnonzero(low)
        self.high_bins = np.flatnonzero(high | self.promoted)
        self.high = high
        self.level_id = np.full(B, -1, np.int64)          # position in LOW_LEVEL_BINS
        self.level_id[low] = np.arange(int(low.sum()))
        self.high_id = np.full(B, -1, np.int64)           # position in HIGH_LEVEL_BINS (promoted bins appended)
        self.high_id[high] = np.arange(int(high.sum()))
        self.high_id[self.promoted] = int(high.sum()) + np.arange(int(self.promoted.sum()))

    def _structures(self):
        B, WG = self.grid.bins, self.s.workgroups
        P, NV = self.trace.pixel_count, self.NV
        n_setup = int(self.setup_tri.sum())
        struct = [
            Structure("indices", 16, self.Q, self.Q, "input: 4 vertex indices per quad (two consecutive triangles)"),
            Structure("vertices", 12, self.vertices, self.vertices, "input: vertex positions (3 floats)"),
            Structure("instances", INSTANCE_BYTES, self.chunks, self.chunks,
                      "instance records and colours, one per chunk of 1,024 quads"),
            Structure("lucid_info", 1, INFO_BYTES, INFO_BYTES, "LucidInfo: global counters and dispatch sizes"),
            Structure("quad_aabbs", 4, NV, NV, "bin AABB and culling bits of each visible quad"),
            Structure("tri_data", TRI_DATA_BYTES, 2 * NV, n_setup,
                      "per-triangle storages (84 B): barycentric and scanline edges, depth equation, normal"),
            Structure("bin_counts", 8, B, int(np.count_nonzero(self.nq + self.nt)),
                      "per bin: quads and large triangles listed"),
            Structure("bin_offsets", 16, B, int(np.count_nonzero(self.nq + self.nt)),
                      "per bin: list offsets of quads and triangles, and their running copies"),
            Structure("bin_levels", 8, B, len(self.low_bins) + len(self.high_bins), "low and high bin lists"),
            Structure("bin_batches", 8, self.D * B + self.nbs + self.nbl, self.D * B,
                      "per binning workgroup: its per-bin counts, and the batches' links"),
            Structure("bin_quad_lists", 4, len(self.sq_bin), len(self.sq_bin), "small quad index per (bin, quad)"),
            Structure("bin_tri_lists", 4, len(self.lt_bin), len(self.lt_bin),
                      "large triangle index per (bin, triangle)"),
        ]
        f = self.f
        tbr_bin = self.grid.bin_of_block_row(f.tbr_region)
        thb_bin = self.grid.bin_of_half_block(f.thb_region)
        rows = np.bincount(tbr_bin, minlength=B) * TRI_BLOCK_ROW_BYTES
        halves = np.bincount(thb_bin, minlength=B) * TRI_HALF_BLOCK_BYTES
        self.uses_low, self.uses_high = len(self.low_bins) > 0, len(self.high_bins) > 0
        if self.uses_low:
            need = int((rows + halves)[self.low_bins].max(initial=0))
            struct.append(Structure("scratch_low", 1, WG * LOW_SCRATCH, min(need, WG * LOW_SCRATCH),
                                    f"{WG} x 128 KiB low-rasterizer scratch (used: the largest bin's need)"))
        if self.uses_high:
            need = int((rows + halves)[self.high_bins].max(initial=0))
            struct.append(Structure("scratch_high", 1, WG * HIGH_SCRATCH, min(need, WG * HIGH_SCRATCH),
                                    f"{WG} x 768 KiB high-rasterizer scratch (used: the largest bin's need)"))
        struct.append(Structure("framebuffer", 4, P, int(np.count_nonzero(self.g.count)), "RGBA8 per pixel"))
        self.struct = struct
        # tri_data regions (structure of arrays over 2 slots per visible quad)
        self.bary0, self.scan0 = 0, BARY_BYTES * 2 * NV
        self.depth0 = (BARY_BYTES + SCAN_BYTES) * 2 * NV
        self.normal0 = (BARY_BYTES + SCAN_BYTES + DEPTH_BYTES) * 2 * NV
        self.colour0 = 16 * self.chunks

    # ------------------------------------------------------------------ plan helpers
    def add(self, p, op, structure, lanes: Lanes, offset: np.ndarray, nbytes, dep=False):
        """``lanes``' items as a group; ``offset[k]`` the byte offset of item ``k``."""
        if len(lanes.threads):
            self.plan.add(p, op, structure, lanes.threads, lanes.counts,
                          lambda i, s, o=offset, ln=lanes: o[ln.item(i, s)], nbytes, dep=dep)

    def each(self, p, op, structure, thread, offset, nbytes, dep=False, count=1):
        """One operation (``count`` of them, at consecutive items of ``offset``) per thread."""
        thread = np.asarray(thread, np.int64)
        if len(thread):
            off = np.asarray(offset, np.int64)
            if count == 1:
                self.plan.add(p, op, structure, thread, 1, lambda i, s, o=off: o[i], nbytes, dep=dep)
            else:
                self.plan.add(p, op, structure, thread, count, lambda i, s, o=off: o[i * count + s], nbytes,
                              dep=dep)

    def alu(self, p, thread, work, dep=True):
        """ALU work: ``work[k]`` instructions on ``thread[k]`` (summed per thread)."""
        threads, totals = thread_totals(thread, work)
        if len(threads):
            self.plan.compute(p, threads, totals, dep=dep)

    def tslot(self, tri):
        """A triangle's slot in tri_data: 2 per visible quad, small quads first."""
        return 2 * self.qslot[tri // 2] + tri % 2

    # ------------------------------------------------------------------ stage 1: quad_setup.glsl
    def _setup(self, p):
        Q, C, cull = self.Q, self.chunks, self.cull
        q = np.arange(Q)
        chunk, lead = q // SETUP_CHUNK, np.arange(C) * SETUP_CHUNK
        # main: a chunk's instance record and its quads' offset (lane 0)
        self.each(p, "load", "instances", lead, np.arange(C) * INSTANCE_BYTES, 16)
        self.each(p, "atomic_inc", "lucid_info", lead, np.full(C, INFO_INPUT_QUADS), 4, dep=True)
        # processInputQuad: 4 indices (g_indices), then 4 vertices of 3 floats (vertexLoad, their addresses from
        # the indices): 4 and 12 scalar loads, each run of them one load here (L1_SPAN_LOADS)
        corner = np.array([0, 1, self.row + 1, self.row])
        self.each(p, "load", "indices", q, q * 16, 16)
        self.each(p, "load", "vertices", q, ((q[:, None] + corner) * 12).ravel(), 12, dep=True, count=4)
        visible = (SETUP_QUAD_INPUT + (SETUP_BACKFACE if cull else 0) + SETUP_PROJECT + SETUP_AABB
                   + SETUP_COMPACT + L1_SPAN_LOADS * (3 + 4 * 2))
        culled = (SETUP_QUAD_INPUT + (SETUP_BACKFACE if cull else SETUP_PROJECT) + SHARED_ATOMIC
                  + L1_SPAN_LOADS * (3 + 4 * 2))
        self.alu(p, q, np.where(self.vis, visible, culled))
        # main after phase 1: the chunk's visible counts into the global ones (lanes 0, 1); every lane reads them
        two = (lead[:, None] + np.arange(2)).ravel()
        self.each(p, "atomic_inc", "lucid_info", two, np.tile(INFO_VISIBLE_QUADS + 4 * np.arange(2), C), 4, dep=True)
        self.alu(p, q, np.full(Q, SETUP_CHUNK_LANE), dep=False)
        # the triangle loop: triangle j of the chunk's compacted quads on lane j % 1024 (addVisibleTri, storeTri)
        vq = np.flatnonzero(self.vis)
        vchunk = chunk[vq]
        n_small = np.bincount(chunk[self.qs], minlength=C)
        k = np.empty(len(vq), np.int64)                  # compacted position in the chunk: small, then large
        is_large = self.large[vq]
        k[~is_large] = _rank_in_groups(vchunk[~is_large])
        k[is_large] = n_small[vchunk[is_large]] + _rank_in_groups(vchunk[is_large])
        j = (2 * k[:, None] + np.arange(2)).ravel()
        t_tri = (2 * vq[:, None] + np.arange(2)).ravel()
        t_thread = np.repeat(vchunk, 2) * SETUP_CHUNK + j % SETUP_CHUNK
        t_seq = j // SETUP_CHUNK
        up = self.setup_tri[t_tri]
        st, sth, sseq = t_tri[up], t_thread[up], t_seq[up]
        second = st % 2
        corners = np.stack([np.zeros_like(second), 1 + second, 2 + second], 1)     # v0, v1 + s, v2 + s
        vidx = (st // 2)[:, None] + corner[corners]
        loads = Lanes(np.repeat(sth, 3), np.repeat(sseq, 3), np.tile(np.arange(3), len(st)))
        self.add(p, "load", "vertices", loads, (vidx * 12).reshape(-1), 12)
        self.alu(p, t_thread, SETUP_TRI_ENTRY + (SETUP_TRI + L1_SPAN_LOADS * 3 * 2) * up)
        slot = self.tslot(st)
        stores = Lanes(sth, sseq)
        self.add(p, "store", "tri_data", stores, self.normal0 + slot * NORMAL_BYTES, NORMAL_BYTES)
        self.add(p, "store", "tri_data", stores, self.depth0 + slot * DEPTH_BYTES, DEPTH_BYTES)
        for half in (0, 16):
            self.add(p, "store", "tri_data", stores, self.bary0 + slot * BARY_BYTES + half, 16)
        for half in (0, 16):
            self.add(p, "store", "tri_data", stores, self.scan0 + slot * SCAN_BYTES + half, 16)
        # the quad loop (addVisibleQuad, storeQuad): the instance flags and the quad's AABB word
        qthread = vchunk * SETUP_CHUNK + k
        self.alu(p, qthread, np.full(len(vq), SETUP_QUAD_STORE), dep=False)
        self.each(p, "load", "instances", qthread, vchunk * INSTANCE_BYTES + 12, 4)
        self.each(p, "store", "quad_aabbs", qthread, self.qslot[vq] * 4, 4)
        # main's end: the rejection counters (lanes 0-3), the finished-chunk counter and the dispatch count
        four = (lead[:, None] + np.arange(4)).ravel()
        self.each(p, "atomic_inc", "lucid_info", four, np.tile(INFO_REJECTED + 4 * np.arange(4), C), 4)
        self.each(p, "atomic_inc", "lucid_info", lead, np.full(C, INFO_SETUP_GROUPS), 4, dep=True)
        self.alu(p, lead, np.full(C, SETUP_CHUNK_LEAD))

    # ------------------------------------------------------------------ stage 2: binning
    def _batches(self):
        """Each binning workgroup's small and large batches (batch b to workgroup b % D) and the lanes of
        their quads: a small quad on lane i % 1024 of its batch (4 steps), a large quad's triangles on lanes
        2 (i % 512) and 2 (i % 512) + 1."""
        D = self.D
        i = np.arange(len(self.qs))
        s_batch = i // SMALL_BATCH
        s_thread = (s_batch % D) * BIN_WORKGROUP + i % BIN_WORKGROUP
        lq = np.arange(len(self.ql))
        l_batch = lq // LARGE_BATCH
        l_tri = (2 * self.ql[:, None] + np.arange(2)).ravel()
        l_thread = np.repeat((l_batch % D) * BIN_WORKGROUP, 2) + (2 * (lq % LARGE_BATCH))[:, None].repeat(
            2, 1).ravel() + np.tile(np.arange(2), len(lq))
        return s_batch, s_thread, np.repeat(l_batch, 2), l_tri, l_thread

    def _wg_batches(self, n_batches):
        return np.bincount(np.arange(n_batches) % self.D, minlength=self.D)

    def _workgroup_lanes(self, p, work_per_lane):
        """Every lane of the D binning workgroups runs ``work_per_lane`` (an array over 1,024 lanes)."""
        threads = (np.arange(self.D)[:, None] * BIN_WORKGROUP + np.arange(BIN_WORKGROUP)).ravel()
        self.alu(p, threads, np.tile(work_per_lane, self.D), dep=False)

    def _bin_copy(self, p, op, structure, wgs, base_of, steps, nbytes=4, dep=False):
        """Per workgroup in ``wgs``, its lanes' loop over the bins: ``op`` at base_of(w) + 4 i."""
        lane = np.arange(BIN_WORKGROUP)
        thread = (wgs[:, None] * BIN_WORKGROUP + lane).ravel()
        cnt = np.tile(steps, len(wgs))
        keep = cnt > 0
        base = np.repeat(base_of(wgs), BIN_WORKGROUP)[keep]
        ln = np.tile(lane, len(wgs))[keep]
        if keep.any():
            self.plan.add(p, op, structure, thread[keep], cnt[keep],
                          lambda i, s, b=base, ln=ln: b[i] + (ln[i] + s * BIN_WORKGROUP) * 4, nbytes, dep=dep)

    def _wg_bins(self, wg_of_entry, bin_of_entry):
        """The distinct (workgroup, bin) pairs of a phase's entries: the bins each workgroup touched."""
        B = self.grid.bins
        if len(bin_of_entry) == 0:
            return np.zeros(0, np.int64), np.zeros(0, np.int64)
        u, _, _ = unique_ids(wg_of_entry * B + bin_of_entry)
        return u // B, u % B

    def _bin_count(self, p):
        """bin_counter.glsl: per-bin counts in shared memory, batch by batch, then added to the global ones."""
        B, D = self.grid.bins, self.D
        steps = _steps(B, BIN_WORKGROUP)
        clears = (2 if len(self.qs) else 0) + (1 if len(self.ql) else 0)
        self._workgroup_lanes(p, 1 + BIN_CLEAR_STEP * steps * clears)
        wg = np.arange(D)
        self.each(p, "load", "lucid_info", (wg[:, None] * BIN_WORKGROUP + np.arange(2)).ravel(),
                  np.tile(INFO_VISIBLE_QUADS + 4 * np.arange(2), D), 4)
        s_batch, s_thread, l_batch, l_tri, l_thread = self._batches()
        lead = wg * BIN_WORKGROUP
        for phase, n_b in ((0, self.nbs), (1, self.nbl)):
            if not n_b:
                continue
            per_wg = self._wg_batches(n_b)
            # lane 0 acquires batches (one failing try at the end) and links them
            self.plan.add(p, "atomic_inc", "lucid_info", lead, per_wg + 1,
                          lambda i, s, ph=phase: np.full(len(i), INFO_COUNTED_QUADS + 4 * ph), 4, dep=True)
            links = np.maximum(per_wg - 1, 0)
            self.plan.add(p, "store", "bin_batches", lead, links,
                          lambda i, s, ph=phase: D * B * 8 + (ph * self.nbs + i + s * D) * 4, 4)
            self.alu(p, lead, BIN_BATCH * (per_wg + 1))
            threads = (wg[:, None] * BIN_WORKGROUP + np.arange(BIN_WORKGROUP)).ravel()
            self.alu(p, threads, np.repeat(BIN_BATCH_LANE * (per_wg + 1), BIN_WORKGROUP), dep=False)
            if phase == 0:
                # countSmallQuadBins: the quad's AABB word, a shared atomic per bin of it
                lanes = Lanes(s_thread, s_batch, np.arange(len(self.qs)))
                self.add(p, "load", "quad_aabbs", lanes, np.arange(len(self.qs)) * 4, 4)
                self.alu(p, s_thread, BIN_QUAD + BIN_QUAD_BIN * self.nab[self.qs])
                wgs_e = (self.sq_slot // SMALL_BATCH) % D
                w_b, b_b = self._wg_bins(wgs_e, self.sq_bin)
                base = 0
            else:
                # countLargeTriBins: the AABB word, the triangle's scanline data, per bin row 2 shared atomics
                l_slot = self.qslot[l_tri // 2]
                up = self.setup_tri[l_tri]
                lanes = Lanes(l_thread, l_batch)
                self.add(p, "load", "quad_aabbs", lanes, l_slot * 4, 4)
                rows = self._tri_rows(l_tri)
                upl = Lanes(l_thread[up], l_batch[up])
                self.add(p, "load", "tri_data", upl, self.scan0 + self.tslot(l_tri[up]) * SCAN_BYTES, SCAN_BYTES,
                         dep=True)
                self.alu(p, l_thread, np.where(up, BIN_TRI + L1_SPAN_LOADS + BIN_TRI_ROW * rows, 6))
                # accumulateLargeTriCountsAcrossRows: a subgroup per bin row, a lane per 32 columns
                bx, by = self.grid.bins_x, -(-self.trace.height // BIN)
                lane = np.arange(BIN_WORKGROUP)
                work = (BIN_ROW_PREFIX * _steps(by, BIN_WORKGROUP // SUBGROUP)[lane // SUBGROUP]
                        * _steps(bx, SUBGROUP)[lane % SUBGROUP])
                active = np.flatnonzero(per_wg > 0)
                self.alu(p, (active[:, None] * BIN_WORKGROUP + lane).ravel(), np.tile(work, len(active)), dep=False)
                l_batch_e = self._large_entry_batch()
                w_b, b_b = self._wg_bins(l_batch_e % D, self.lt_bin)
                base = B * 4
            # the workgroup's counts saved for bin_dispatcher, and added to the global counts where not 0
            active = np.flatnonzero(per_wg > 0)
            self._bin_copy(p, "store", "bin_batches", active, lambda w, b=base: w * B * 8 + b, steps)
            self.alu(p, (active[:, None] * BIN_WORKGROUP + np.arange(BIN_WORKGROUP)).ravel(),
                     np.tile(BIN_COPY_STEP * steps, len(active)), dep=False)
            self._atomics(p, "bin_counts", w_b, b_b, base)
        self.each(p, "store", "lucid_info", (wg[:, None] * BIN_WORKGROUP + np.arange(2)).ravel(),
                  INFO_DISPATCHER + (np.arange(2)[None, :] * 4 * 256 + wg[:, None] * 4).ravel(), 4)

    def _atomics(self, p, structure, w_b, b_b, base, dep=False):
        """A global atomic per (workgroup, bin) pair, by the lane that takes bin ``b`` in the loop over bins."""
        thread = w_b * BIN_WORKGROUP + b_b % BIN_WORKGROUP
        lanes = Lanes(thread, b_b)
        self.add(p, "atomic_inc", structure, lanes, base + b_b * 4, 4, dep=dep)

    def _large_entry_batch(self):
        """The large batch of each large-triangle list entry (its quad's place among the large quads)."""
        return (self.qslot[self.lt_tri // 2] - len(self.qs)) // LARGE_BATCH

    def _tri_rows(self, tri):
        """Bin rows a large triangle's scanline walks (from its first to its last row with samples)."""
        out = np.zeros(len(tri), np.int64)
        if len(self.lt_tri):
            u, first = np.unique(self.lt_tri, return_index=True)
            at, found = _lookup(u, tri)
            out[found] = self.lt_rows[first[at[found]]]
        return out

    def _bin_offsets(self, p):
        """bin_categorizer.glsl: workgroup 0 prefix-sums the counts into list offsets, workgroup 1 sorts the
        bins into the low and high lists."""
        B = self.grid.bins
        steps = _steps(B, BIN_WORKGROUP)
        lane = np.arange(BIN_WORKGROUP)
        totals = (CATEGORIZE_TOTALS * (lane < max(B // SUBGROUP, 1))).astype(np.int64)
        for mode in (0, 1):
            self._bin_copy(p, "load", "bin_counts", np.array([0]), lambda w, m=mode: np.full(len(w), m * B * 4),
                           steps)
            self.alu(p, lane, 1 + (CATEGORIZE_SCAN + CATEGORIZE_OFFSET) * steps + totals)
            for k in (0, 1):
                self._bin_copy(p, "store", "bin_offsets", np.array([0]),
                               lambda w, m=mode, k=k: np.full(len(w), (2 * m + k) * B * 4), steps)
        for mode in (0, 1):
            self._bin_copy(p, "load", "bin_counts", np.array([1]), lambda w, m=mode: np.full(len(w), m * B * 4),
                           steps)
        self.alu(p, BIN_WORKGROUP + lane, 1 + CATEGORIZE_BIN * steps)
        listed = np.flatnonzero((self.level_id >= 0) | self.high)
        high = self.high[listed]
        at = np.where(high, B + self.high_id[listed], self.level_id[listed]) * 4
        self.add(p, "store", "bin_levels", Lanes(BIN_WORKGROUP + listed % BIN_WORKGROUP, listed), at, 4)
        self.each(p, "store", "lucid_info", BIN_WORKGROUP + np.arange(5), INFO_LEVEL_COUNTS + 4 * np.arange(5), 4)

    def _bin_write(self, p):
        """bin_dispatcher.glsl: each workgroup reserves its runs of the lists, then writes its batches'
        entries (a shared atomic gives each its place)."""
        B, D = self.grid.bins, self.D
        steps = _steps(B, BIN_WORKGROUP)
        self._workgroup_lanes(p, np.ones(BIN_WORKGROUP, np.int64))
        wg = np.arange(D)
        lead = wg * BIN_WORKGROUP
        self.each(p, "load", "lucid_info", (lead[:, None] + np.arange(2)).ravel(),
                  np.tile(INFO_VISIBLE_QUADS + 4 * np.arange(2), D), 4)
        self.each(p, "load", "lucid_info", (lead[:, None] + np.arange(2)).ravel(),
                  INFO_DISPATCHER + (np.arange(2)[None, :] * 4 * 256 + wg[:, None] * 4).ravel(), 4, count=1)
        s_batch, s_thread, l_batch, l_tri, l_thread = self._batches()
        lanes_all = (wg[:, None] * BIN_WORKGROUP + np.arange(BIN_WORKGROUP)).ravel()
        for phase, n_b in ((0, self.nbs), (1, self.nbl)):
            if not n_b:
                continue
            per_wg = self._wg_batches(n_b)
            active = np.flatnonzero(per_wg > 0)
            base = phase * B * 4
            # dispatchSmallQuads / dispatchLargeTris: the saved counts, an atomic per touched bin on the offsets
            self._bin_copy(p, "load", "bin_batches", active, lambda w, b=base: w * B * 8 + b, steps)
            if phase == 0:
                w_b, b_b = self._wg_bins((self.sq_slot // SMALL_BATCH) % D, self.sq_bin)
            else:
                w_b, b_b = self._wg_bins(self._large_entry_batch() % D, self.lt_bin)
            self._atomics(p, "bin_offsets", w_b, b_b, (2 * phase + 1) * B * 4, dep=True)
            self.alu(p, (active[:, None] * BIN_WORKGROUP + np.arange(BIN_WORKGROUP)).ravel(),
                     np.tile(BIN_OFFSET_STEP * steps, len(active)))
            # lane 0 follows the batch links; every lane per batch
            self.plan.add(p, "load", "bin_batches", lead, per_wg,
                          lambda i, s, ph=phase: D * B * 8 + (ph * self.nbs + i + s * D) * 4, 4, dep=True)
            self.alu(p, lead, BIN_BATCH * per_wg)
            self.alu(p, lanes_all, np.repeat(BIN_BATCH_LANE * per_wg, BIN_WORKGROUP), dep=False)
            if phase == 0:
                lanes = Lanes(s_thread, s_batch, np.arange(len(self.qs)))
                self.add(p, "load", "quad_aabbs", lanes, np.arange(len(self.qs)) * 4, 4)
                self.alu(p, s_thread, BIN_QUAD + 2 + BIN_QUAD_BIN * self.nab[self.qs])
                e = np.arange(len(self.sq_bin))
                el = Lanes(s_thread[self.sq_slot], self.sq_slot // SMALL_BATCH, self.sq_slot, e)
                addr = (self.q_first[self.sq_bin] + self.q_pos) * 4
                self.add(p, "store", "bin_quad_lists", el, addr, 4)
            else:
                self._balanced(p, l_batch, l_tri, l_thread)

    def _balanced(self, p, l_batch, l_tri, l_thread):
        """dispatchLargeTriBalanced: a subgroup's triangles walk their rows together; each row's entries
        are split evenly over the subgroup's lanes."""
        up = self.setup_tri[l_tri]
        lanes = Lanes(l_thread, l_batch)
        self.add(p, "load", "quad_aabbs", lanes, self.qslot[l_tri // 2] * 4, 4)
        upl = Lanes(l_thread[up], l_batch[up])
        self.add(p, "load", "tri_data", upl, self.scan0 + self.tslot(l_tri[up]) * SCAN_BYTES, SCAN_BYTES, dep=True)
        self.alu(p, l_thread, np.where(up, BIN_TRI + L1_SPAN_LOADS + 2, 8))
        if len(self.lt_tri) == 0:
            return
        # the subgroup (warp of a batch) of each entry's triangle, and the row loop's length per subgroup
        u, first = np.unique(l_tri, return_index=True)
        at, _ = _lookup(u, self.lt_tri)
        thread = l_thread[first[at]]
        batch = l_batch[first[at]]
        warp = (batch * (BIN_WORKGROUP // SUBGROUP)) + (thread % BIN_WORKGROUP) // SUBGROUP
        wthread0 = thread - thread % SUBGROUP
        rows = self.lt_rows
        wkey, _, winv = unique_ids(warp)
        wrows = np.zeros(len(wkey), np.int64)
        np.maximum.at(wrows, winv, rows)
        wbase = np.zeros(len(wkey), np.int64)
        wbase[winv] = wthread0
        sub = np.arange(SUBGROUP)
        self.alu(p, (wbase[:, None] + sub).ravel(), np.repeat(BIN_BALANCE_ROW * wrows, SUBGROUP))
        # per (subgroup, row): its entries in lane order, cut into 32 segments of ceil(E / 32)
        rkey = winv * (int(rows.max()) + 1) + self.lt_row
        order = lex_order(rkey, thread, self.lt_bin)
        rk = rkey[order]
        _, rfirst, rinv = unique_ids(rk)
        E = np.bincount(rinv)
        seg = -(-E // SUBGROUP)
        pos = rank_in_runs(rk)
        lane = pos // seg[rinv]
        wb = wbase[winv[order]]
        self.alu(p, (np.repeat(wbase[winv[order][rfirst]], SUBGROUP) + np.tile(sub, len(rfirst))),
                 np.repeat(BIN_BALANCE_ENTRY * seg, SUBGROUP))
        addr = (self.t_first[self.lt_bin] + self.t_pos) * 4
        el = Lanes(wb + lane, rk, pos)
        self.add(p, "store", "bin_tri_lists", el, addr[order], 4)

    # ------------------------------------------------------------------ stage 3: raster_low / raster_high
    def _raster(self, p, high: bool):
        bins = self.high_bins if high else self.low_bins
        if len(bins) == 0:
            return
        size = HIGH_WORKGROUP if high else LOW_WORKGROUP
        name = "scratch_high" if high else "scratch_low"
        scratch = HIGH_SCRATCH if high else LOW_SCRATCH
        B = self.grid.bins
        slot_of_bin = np.full(B, -1, np.int64)
        slot_of_bin[bins] = np.arange(len(bins)) % self.s.workgroups
        base_of_bin = slot_of_bin * scratch
        lanes = (bins[:, None] * HIGH_WORKGROUP + np.arange(size)).ravel()
        self.alu(p, lanes, np.full(len(lanes), RASTER_BIN_LANE), dep=False)
        # loadNextBin (lane 0): the level's counter, the bin's id, its counts and offsets
        lead = bins * HIGH_WORKGROUP
        info = INFO_HIGH_BINS if high else INFO_SMALL_BINS
        self.each(p, "atomic_inc", "lucid_info", lead, np.full(len(bins), info), 4)
        lvl = (B + self.high_id[bins]) if high else self.level_id[bins]
        self.each(p, "load", "bin_levels", lead, lvl * 4, 4, dep=True)
        cnt = np.stack([bins * 4, B * 4 + bins * 4], 1).ravel()
        self.each(p, "load", "bin_counts", lead, cnt, 4, dep=True, count=2)
        off = np.stack([bins * 4, 2 * B * 4 + bins * 4], 1).ravel()
        self.each(p, "load", "bin_offsets", lead, off, 4, dep=True, count=2)
        self.alu(p, lead, np.full(len(bins), RASTER_BIN_FETCH))
        self._process_quads(p, bins, high, name, base_of_bin)
        if high:
            self._rblocks(p, bins, name, base_of_bin)
            shaded = bins
        else:
            self._blocks(p, bins, name, base_of_bin)
            pro = bins[self.promoted[bins]]
            if len(pro):      # promoted: the bin goes to the high list
                self.each(p, "atomic_inc", "lucid_info", pro * HIGH_WORKGROUP, np.full(len(pro), INFO_LEVEL_COUNTS
                                                                                        + 16), 4, dep=True)
                self.each(p, "store", "bin_levels", pro * HIGH_WORKGROUP, (B + self.high_id[pro]) * 4, 4, dep=True)
            shaded = bins[~self.promoted[bins]]
        self._shade(p, shaded, high, name, base_of_bin)

    def _process_quads(self, p, bins, high, name, base_of_bin):
        """processQuads / generateRowTris: each listed triangle's rows (block-rows of 8 pixel rows in the low
        rasterizer, half-block rows of 4 in the high one) as tri-block-rows in the scratch buffer."""
        T = 2 * self.Q
        in_pass = np.zeros(self.grid.bins, bool)
        in_pass[bins] = True
        size = HIGH_WORKGROUP if high else LOW_WORKGROUP
        pairs_per = size // 2
        # quad entries (two lanes each) and large-triangle entries
        qe = np.flatnonzero(in_pass[self.sq_bin])
        qbin, qpos = self.sq_bin[qe], self.q_pos[qe]
        qquad = self.qs[self.sq_slot[qe]]
        i_bin = np.repeat(qbin, 2)
        i_tri = (2 * qquad[:, None] + np.arange(2)).ravel()
        i_lane = (2 * (qpos % pairs_per))[:, None].repeat(2, 1).ravel() + np.tile(np.arange(2), len(qe))
        i_seq = np.repeat(qpos // pairs_per, 2)
        i_addr = np.repeat((self.q_first[qbin] + qpos) * 4, 2)
        te = np.flatnonzero(in_pass[self.lt_bin])
        tbin, tpos = self.lt_bin[te], self.t_pos[te]
        t_lane = tpos % size if high else (size - 1) - tpos % size
        kind = np.r_[np.zeros(len(i_bin), np.int64), np.ones(len(te), np.int64)]
        i_bin = np.r_[i_bin, tbin]
        i_tri = np.r_[i_tri, self.lt_tri[te]]
        i_thread = i_bin * HIGH_WORKGROUP + np.r_[i_lane, t_lane]
        i_seq = np.r_[i_seq, tpos // size]
        entry_addr = np.r_[i_addr, (self.t_first[tbin] + tpos) * 4]
        qsel = kind == 0
        if qsel.any():
            ql = Lanes(i_thread[qsel], i_seq[qsel])
            self.add(p, "load", "bin_quad_lists", ql, entry_addr[qsel], 4)
        if (~qsel).any():
            tl = Lanes(i_thread[~qsel], i_seq[~qsel])
            self.add(p, "load", "bin_tri_lists", tl, entry_addr[~qsel], 4)
        up = self.setup_tri[np.minimum(i_tri, T - 1)] & (i_tri < T)
        upl = Lanes(i_thread[up], kind[up], i_seq[up])
        self.add(p, "load", "tri_data", upl, self.scan0 + self.tslot(i_tri[up]) * SCAN_BYTES, SCAN_BYTES, dep=True)
        # rows walked and rows covered per (bin, triangle)
        keys, cov, span, _, (reg_rank, reg_key, reg_row) = self._row_pairs(high)
        at, found = _lookup(keys, i_bin * T + i_tri)
        icov = np.where(found, cov[at], 0)
        iters = np.where(found, span[at], 1)
        step, store = (ROW_STEP_HIGH, ROW_STORE_HIGH) if high else (ROW_STEP_LOW, ROW_STORE_LOW)
        work = np.where(kind == 0, ROW_QUAD_ENTRY, ROW_TRI_ENTRY) + up * (ROW_TRI_SETUP + L1_SPAN_LOADS
                                                                          + step * iters + store * icov)
        self.alu(p, i_thread, work)
        # the stores of each covered row, by the lane that walked the triangle
        rbin, rtri, rrow = reg_key // T, reg_key % T, reg_row
        at, found = _lookup(np.sort(i_bin * T + i_tri), rbin * T + rtri)
        srt = np.argsort(i_bin * T + i_tri, kind="stable")
        ok = found & in_pass[rbin]
        who = i_thread[srt[at[ok]]]
        rowbase = base_of_bin[rbin[ok]]
        if high:
            half = HIGH_SCRATCH // 4
            o32 = rowbase + ((rrow[ok] * MAX_HBLOCK_ROW_TRIS + reg_rank[ok]) * 4) % half
            o64 = rowbase + half + ((rrow[ok] * MAX_HBLOCK_ROW_TRIS + reg_rank[ok]) * 8) % half
            sl = Lanes(who, rrow[ok])
            self.add(p, "store", name, sl, o32, 4)
            self.add(p, "store", name, sl, o64, 8)
        else:
            o = rowbase + rrow[ok] * (2 * MAX_BLOCK_ROW_TRIS * 8) + reg_rank[ok] * 8
            sl = Lanes(who, rrow[ok])
            self.add(p, "store", name, sl, o, 8)
            self.add(p, "store", name, sl, o + MAX_BLOCK_ROW_TRIS * 8, 8)
        self.row_rank = (reg_key, reg_rank, reg_row)

    def _row_pairs(self, high):
        """(bin, triangle) keys with the rows they cover, walk and start at, and per (row, triangle) pair
        its bin-triangle key, row in the bin and position in the row's list (triangle order)."""
        f, grid, T = self.f, self.grid, 2 * self.Q
        if high:       # half-block rows (4 pixel rows) from the tri-half-blocks
            hby, hbx = f.thb_region // grid.blocks_x, f.thb_region % grid.blocks_x
            region = hby * grid.bins_x + hbx // (BIN // BLOCK)
            reg, rtri = pairs(region, f.thb_tri, T)[:2]
            per_bin = BIN // HALF_BLOCK_H
        else:
            reg, rtri, per_bin = f.tbr_region, f.tbr_tri, BIN // BLOCK
        keys, cov, span, r0 = rows_in_bins(reg, rtri, grid.bins_x, per_bin, T)
        row = reg // grid.bins_x
        b = (row // per_bin) * grid.bins_x + reg % grid.bins_x
        rank = rank_in_runs(reg) if len(reg) else np.zeros(0, np.int64)
        return keys, cov, span, r0, (rank, b * T + rtri, row % per_bin)

    def _blocks(self, p, bins, name, base_of_bin):
        """raster_low.glsl generateBlocks: a subgroup per block (warp bid % 8): the block-row's tri-block-rows
        tested, its tri-blocks' depths, the sort, the two half-blocks' tri-half-blocks."""
        f, grid, T, DF = self.f, self.grid, 2 * self.Q, self.DF
        reg_key, reg_rank, reg_row = self.row_rank
        # the blocks of these bins: block-row list lengths and tri-block counts
        bpr = BIN // BLOCK
        nby = -(-self.trace.height // BLOCK)
        bxs, bys = np.meshgrid(np.arange(grid.blocks_x), np.arange(nby))
        block = (bys * grid.blocks_x + bxs).ravel()
        bbin = grid.bin_of_block(block)
        in_pass = np.zeros(grid.bins, bool)
        in_pass[bins] = True
        sel = in_pass[bbin]
        block, bbin = block[sel], bbin[sel]
        bx, by = block % grid.blocks_x % bpr, block // grid.blocks_x % bpr
        bid = bx + bpr * by
        warp, rnd = bid % (LOW_WORKGROUP // SUBGROUP), bid // (LOW_WORKGROUP // SUBGROUP)
        wthread = bbin * HIGH_WORKGROUP + warp * SUBGROUP
        tbr_reg = grid.block_row_of_block(block)
        n_rows = np.bincount(f.tbr_region, minlength=int(tbr_reg.max(initial=0)) + 1)[tbr_reg]
        tc = self.block_tris[block]
        over = tc > self.s.low_block_triangles
        sub = np.arange(SUBGROUP)
        lane_thread = (wthread[:, None] + sub).ravel()
        rows_l = np.maximum(-(-(n_rows[:, None] - sub) // SUBGROUP), 0)
        tcl = np.minimum(tc, self.s.low_block_triangles)
        hits_l = np.maximum(-(-(tcl[:, None] - sub) // SUBGROUP), 0)
        # first loop: every tri-block-row of the row, its column bits
        rowbase = base_of_bin[bbin] + by * (2 * MAX_BLOCK_ROW_TRIS * 8)
        item_b = np.repeat(np.arange(len(block)), n_rows)
        item_i = np.arange(len(item_b)) - np.repeat(np.cumsum(n_rows) - n_rows, n_rows)
        l1 = Lanes(wthread[item_b] + item_i % SUBGROUP, rnd[item_b], item_i // SUBGROUP)
        self.add(p, "load", name, l1, rowbase[item_b] + item_i * 8, 4)
        self.alu(p, lane_thread, (BLOCK_SETUP + BLOCK_ROW_TEST * rows_l + BLOCK_ROW_HIT * hits_l).ravel())
        # second loop: each tri-block's rows (mins, maxs) and its triangle's depth equation
        ok = ~over
        tb_sel = np.flatnonzero(in_pass[grid.bin_of_block(f.tb_block)])
        tb_block, tb_tri = f.tb_block[tb_sel], f.tb_tri[tb_sel]
        bpos = np.full(grid.blocks_x * nby, -1, np.int64)
        bpos[block] = np.arange(len(block))
        tbi = bpos[tb_block]
        keep = ok[tbi]
        tb_block, tb_tri, tbi, tb_sel = tb_block[keep], tb_tri[keep], tbi[keep], tb_sel[keep]
        pos = _rank_in_groups(tb_block)               # list order before the sort (triangle order)
        # each tri-block's tri-block-row: its index in the row's list
        bk = grid.bin_of_block(tb_block) * T + tb_tri
        rkey = reg_key * (BIN // BLOCK) + reg_row
        srt = np.argsort(rkey, kind="stable")
        at, found = _lookup(rkey[srt], bk * (BIN // BLOCK) + by[tbi])
        ridx = np.where(found, reg_rank[srt[np.minimum(at, max(len(srt) - 1, 0))]], 0)
        raddr = rowbase[tbi] + ridx * 8
        thr = wthread[tbi] + pos % SUBGROUP
        l2 = Lanes(thr, rnd[tbi], pos // SUBGROUP)
        self.add(p, "load", name, l2, raddr, 8, dep=True)
        self.add(p, "load", name, l2, raddr + MAX_BLOCK_ROW_TRIS * 8, 8)
        self.add(p, "load", "tri_data", l2, self.depth0 + self.tslot(tb_tri) * DEPTH_BYTES, DEPTH_BYTES, dep=True)
        self.alu(p, thr, np.full(len(thr), TRI_BLOCK_DEPTH))
        okb = np.flatnonzero(ok)
        self.alu(p, (wthread[okb][:, None] + sub).ravel(), np.full(len(okb) * SUBGROUP, BLOCK_SCAN), dep=False)
        # the sort (only past the depth filter's size: the filter orders that many itself)
        srt_b = okb[tc[okb] > DF]
        if len(srt_b):
            work = lucid_sort_work(tc[srt_b], _next_pow2(tc[srt_b], SUBGROUP), np.full(len(srt_b), SUBGROUP))
            self.alu(p, (wthread[srt_b][:, None] + sub).ravel(), np.repeat(work, SUBGROUP), dep=False)
        # third loop: in sorted order, the rows again and two tri-half-blocks stored
        rank = f.frag_rank_tb[tb_sel]
        thr3 = wthread[tbi] + rank % SUBGROUP
        l3 = Lanes(thr3, rnd[tbi], rank // SUBGROUP)
        self.add(p, "load", name, l3, raddr, 8)
        self.add(p, "load", name, l3, raddr + MAX_BLOCK_ROW_TRIS * 8, 8)
        self.alu(p, thr3, np.full(len(thr3), TRI_HALF_BLOCKS))
        hb0 = bx[tbi] + 2 * bpr * by[tbi]
        thb0 = base_of_bin[grid.bin_of_block(tb_block)] + LOW_SCRATCH // 2
        for k in (0, 1):
            self.add(p, "store", name, l3, thb0 + ((hb0 + k * bpr) * MAX_BLOCK_TRIS + rank) * 8, 8, dep=k == 0)

    def _rblocks(self, p, bins, name, base_of_bin):
        """raster_high.glsl computeRBlockGroups and generateRBlocks: per half-block, a group of 32 x 2^k
        lanes lists its tri-half-blocks from the half-block row's list, takes their depths, sorts them (every
        half-block to the bin's largest count) and stores them with their sample offsets."""
        f, grid, T = self.f, self.grid, 2 * self.Q
        reg_key, reg_rank, reg_row = self.row_rank
        in_pass = np.zeros(grid.bins, bool)
        in_pass[bins] = True
        nhb = grid.blocks_x * -(-self.trace.height // HALF_BLOCK_H)
        hb_tris = np.bincount(f.thb_region, minlength=nhb)
        hbs = np.arange(nhb)
        hbin = grid.bin_of_half_block(hbs)
        sel = in_pass[hbin]
        hbs, hbin = hbs[sel], hbin[sel]
        hby, hbx = hbs // grid.blocks_x, hbs % grid.blocks_x
        rby, rbx = hby % (BIN // HALF_BLOCK_H), hbx % (BIN // BLOCK)
        hbid = rbx + (BIN // BLOCK) * rby
        tc = hb_tris[hbs]
        bmax = np.zeros(grid.bins, np.int64)
        np.maximum.at(bmax, hbin, tc)
        gs = np.select([bmax <= 256 * 2 ** k for k in range(5)], [2 ** k for k in range(5)], 32)
        rcount = _next_pow2(bmax, SUBGROUP)
        bl = bins * HIGH_WORKGROUP
        sub32 = np.arange(SUBGROUP)
        self.alu(p, (bl[:, None] + sub32).ravel(), np.full(len(bins) * SUBGROUP, RBLOCK_GROUPS), dep=False)
        self.alu(p, bl, np.full(len(bins), RBLOCK_GROUPS_LEAD), dep=False)
        err = gs[hbin] > MAX_GROUP
        G = SUBGROUP * np.minimum(gs[hbin], MAX_GROUP)
        step = SUBGROUP * SUBGROUP // G
        it, r = hbid // step, hbid % step
        gbase = hbin * HIGH_WORKGROUP + r * G
        # the rows' list lengths
        row_len = np.zeros((grid.bins, BIN // HALF_BLOCK_H), np.int64)
        rb = reg_key // T
        np.add.at(row_len, (rb[in_pass[rb]], reg_row[in_pass[rb]]), 1)
        n_rows = row_len[hbin, rby]
        ok = ~err
        # fill: each group's lanes over the row's list (a 4-byte column mask each)
        item_h = np.repeat(np.flatnonzero(ok), n_rows[ok])
        item_i = np.arange(len(item_h)) - np.repeat(np.cumsum(n_rows[ok]) - n_rows[ok], n_rows[ok])
        quarter = HIGH_SCRATCH // 4
        row32 = base_of_bin[hbin] + ((rby * MAX_HBLOCK_ROW_TRIS) * 4) % quarter
        row64 = base_of_bin[hbin] + quarter + ((rby * MAX_HBLOCK_ROW_TRIS) * 8) % quarter
        l1 = Lanes(gbase[item_h] + item_i % G[item_h], it[item_h], item_i // G[item_h])
        self.add(p, "load", name, l1, row32[item_h] + (item_i * 4) % quarter, 4)
        gl_h = np.repeat(np.flatnonzero(ok), G[ok])
        gl_l = np.arange(len(gl_h)) - np.repeat(np.cumsum(G[ok]) - G[ok], G[ok])
        gl_thread = gbase[gl_h] + gl_l
        items = np.maximum(-(-(n_rows[gl_h] - gl_l) // G[gl_h]), 0)
        hits = np.maximum(-(-(tc[gl_h] - gl_l) // G[gl_h]), 0)
        self.alu(p, gl_thread, RBLOCK_SETUP + BLOCK_ROW_TEST * items + BLOCK_ROW_HIT * hits)
        # the tri-half-blocks: depth, the sort (all lanes of the group), counts, prefix, store
        thb_sel = np.flatnonzero(in_pass[grid.bin_of_half_block(f.thb_region)])
        hpos = np.full(nhb, -1, np.int64)
        hpos[hbs] = np.arange(len(hbs))
        th = hpos[f.thb_region[thb_sel]]
        keep = ok[th]
        thb_sel, th = thb_sel[keep], th[keep]
        ttri = f.thb_tri[thb_sel]
        pos = _rank_in_groups(f.thb_region[thb_sel])
        rk = reg_key * (BIN // HALF_BLOCK_H) + reg_row
        srt = np.argsort(rk, kind="stable")
        at, found = _lookup(rk[srt], (hbin[th] * T + ttri) * (BIN // HALF_BLOCK_H) + rby[th])
        ridx = np.where(found, reg_rank[srt[np.minimum(at, max(len(srt) - 1, 0))]], 0)
        raddr = row64[th] + (ridx * 8) % quarter
        thr = gbase[th] + pos % G[th]
        ln = Lanes(thr, it[th], pos // G[th])
        self.add(p, "load", name, ln, raddr, 8, dep=True)
        self.add(p, "load", "tri_data", ln, self.depth0 + self.tslot(ttri) * DEPTH_BYTES, DEPTH_BYTES, dep=True)
        self.alu(p, thr, np.full(len(thr), RBLOCK_DEPTH))
        sort = lucid_sort_work(tc[gl_h], rcount[hbin[gl_h]], G[gl_h])
        self.alu(p, gl_thread, sort, dep=False)
        rank = f.thb_rank[thb_sel]
        thr2 = gbase[th] + rank % G[th]
        l2 = Lanes(thr2, it[th], rank // G[th])
        self.add(p, "load", name, l2, raddr, 8)
        self.alu(p, thr2, np.full(len(thr2), RBLOCK_COUNT))
        pre = np.repeat(bins * HIGH_WORKGROUP, 2 * SUBGROUP) + np.tile(np.arange(2 * SUBGROUP), len(bins))
        self.alu(p, pre, np.repeat(RBLOCK_PREFIX * np.minimum(gs[bins], MAX_GROUP), 2 * SUBGROUP), dep=False)
        self.add(p, "load", name, l2, raddr, 8)
        self.alu(p, thr2, np.full(len(thr2), RBLOCK_STORE))
        dst = base_of_bin[hbin[th]] + 2 * quarter + ((hbid[th] * MAX_HBLOCK_TRIS + rank) * 8) % (2 * quarter)
        self.add(p, "store", name, l2, dst, 8)

    def _shade(self, p, bins, high, name, base_of_bin):
        """Phase 3 (raster.glsl unpackSamples, shadeAndReduceSamples, shading.glsl shadeSample, reduceSample,
        finishReduceSamples, outputPixel): a subgroup per half-block (low: half-blocks w, w + 8, w + 16,
        w + 24 on warp w; high: half-block w on warp w), segments of 256 samples, 32 at a time."""
        f, grid, trace, DF = self.f, self.grid, self.trace, self.DF
        if len(bins) == 0:
            return
        in_pass = np.zeros(grid.bins, bool)
        in_pass[bins] = True
        nhb = grid.blocks_x * -(-trace.height // HALF_BLOCK_H)
        hbs = np.arange(nhb)
        hbin = grid.bin_of_half_block(hbs)
        hbs = hbs[in_pass[hbin]]
        hbin = grid.bin_of_half_block(hbs)
        hby, hbx = hbs // grid.blocks_x, hbs % grid.blocks_x
        hbid = hbx % (BIN // BLOCK) + (BIN // BLOCK) * (hby % (BIN // HALF_BLOCK_H))
        warps = (HIGH_WORKGROUP if high else LOW_WORKGROUP) // SUBGROUP
        warp, rnd = hbid % warps, hbid // warps
        wthread = hbin * HIGH_WORKGROUP + warp * SUBGROUP
        hpos = np.full(nhb, -1, np.int64)
        hpos[hbs] = np.arange(len(hbs))
        # samples of these half-blocks, kept (not skipped by the alpha threshold), in processing order
        smp = np.flatnonzero(in_pass[grid.bin_of_half_block(f.half_block)] & ~f.skipped)
        h = hpos[f.half_block[smp]]
        order = lex_order(h, f.frag_rank[smp], -trace.y[smp].astype(np.int64), trace.x[smp])
        smp, h = smp[order], h[order]
        pos = rank_in_runs(h) if len(h) else np.zeros(0, np.int64)
        kept = np.bincount(h, minlength=len(hbs))
        total = np.bincount(hpos[f.half_block[in_pass[grid.bin_of_half_block(f.half_block)]]],
                            minlength=len(hbs))
        segs = -(-kept // SEGMENT)
        chunks = -(-kept // SUBGROUP)
        pixel = (trace.x[smp] % BLOCK) + BLOCK * (trace.y[smp] % HALF_BLOCK_H)
        chunk = pos // SUBGROUP
        # per (half-block, chunk): the most samples of one pixel (reduceSample's loop) and their insertions
        cstart = np.cumsum(chunks) - chunks
        ck = (cstart[h] + chunk) * SUBGROUP + pixel
        nck = int(chunks.sum())
        per_pix = np.bincount(ck, minlength=nck * SUBGROUP).reshape(nck, SUBGROUP)
        swaps = np.bincount(ck, weights=self._swaps(smp), minlength=nck * SUBGROUP).reshape(nck, SUBGROUP)
        c_iter = per_pix.max(axis=1)
        c_swap = swaps.max(axis=1).astype(np.int64)
        c_h = np.repeat(np.arange(len(hbs)), chunks)
        step = reduce_step(DF, self.s.alpha_threshold)
        reduce = np.bincount(c_h, weights=(SHADE_STEP + SHADE_SAMPLE + L1_SPAN_LOADS + step * c_iter
                                           + REDUCE_SWAP * c_swap),
                             minlength=len(hbs))
        pix_count = np.bincount(h * SUBGROUP + pixel, minlength=len(hbs) * SUBGROUP).reshape(-1, SUBGROUP)
        filled = pix_count.max(axis=1)
        unpack, u_thread, u_addr, u_key = self._unpack(p, hbs, hpos, kept, total, high, base_of_bin, wthread)
        work = (HALF_BLOCK_START + 2 * DF + segs * (UNPACK_SEGMENT + (REDUCE_THRESHOLD if self.s.alpha_threshold
                                                                          else 0))
                + unpack + reduce + finish_work(DF, filled))
        sub = np.arange(SUBGROUP)
        lanes = (wthread[:, None] + sub).ravel()
        # the unpack loads of the tri-half-blocks, then per sample the triangle's data
        if len(u_thread):
            ul = Lanes(u_thread, *u_key)
            self.add(p, "load", name, ul, u_addr, 8)
        tri = f.tri[smp]
        slot = self.tslot(tri)
        sl = Lanes(wthread[h] + pos % SUBGROUP, rnd[h], chunk)
        self.add(p, "load", "tri_data", sl, self.depth0 + slot * DEPTH_BYTES, DEPTH_BYTES, dep=True)
        self.add(p, "load", "tri_data", sl, self.bary0 + slot * BARY_BYTES, BARY_BYTES)
        self.add(p, "load", "instances", sl, self.colour0 + (tri // 2 // SETUP_CHUNK) * 4, 4)
        self.add(p, "load", "tri_data", sl, self.normal0 + slot * NORMAL_BYTES, NORMAL_BYTES)
        self.alu(p, lanes, np.repeat(np.rint(work).astype(np.int64), SUBGROUP))
        # outputPixel: every on-screen pixel of the half-block
        px = (hbx * BLOCK)[:, None] + sub % BLOCK
        py = (hby * HALF_BLOCK_H)[:, None] + sub // BLOCK
        on = (px < trace.width) & (py < trace.height)
        fl = Lanes(lanes[on.ravel()], np.repeat(rnd, SUBGROUP)[on.ravel()])
        self.add(p, "store", "framebuffer", fl, (py * trace.width + px)[on] * 4, 4)
        # updateStats
        stat = (np.arange(SUBGROUP) if high else np.arange(LOW_WORKGROUP - SUBGROUP, LOW_WORKGROUP))
        self.alu(p, (bins[:, None] * HIGH_WORKGROUP + stat).ravel(), np.full(len(bins) * SUBGROUP, RASTER_STATS),
                 dep=False)

    def _swaps(self, smp):
        """Per sample, the filter entries it moves past in reduceSample: among the previous ``depth_filter``
        arrivals at its pixel those farther than it. Arrival order is the sorted order, or the list
        (triangle) order in a low-rasterizer block of at most ``depth_filter`` tri-blocks (not sorted)."""
        f, DF = self.f, self.DF
        n = len(self.trace)
        out = np.zeros(n, np.float64)
        if len(smp) == 0:
            return out[smp]
        pix = self.g.pix[smp]
        block = self.grid.block_of_half_block(f.half_block[smp])
        unsorted = self.block_tris[block] <= DF
        akey = np.where(unsorted, f.tri[smp], f.frag_rank[smp])
        o = lex_order(pix, akey)
        pp, z = pix[o], self.trace.z[smp][o]
        sw = np.zeros(len(o), np.float64)
        depth = int(np.bincount(pp).max(initial=1))
        for j in range(1, min(DF, depth - 1) + 1):
            sw[j:] += (pp[j:] == pp[:-j]) & (z[:-j] > z[j:])
        res = np.empty(len(o), np.float64)
        res[o] = sw
        return res

    def _unpack(self, p, hbs, hpos, kept, total, high, base_of_bin, wthread):
        """unpackSamples per half-block: its tri-half-block list (low: the block's tri-blocks, each with the
        half's samples; high: its own) walked segment by segment; returns each half-block's instructions, and
        the list loads (thread, address, order keys)."""
        f, grid = self.f, self.grid
        # samples per (half-block, triangle) and the most in one of its 4 rows
        thb_s = np.bincount(f.thb_of, minlength=len(f.thb_tri))
        row = self.trace.y % HALF_BLOCK_H
        thb_row = np.bincount(f.thb_of * HALF_BLOCK_H + row, minlength=len(f.thb_tri) * HALF_BLOCK_H)
        thb_rowmax = thb_row.reshape(-1, HALF_BLOCK_H).max(axis=1)
        if high:
            e_hb = f.thb_region
            e_s, e_rm = thb_s, thb_rowmax
            e_rank = f.thb_rank
        else:
            # every tri-block of the block for each of its two half-blocks
            tb = np.arange(len(f.tb_block))
            blk = f.tb_block
            top = (blk // grid.blocks_x) * 2 * grid.blocks_x + blk % grid.blocks_x   # the block's first half
            e_hb = np.r_[top, top + grid.blocks_x]
            e_s = np.zeros(2 * len(tb), np.int64)
            e_rm = np.zeros(2 * len(tb), np.int64)
            half = (f.thb_region // grid.blocks_x) % 2
            idx = f.thb_to_tb + half * len(tb)
            e_s[idx] = thb_s
            e_rm[idx] = thb_rowmax
            e_rank = np.r_[f.frag_rank_tb, f.frag_rank_tb]
        sel = hpos[np.minimum(e_hb, len(hpos) - 1)] >= 0
        sel &= e_hb < len(hpos)
        e_h = hpos[e_hb[sel]]
        e_s, e_rm, e_rank = e_s[sel], e_rm[sel], e_rank[sel]
        o = lex_order(e_h, e_rank)
        e_h, e_s, e_rm, e_rank = e_h[o], e_s[o], e_rm[o], e_rank[o]
        i = rank_in_runs(e_h) if len(e_h) else np.zeros(0, np.int64)
        csum = np.cumsum(e_s) - e_s
        first = np.zeros(len(hbs), np.int64)
        if len(e_h):
            starts = np.flatnonzero(np.r_[True, e_h[1:] != e_h[:-1]])
            first[e_h[starts]] = csum[starts]
        off = csum - first[e_h]
        seg = off >> 8
        nseg = -(-kept // SEGMENT)
        live = seg < nseg[e_h]
        e_h, e_s, e_rm, i, seg = e_h[live], e_s[live], e_rm[live], i[live], seg[live]
        listed = self.block_tris[grid.block_of_half_block(hbs)] if not high else np.bincount(
            f.thb_region, minlength=int(hbs.max(initial=0)) + 1)[hbs]
        dense = (total < listed * 8) & (listed >= 16)
        per_it = np.where(dense, SUBGROUP, SUBGROUP // HALF_BLOCK_H)[e_h]
        # iterations: position in its segment's run of the list, per_it at a time
        sk = e_h * (int(seg.max(initial=0)) + 1) + seg
        sfirst = np.zeros(0, np.int64)
        if len(sk):
            st = np.flatnonzero(np.r_[True, sk[1:] != sk[:-1]])
            sfirst = np.repeat(i[st], np.diff(np.r_[st, len(sk)]))
        it = (i - sfirst) // per_it
        span = int(it.max(initial=0)) + 1
        ik = sk * span + it
        u, ufirst, inv = unique_ids(ik) if len(ik) else (ik, ik, ik)
        imax = np.zeros(len(u), np.int64)
        d = dense[e_h]
        np.maximum.at(imax, inv, np.where(d, e_s, e_rm))
        ih = e_h[ufirst]
        id_ = dense[ih]
        icost = np.where(id_, UNPACK_BITS + UNPACK_BIT_SAMPLE * imax, UNPACK_ROWS + UNPACK_ROW_SAMPLE * imax)
        cost = np.bincount(ih, weights=icost, minlength=len(hbs))
        # the loads: one lane per entry (bit path) or its 4 row lanes (row path)
        rows = np.where(d, 1, HALF_BLOCK_H)
        lh = np.repeat(e_h, rows)
        li = np.repeat(i, rows)
        ly = np.arange(len(lh)) - np.repeat(np.cumsum(rows) - rows, rows)
        dd = np.repeat(d, rows)
        lane = np.where(dd, li % SUBGROUP, HALF_BLOCK_H * (li % (SUBGROUP // HALF_BLOCK_H)) + ly)
        hbid = self._hbid(hbs[lh])
        hb_bin = grid.bin_of_half_block(hbs[lh])
        if high:
            quarter = HIGH_SCRATCH // 4
            addr = base_of_bin[hb_bin] + 2 * quarter + ((hbid * MAX_HBLOCK_TRIS + li) * 8) % (2 * quarter)
        else:
            addr = base_of_bin[hb_bin] + LOW_SCRATCH // 2 + (hbid * MAX_BLOCK_TRIS + li) * 8
        warps = (HIGH_WORKGROUP if high else LOW_WORKGROUP) // SUBGROUP
        rnd = hbid // warps
        seq = np.where(dd, li // SUBGROUP, li // (SUBGROUP // HALF_BLOCK_H))
        return cost, wthread[lh] + lane, addr, (rnd, seq)

    def _hbid(self, hb):
        grid = self.grid
        hby, hbx = hb // grid.blocks_x, hb % grid.blocks_x
        return hbx % (BIN // BLOCK) + (BIN // BLOCK) * (hby % (BIN // HALF_BLOCK_H))
