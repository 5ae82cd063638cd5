"""LucidRaster (seed 002 section 2, stage 3): two-stage sort, depth filter, invalid pixels, bins."""

from __future__ import annotations

import numpy as np
import pytest
from conftest import make_trace

from gpusim.metrics import composite_exact, image_error
from gpusim.scene import load_scene, trace_scene
from gpusim.schemes import make_scheme
from gpusim.schemes.common import alu


def run(trace, **params):
    return make_scheme("lucidraster", params).run(trace)


def test_a_sample_nearer_than_one_blended_makes_the_pixel_invalid():
    # one 8x8 block; centroid depths: prim 0 -> 0.3, prim 1 -> 0.4, prim 2 -> 0.475 (sorted in that order),
    # but at pixel (0, 0) prim 2 is the nearest: arrivals 0.5, 0.6, 0.05
    xs, zs, prims = [0, 1, 0, 1, 0, 2], [0.5, 0.1, 0.6, 0.2, 0.05, 0.9], [0, 0, 1, 1, 2, 2]
    rgba = np.array([[1, 0, 0, .5], [1, 0, 0, .5], [0, 1, 0, .5], [0, 1, 0, .5], [0, 0, 1, .5], [0, 0, 1, .5]])
    t = make_trace(xs, [0] * 6, zs, rgba=rgba, prim=prims, width=8, height=8)
    ref = composite_exact(t)
    df1 = run(t, depth_filter=1)           # 0.5 leaves first, then 0.05: out of order
    assert df1.stats["invalid_pixels"].value == 1 and df1.stats["invalid_samples"].value == 1
    assert df1.lists.of_pixel(0).tolist() == [0, 4, 2]
    assert image_error(df1.image, ref)["max_abs"] > 0.05
    df2 = run(t, depth_filter=2)           # room for two: the filter repairs it
    assert df2.stats["invalid_pixels"].value == 0
    assert image_error(df2.image, ref)["max_abs"] < 1e-6


def test_depth_filter_as_large_as_the_depth_complexity_is_exact(random_trace):
    dc = int(random_trace.depth_complexity().max())
    res = run(random_trace, depth_filter=dc)
    assert res.stats["invalid_pixels"].value == 0
    err = image_error(res.image, composite_exact(random_trace))
    assert err["differing_pixels"] == 0 and err["max_abs"] < 1e-5


def test_invalid_pixels_fall_as_the_depth_filter_grows():
    scene, base = load_scene("foliage", ["screen.width=192", "screen.height=192"])
    trace = trace_scene(scene, base, progress=False)
    ref = composite_exact(trace)
    invalid, rmse = [], []
    for df in (1, 3, 8, 12):
        res = run(trace, depth_filter=df)
        invalid.append(res.stats["invalid_pixels"].value)
        rmse.append(image_error(res.image, ref)["rmse"])
    assert invalid[0] > invalid[1] > 0 and invalid[1] > invalid[2] >= invalid[3], invalid
    assert rmse[0] > rmse[1] > rmse[2] >= rmse[3] * 0.999, rmse


def test_equal_22_bit_keys_keep_submission_order():
    # two triangles over the same pixels, depths equal in their top 22 bits: prim 0 (submitted first) leads
    z0, z1 = np.float32(0.5), np.nextafter(np.float32(0.5), np.float32(0))   # differ in the last bit only
    t = make_trace([0, 0], [0, 0], [z0, z1], prim=[0, 1], width=8, height=8)
    res = run(t, depth_filter=1)
    # arrival is prim 0 then prim 1; the filter still emits the nearer one (prim 1) first
    assert res.lists.of_pixel(0).tolist() == [1, 0] and res.stats["invalid_pixels"].value == 0


