"""LucidRaster (seed 002 section 2, stage 3): two-stage sort, depth filter, invalid pixels, bins."""

from __future__ import annotations

import numpy as np
import pytest
from conftest import make_trace

from gpusim.metrics import composite_exact, image_error
from gpusim.scene import load_scene, trace_scene
from gpusim.schemes import make_scheme


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
    tris = len(np.unique(random_trace.prim))
    assert fp["tri_data"] == 84 * tris and fp["framebuffer"] == 4 * random_trace.pixel_count
    assert fp["bin_tri_lists"] == 4 * tris          # 16x12 screen: one bin, every triangle listed once
    assert fp["scratch_high"] == 4 * 768 * 1024
    # binning counts in shared memory: one global atomic per (batch of 2,048 triangles, bin) on the counter, and
    # one on the offsets to reserve the batch's run of the list
    batches = len(np.unique(np.unique(random_trace.prim) // 2048))
    assert res.accesses["bin_counts"]["atomic_inc"] == batches
    assert res.accesses["bin_offsets"]["atomic_inc"] == batches


@pytest.mark.parametrize("df", [0, 5000])
def test_depth_filter_bounds(df):
    from gpusim.errors import ConfigError
    with pytest.raises(ConfigError, match="depth_filter"):
        make_scheme("lucidraster", {"depth_filter": df})