def test_alpha_threshold_stops_a_saturated_half_block():
    layers, rng = 300, np.random.default_rng(5)
    x, y = np.meshgrid(np.arange(8), np.arange(4))
    xs, ys = np.tile(x.ravel(), layers), np.tile(y.ravel(), layers)
    depth = rng.permutation(layers) / layers
    zs = np.repeat(depth, 32)
    prims = np.repeat(np.arange(layers), 32)
    rgba = np.c_[rng.random((32 * layers, 3)), np.full(32 * layers, 0.5)]
    t = make_trace(xs, ys, zs, rgba=rgba, prim=prims, width=8, height=8)
    ref = composite_exact(t)
    off, on = run(t), run(t, alpha_threshold=True)
    assert off.stats["skipped_samples"].value == 0
    # alpha 0.5: transmittance <= 1/128 after 7 blends; with DF = 3 the 7th leaves the filter when the
    # 10th layer arrives (half-block positions 288..319), so shading stops after the 2nd 256-sample segment
    assert on.stats["skipped_samples"].value == on.dropped_fragments == 32 * layers - 512
    assert on.overflowed_pixels == 32                 # every pixel of the half-block lost the skipped samples
    assert image_error(on.image, ref)["max_abs"] <= 1 / 128 + 1e-6
    # a pixel of the half-block that never saturates (no samples) keeps the whole half-block shading
    holed = t.subset(~((t.x == 7) & (t.y == 3)))
    assert run(holed, alpha_threshold=True).stats["skipped_samples"].value == 0


def test_bins_are_classified_by_triangle_density():
    n = 1100                                   # 1100 one-sample triangles in bin 0: a high bin
    rng = np.random.default_rng(2)
    t = make_trace(rng.integers(0, 32, n), rng.integers(0, 32, n), rng.random(n), width=64, height=32)
    res = run(t)
    assert res.stats["bins"].value == {"empty": 1, "low": 0, "high": 1, "promoted": 0}
    assert "scratch_high" in res.footprint and "scratch_low" not in res.footprint
    crowded = make_trace(rng.integers(0, 8, 300), rng.integers(0, 8, 300), rng.random(300), width=64, height=32)
    res = run(crowded)                         # 300 triangles in one 8x8 block: over the low limit of 256
    assert res.stats["bins"].value["promoted"] == 1 and res.stats["max_block_triangles"].value == 300
    assert run(crowded, low_block_triangles=512).stats["bins"].value["low"] == 1


def test_footprint_structures_and_counts(random_trace):
    res = run(random_trace, workgroups=4)
    fp = res.footprint
    tris = len(np.unique(random_trace.prim))        # 5,000 one-sample triangles: 2,500 visible quads
    assert fp["tri_data"] == 84 * tris and fp["framebuffer"] == 4 * random_trace.pixel_count
    assert fp["indices"] == 16 * tris // 2 and fp["quad_aabbs"] == 4 * tris // 2
    # 16x12 screen: one bin, every quad small and listed once; 5,000 triangles make it a high bin
    assert fp["bin_quad_lists"] == 4 * tris // 2 and fp["bin_tri_lists"] == 0
    assert fp["scratch_high"] == 4 * 768 * 1024 and "scratch_low" not in fp
    # binning counts in shared memory: one global atomic per (workgroup, bin touched) on the counts, and one
    # on the offsets to reserve the workgroup's run of the list (one batch of 4,096 quads: one workgroup)
    assert res.accesses["bin_counts"]["atomic_inc"] == 1
    assert res.accesses["bin_offsets"]["atomic_inc"] == 1


def _computes(res, p):
    """The ALU groups of pass ``p``: {thread: instructions} each."""
    out = []
    for g in res.plan.groups:
        if g.is_compute and g.pass_index == p:
            out.append(dict(zip(g.thread_ids().tolist(), np.asarray(g.instructions).tolist())))
    return out


def _has(groups, lanes, value) -> bool:
    """Whether some ALU group gives each of ``lanes`` ``value`` instructions."""
    return any(all(g.get(lane) == value for lane in lanes) for g in groups)


def _ops(res, p, structure, op):
    return sum(g.total for g in res.plan.memory_groups if g.pass_index == p and g.structure == structure
               and g.op == op)


@pytest.mark.parametrize("cull", [False, True])
def test_setup_runs_every_input_quad_and_stores_its_set_up_triangles(cull):
    # 4 triangles submitted (2 quads); only triangle 0 has samples: quad 0 visible, quad 1 culled
    meta = {"primitives": 4} | ({"scene_config": {"raster": {"cull": "back"}}} if cull else {})
    t = make_trace([0, 1], [0, 0], [0.5, 0.5], prim=[0, 0], meta=meta)
    res = run(t)
    back = alu.SETUP_BACKFACE if cull else 0
    spans = alu.L1_SPAN_LOADS * (3 + 4 * 2)        # 4 index loads and 4 x 3 vertex loads, as 1 + 4 spans
    visible = (alu.SETUP_QUAD_INPUT + back + alu.SETUP_PROJECT + alu.SETUP_AABB + alu.SETUP_COMPACT + spans)
    culled = alu.SETUP_QUAD_INPUT + (alu.SETUP_BACKFACE if cull else alu.SETUP_PROJECT) + alu.SHARED_ATOMIC + spans
    assert {0: visible, 1: culled} in _computes(res, 0)
    assert _ops(res, 0, "indices", "load") == 2 and _ops(res, 0, "vertices", "load") == 2 * 4 + 3 * (1 + (not cull))
    # storeTri: normal, depth equation, 2 x barycentric, 2 x scanline; without culling both triangles of a
    # visible quad are set up, with it the one without samples carries the quad's culling flag
    assert _ops(res, 0, "tri_data", "store") == 6 * (1 if cull else 2)
    # the triangle loop: the quad's two triangles on lanes 0 and 1
    tri = alu.SETUP_TRI_ENTRY + alu.SETUP_TRI + alu.L1_SPAN_LOADS * 6
    assert {0: tri, 1: alu.SETUP_TRI_ENTRY if cull else tri} in _computes(res, 0)


def test_binning_lists_small_quads_by_aabb_and_large_triangles_by_rows():
    # a quad with samples in bins 0 and 1: a small quad, listed in both, a shared atomic per bin when counting
    small = make_trace([30, 33], [3, 3], [0.5, 0.5], prim=[0, 0], width=64, height=32)
    res = run(small)
    assert _ops(res, 3, "bin_quad_lists", "store") == 2 and _ops(res, 4, "bin_quad_lists", "load") == 2 * 2
    assert {0: alu.BIN_QUAD + 2 * alu.BIN_QUAD_BIN} in _computes(res, 1)
    assert {0: alu.BIN_QUAD + 2 + 2 * alu.BIN_QUAD_BIN} in _computes(res, 3)
    # a triangle over 3 x 2 bins: a large quad; its triangle listed in the 3 bins of each of its 2 rows
    large = make_trace([5, 70, 5, 70], [5, 5, 40, 40], [0.5] * 4, prim=[0] * 4, width=256, height=64)
    res = run(large)
    assert _ops(res, 3, "bin_tri_lists", "store") == 6 and _ops(res, 4, "bin_tri_lists", "load") == 6
    assert "bin_quad_lists" not in res.accesses
    rows = alu.BIN_TRI + alu.L1_SPAN_LOADS + 2 * alu.BIN_TRI_ROW
    assert {0: rows, 1: 6} in _computes(res, 1)    # lane 1: the quad's second triangle, culled (no samples)


def _stack(n=6):
    """One 8x8 block: n triangles over all 64 pixels, submitted back to front (triangle 0 the farthest)."""
    x, y = np.meshgrid(np.arange(8), np.arange(8))
    xs, ys = np.tile(x.ravel(), n), np.tile(y.ravel(), n)
    zs = np.repeat(np.linspace(0.9, 0.1, n), 64)
    return make_trace(xs, ys, zs, prim=np.repeat(np.arange(n), 64))


def test_a_block_is_sorted_only_past_the_depth_filter_and_every_sample_is_shaded():
    t, sort = _stack(), alu.lucid_sort_work(np.array([6]), np.array([32]), np.array([32]))[0]
    assert sort == 2 + 12 + 44 + 25        # padding, direction bits, stages K = 2..16, merge K = 32
    df3, df8 = run(t), run(t, depth_filter=8)
    assert _has(_computes(df3, 4), range(32), sort) and not _has(_computes(df8, 4), range(32), sort)
    for res in (df3, df8):
        # per sample its triangle's depth equation, barycentric edges, normal and instance colour; every pixel out
        # (+ generateRowTris' scanline data and generateBlocks' depth equation, per triangle)
        assert _ops(res, 4, "instances", "load") == 6 * 64 and _ops(res, 4, "tri_data", "load") == 3 * 6 * 64 + 2 * 6
        assert _ops(res, 4, "framebuffer", "store") == 64
    # phase 3 on warps 0 and 4 (the half-blocks: 6 tri-half-blocks of 32 samples, one segment, one unpack iteration
    # of its 8-lane groups, 6 steps of 32 samples, each pixel's sample through reduceSample once)
    unpack = alu.UNPACK_SEGMENT + alu.UNPACK_ROWS + alu.UNPACK_ROW_SAMPLE * 8
    step = alu.SHADE_STEP + alu.SHADE_SAMPLE + alu.L1_SPAN_LOADS
    sorted_ = alu.HALF_BLOCK_START + 2 * 3 + unpack + 6 * (step + alu.reduce_step(3)) + alu.finish_work(3, 6)
    # DF = 8: not sorted, the samples arrive back to front: the k-th moves past the k before it
    unsorted = (alu.HALF_BLOCK_START + 2 * 8 + unpack + 6 * (step + alu.reduce_step(8))
                + alu.REDUCE_SWAP * sum(range(6)) + alu.finish_work(8, 6))
    halves = [*range(32), *range(128, 160)]
    assert _has(_computes(df3, 4), halves, sorted_) and _has(_computes(df8, 4), halves, unsorted)


def test_the_high_rasterizer_sorts_every_half_block_to_the_largest():
    # the same block as a high bin: each of its two half-blocks (warps 0 and 4) sorts its 6 tri-half-blocks on a
    # group of 32 lanes, whatever the depth filter
    res = run(_stack(), high_bin_triangles=1, depth_filter=8)
    sort = alu.lucid_sort_work(np.array([6]), np.array([32]), np.array([32]))[0]
    assert _has(_computes(res, 5), [*range(32), *range(128, 160)], sort)
    assert _ops(res, 5, "framebuffer", "store") == 64 and _ops(res, 4, "framebuffer", "store") == 0
    # a half-block group of 2^k subgroups past 256 tri-half-blocks: 300 keys in 512 slots on 64 lanes
    assert alu.lucid_sort_work(np.array([300]), np.array([512]), np.array([64]))[0] == (
        2 * 4 + 12 + 8 * (4 + 4 * 15) + 4 * 8 * 25 + (1 + 2 + 3 + 4) * 4 * 14)


def test_the_alpha_threshold_skips_the_shading_of_skipped_samples():
    layers, rng = 300, np.random.default_rng(5)
    x, y = np.meshgrid(np.arange(8), np.arange(4))
    xs, ys = np.tile(x.ravel(), layers), np.tile(y.ravel(), layers)
    zs = np.repeat(rng.permutation(layers) / layers, 32)
    rgba = np.c_[rng.random((32 * layers, 3)), np.full(32 * layers, 0.5)]
    t = make_trace(xs, ys, zs, rgba=rgba, prim=np.repeat(np.arange(layers), 32), width=8, height=8)
    low = {"high_bin_triangles": 4096, "low_block_triangles": 512}      # shaded by the low rasterizer
    off, on = run(t, **low), run(t, alpha_threshold=True, **low)
    assert _ops(off, 4, "instances", "load") == 32 * layers
    assert _ops(on, 4, "instances", "load") == 32 * layers - on.stats["skipped_samples"].value == 512


@pytest.mark.parametrize("df", [0, 5000])
def test_depth_filter_bounds(df):
    from gpusim.errors import ConfigError
    with pytest.raises(ConfigError, match="depth_filter"):
        make_scheme("lucidraster", {"depth_filter": df})
