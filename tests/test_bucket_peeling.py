"""Bucket depth peeling (uniform and adaptive) and the multi-pass k-buffer: hand-computed cases against the
exact reference, footprints as seed 000 Table 3 counts them, and the timing levels."""

from __future__ import annotations

import numpy as np
import pytest
from conftest import make_trace

from gpusim.hw import load_gpu
from gpusim.hw.hazards import count_hazards
from gpusim.metrics import composite_exact, image_error
from gpusim.opplan import OPS
from gpusim.replay import replay
from gpusim.schemes import make_scheme
from gpusim.schemes.bucket import bucket_of
from gpusim.trace import FragmentTrace

MIB = 2 ** 20
RGBA = [[1, 0, 0, 0.5], [0, 1, 0, 0.5], [0, 0, 1, 0.5], [1, 1, 0, 0.5], [0, 1, 1, 0.5]]


def run(name, trace, **params):
    return make_scheme(name, params).run(trace)


def one_pixel(zs, rgba=None):
    n = len(zs)
    rgba = (RGBA * n)[:n] if rgba is None else rgba
    return make_trace(np.zeros(n, int), np.zeros(n, int), zs, rgba, width=1, height=1)


def composite_of(trace, keep):
    """The exact composite of the fragments ``keep`` of ``trace`` only."""
    keep = np.asarray(keep)
    return composite_exact(make_trace(trace.x[keep], trace.y[keep], trace.z[keep], trace.rgba[keep],
                                      trace.opaque[keep], width=trace.width, height=trace.height))


def assert_exact(result, trace):
    err = image_error(result.image, composite_exact(trace))
    assert err["differing_pixels"] == 0 and err["max_abs"] < 1e-6, err


# ---------------------------------------------------------------------- buckets
def test_bucket_of_the_range_ends_and_a_single_depth():
    near, far = np.float32(0.25), np.float32(0.75)
    z = np.array([0.25, np.nextafter(np.float32(0.25), np.float32(1)), 0.5, np.nextafter(np.float32(0.75),
                  np.float32(0)), 0.75], np.float32)
    assert bucket_of(z, np.full(5, near), np.full(5, far), 32).tolist() == [0, 0, 16, 31, 31]
    assert bucket_of(z, np.full(5, near), np.full(5, far), 64).tolist() == [0, 0, 32, 63, 63]
    # a pixel of one distinct depth: everything in bucket 0
    same = np.full(3, 0.4, np.float32)
    assert bucket_of(same, same, same, 32).tolist() == [0, 0, 0]


def test_collisions_keep_the_farthest_of_a_bucket_and_are_counted():
    # range [0, 1]: buckets floor(32 z) = 0, 0, 0, 31; bucket 0 keeps its farthest, 0.02
    t = one_pixel([0.01, 0.02, 0.0, 1.0])
    res = run("bucket-depth-peeling", t)
    assert res.stats["bucket_collisions"].value == res.dropped_fragments == 2
    assert res.overflowed_pixels == 1
    assert res.lists.fragment.tolist() == [1, 3]
    assert np.allclose(res.image[0, 0], composite_of(t, [1, 3])[0, 0], atol=1e-6)
    assert image_error(res.image, composite_exact(t))["max_abs"] > 0.05      # the image shows the loss
    # a depth of 0 is kept like any other (the buckets are cleared below every depth)
    assert run("bucket-depth-peeling", one_pixel([0.0, 1.0])).dropped_fragments == 0


def test_equal_depths_share_a_bucket_and_the_first_submitted_colour_shows():
    t = one_pixel([0.5, 0.5, 0.5], [[1, 0, 0, 0.5], [0, 1, 0, 0.5], [0, 0, 1, 0.5]])
    res = run("bucket-depth-peeling", t)
    assert res.dropped_fragments == 2 and res.lists.fragment.tolist() == [0]
    assert np.allclose(res.image[0, 0], composite_of(t, [0])[0, 0])


def test_exact_when_every_fragment_has_a_bucket_of_its_own():
    # 32 evenly spaced depths in [0, 1]: bucket i for the i-th; shuffled submission
    zs = (np.arange(32) / np.float32(31)).astype(np.float32)
    order = np.random.default_rng(1).permutation(32)
    rng = np.random.default_rng(2)
    t = make_trace(np.zeros(32, int), np.zeros(32, int), zs[order], rng.random((32, 4)), width=1, height=1)
    res = run("bucket-depth-peeling", t)
    assert res.dropped_fragments == 0
    assert_exact(res, t)
    # a screen of pixels with at most two distinct depths: their near and far, buckets 0 and 31
    n = 300
    rng = np.random.default_rng(3)
    xy = rng.permutation(24 * 16 * 2)[:n] % (24 * 16)
    t = make_trace(xy % 24, xy // 24, rng.random(n), rng.random((n, 4)), rng.random(n) < 0.2, width=24, height=16)
    for name, params in [("bucket-depth-peeling", {}), ("bucket-depth-peeling", {"passes": 2}),
                         ("adaptive-bucket-depth-peeling", {})]:
        res = run(name, t, bounds="geometry", **params)
        assert res.dropped_fragments == 0, name
        assert_exact(res, t)
        # on the scene's range (the box), some pixel's two depths share one of the 32 buckets
        assert run(name, t, **params).dropped_fragments > 0, name


def test_the_box_range_is_the_scenes_over_its_rectangle_and_costs_no_scene_pass():
    # fragments at (1, 1) z 0.2 and 0.3, (3, 2) z 0.6 and 0.9 on a 5x4 screen: the box covers x 1-3, y 1-2
    t = make_trace(np.array([1, 1, 3, 3]), np.array([1, 1, 2, 2]), np.array([0.3, 0.2, 0.9, 0.6]), RGBA[:4],
                   width=5, height=4)
    box, own = run("bucket-depth-peeling", t), run("bucket-depth-peeling", t, bounds="geometry")
    # in the scene's range [0.2, 0.9] the buckets are floor(32 (z - 0.2) / 0.7): 4, 0, 31, 18, all distinct
    assert box.dropped_fragments == own.dropped_fragments == 0
    assert_exact(box, t)
    assert (box.geometry_passes, own.geometry_passes) == (1, 2)
    assert box.params["bounds"] == "box"
    bounds = box.passes[1]
    assert (bounds.name, bounds.kind, bounds.threads) == ("bounds", "fullscreen", "pixel")
    # the box's front and back faces blend at each of its 3 x 2 pixels; the scene pass blends each fragment
    assert box.accesses["depth_range"]["blend"] == 2 * 6 and own.accesses["depth_range"]["blend"] == 4
    assert next(s for s in box.structures if s.name == "depth_range").used_entries == 6
    stream = box.opstream()
    blends = (stream.op == OPS.index("blend")) & (stream.pass_index == 1)
    pixels = sorted(set((stream.address[blends] - stream.address[blends].min()).tolist()))
    assert len(pixels) == 6
    for name, params, passes in [("bucket-depth-peeling", {"passes": 2}, (2, 3)),
                                 ("adaptive-bucket-depth-peeling", {}, (2, 3))]:
        got = (run(name, t, **params).geometry_passes, run(name, t, bounds="geometry", **params).geometry_passes)
        assert got == passes, name
    assert run("bucket-depth-peeling", FragmentTrace.empty(4, 4)).accesses["depth_range"].get("blend", 0) == 0


def test_two_passes_halve_the_range_over_64_buckets():
    # 0 and 0.02 share bucket 0 of 32 (floor(0.64)) but not of 64 (floor(1.28) = 1); 0.6 is in the far half
    t = one_pixel([0.02, 0.0, 0.6, 1.0])
    one, two = run("bucket-depth-peeling", t), run("bucket-depth-peeling", t, passes=2)
    assert one.dropped_fragments == 1 and two.dropped_fragments == 0
    assert_exact(two, t)
    assert (one.geometry_passes, two.geometry_passes) == (1, 2)
    assert [p.name for p in two.passes] == ["clear", "bounds", "capture 0", "capture 1", "composite"]
    # every fragment loads the range in both capture passes; only those of a pass's half blend its 8 targets
    acc = two.accesses
    assert acc["depth_range"] == {"store": 1, "blend": 2, "load": 8}      # the box: front and back face
    assert acc["buckets"] == {"store": 16, "blend": 4 * 8, "load": 16}
    stream = two.opstream()
    on_buckets = (stream.op == OPS.index("blend")) & (stream.structure == stream.structures.index("buckets"))
    by_pass = np.bincount(stream.pass_index[on_buckets], minlength=5)
    assert by_pass.tolist() == [0, 0, 2 * 8, 2 * 8, 0]        # 0.02 and 0 near; 0.6 and 1.0 far


def test_adaptive_buckets_follow_the_occupied_bins():
    # 512 bins over [0, 1]: bins 0, 0, 1, 511; three occupied bins take buckets 0, 1, 2
    t = one_pixel([0.0, 0.001, 0.002, 1.0])
    res = run("adaptive-bucket-depth-peeling", t)
    assert res.stats["bin_collisions"].value == 1 and res.dropped_fragments == 1
    assert res.lists.fragment.tolist() == [1, 2, 3]
    assert res.stats["occupied_bins"].value == 3 and res.stats["merged_pixels"].value == 0
    # the uniform buckets lose two of them (0, 0.001 and 0.002 all in bucket 0)
    assert run("bucket-depth-peeling", t).dropped_fragments == 2
    # 40 occupied bins: bucket floor(32 r / 40) covers all 32 buckets, 8 of them twice
    zs = (np.arange(40) / np.float32(39)).astype(np.float32)
    deep = one_pixel(zs)
    res = run("adaptive-bucket-depth-peeling", deep)
    assert res.stats["occupied_bins"].value == 40 and res.stats["merged_pixels"].value == 1
    assert res.stats["bin_collisions"].value == 0 and res.dropped_fragments == 8
    assert len(res.lists.fragment) == 32
    # a histogram read: every fragment loads its 4 targets in the capture pass
    assert res.accesses["histogram"] == {"store": 4, "blend": 40 * 4, "load": 40 * 4}


def test_bucket_footprints_are_table_3s_memory():
    screen = FragmentTrace.empty(512, 512)
    assert run("bucket-depth-peeling", screen).footprint["buckets"] == 32 * MIB                  # BDP 32 MB
    assert run("bucket-depth-peeling", screen, passes=2).footprint["buckets"] == 64 * MIB        # BDP2 64 MB
    adp = run("adaptive-bucket-depth-peeling", screen).footprint
    assert adp["buckets"] == 32 * MIB and adp["histogram"] == 16 * MIB and adp["depth_range"] == 2 * MIB
    kb = run("multipass-kbuffer", screen, k=4).footprint
    assert kb["kbuffer"] == 20 * MIB                                                             # Liu 20 MB
    with pytest.raises(Exception, match="multiple of 128"):
        make_scheme("adaptive-bucket-depth-peeling", {"histogram_bins": 200})


# ---------------------------------------------------------------------- multi-pass k-buffer
@pytest.fixture(scope="module")
def deep():
    """Up to 12 fragments per pixel with distinct depths, on 6x5 pixels, opaque ones among them."""
    rng = np.random.default_rng(7)
    n = 200
    x, y = rng.integers(0, 6, n), rng.integers(0, 5, n)
    return make_trace(x, y, rng.random(n).astype(np.float32), rng.random((n, 4)), rng.random(n) < 0.1,
                      width=6, height=5, meta={"background": [0.1, 0.2, 0.3]})


@pytest.mark.parametrize("k", [1, 3, 8, 64])
def test_multipass_kbuffer_is_exact_and_peels_k_layers_a_pass(deep, k):
    res = run("multipass-kbuffer", deep, k=k)
    layers = int(deep.depth_complexity().max())
    assert res.dropped_fragments == 0
    assert_exact(res, deep)
    assert res.geometry_passes == -(-layers // k)
    assert run("multipass-kbuffer", deep, k=k, termination="occlusion-query").geometry_passes == -(-layers // k) + 1
    # a fragment read-modify-writes k entries in every pass it reaches: the passes its pixel needs before
    # the one that keeps it, and that one
    count = np.bincount(deep.pixel_ids(), minlength=deep.pixel_count)
    rank = np.empty(len(deep), np.int64)
    order = np.lexsort((deep.z, deep.pixel_ids()))
    starts = np.r_[0, np.cumsum(count)][deep.pixel_ids()[order]]
    rank[order] = np.arange(len(deep)) - starts
    assert res.accesses["kbuffer"]["rmw_read"] == k * int((rank // k + 1).sum())
    assert res.accesses["peel_depth"].get("load", 0) == len(deep) * (res.geometry_passes - 1)


def test_multipass_kbuffer_plan_grows_with_fragments_plus_passes():
    """A pixel 2,000 layers deep takes 250 passes of k = 8, every fragment in all of them up to its own: 125,000
    fragment-passes of RMW, held as one group per op across the passes (each fragment once), not a group per
    pass of every fragment still behind the peel depth."""
    rng = np.random.default_rng(3)
    t = one_pixel(rng.permutation(np.linspace(0.001, 0.999, 2000)).astype(np.float32))
    res = run("multipass-kbuffer", t, k=8)
    assert res.geometry_passes == 250 and res.dropped_fragments == 0
    assert res.accesses["kbuffer"]["rmw_read"] == 8 * sum(2000 - 8 * p for p in range(250))
    held = sum(len(g.thread) for g in res.plan.groups)
    assert held <= 20 * 2000 + 10 * res.geometry_passes, held


def test_multipass_kbuffer_behind_the_scoreboard_times_at_every_level(deep):
    """The analytic level packs the scoreboard's warps from every lane of a peel pass, as dispatch does (the peel
    test runs on fragments that do not reach the scoreboard); it failed with an IndexError before."""
    res = run("multipass-kbuffer", deep, k=3, hw="scoreboard")
    gpu = load_gpu("gtx280", ["runner.workers=1"])
    from gpusim.replay import run_timing
    cycles = {level: run_timing(res, deep, level, gpu, None)[0]["cycles"] for level in ("analytic", "full")}
    assert 0.5 * cycles["full"] <= cycles["analytic"] <= 2 * cycles["full"], cycles


def test_multipass_kbuffer_with_one_entry_is_depth_peeling():
    t = one_pixel([0.3, 0.1, 0.3, 0.2, 0.3])
    mp, dp = run("multipass-kbuffer", t, k=1, colour_format="rgba8"), run("depth-peeling", t)
    assert np.array_equal(mp.image, dp.image)
    assert mp.geometry_passes == dp.geometry_passes == 3
    assert mp.dropped_fragments == dp.dropped_fragments == 2


def test_multipass_kbuffer_loses_equal_depths_cut_by_a_pass():
    # k = 2: pass 0 keeps 0.1 and the first 0.2; the second 0.2 is not behind 0.2, never captured; pass 1: 0.3
    t = one_pixel([0.2, 0.1, 0.2, 0.3])
    res = run("multipass-kbuffer", t, k=2)
    assert res.stats["tie_losses"].value == res.dropped_fragments == 1
    assert res.lists.fragment.tolist() == [1, 0, 3] and res.geometry_passes == 2
    assert res.accesses["kbuffer"]["rmw_read"] == 2 * (4 + 1)
    assert np.allclose(res.image[0, 0], composite_of(t, [1, 0, 3])[0, 0], atol=1e-6)


@pytest.mark.parametrize("entry,k,slots", [("rgbz", 4, 4), ("z", 16, 4), ("z", 4, 1)])
def test_multipass_kbuffer_entry_formats(deep, entry, k, slots):
    """RGBZ and Z-only entries (seed 004 Table 1) peel the same fragments in the same passes; the buffer is k
    RGBA32F texels (RGBZ) or ceil(k / 4) (Z-only), each read or write moving one; the image is the stored
    entries' (the RGB, or the grey 1 - z, at the uniform alpha), the same when replayed without a hazard."""
    res = run("multipass-kbuffer", deep, k=k, entry=entry, uniform_alpha=0.5)
    ref = run("multipass-kbuffer", deep, k=k)
    assert res.geometry_passes == ref.geometry_passes and np.array_equal(res.lists.fragment, ref.lists.fragment)
    P = deep.pixel_count
    assert res.footprint["kbuffer"] == P * slots * 16
    got, want = res.accesses["kbuffer"], ref.accesses["kbuffer"]
    assert {op: got[op] * k for op in got} == {op: want[op] * slots for op in want}
    stream = res.opstream()
    assert set(stream.bytes[stream.structure == stream.structures.index("kbuffer")].tolist()) == {16}
    colours = deep.rgba[:, :3] if entry == "rgbz" else np.repeat(np.clip(1 - deep.z, 0, 1)[:, None], 3, axis=1)
    stored = make_trace(deep.x, deep.y, deep.z, np.c_[colours, np.full(len(deep), 0.5)], width=deep.width,
                        height=deep.height, meta=dict(deep.meta))
    kept = np.isin(np.arange(len(deep)), res.lists.fragment)
    assert np.allclose(res.image, composite_exact(stored.subset(kept)), atol=1e-5)
    times = np.tile(2 * np.arange(len(deep)), (res.geometry_passes, 1))
    image, stats = res.extras["rmw_replay"](times, times + 1)
    assert np.array_equal(image, res.image) and stats["lost_entries"] == 0


# ---------------------------------------------------------------------- timing
def test_hazards_are_counted_per_pass():
    # A reads at 0 and writes at 4 in pass 0, then read-modify-writes again in pass 1 (cycles 20-30); B reads at
    # 5, after A's write landed: no hazard. One window per thread over both passes would make B read before A's
    # (pass 1) write.
    pixel = np.array([0, 0])
    read, write = np.array([[0, 5], [20, -1]]), np.array([[4, 8], [30, -1]])
    assert count_hazards(pixel, read, write) == (0, 0)
    assert count_hazards(pixel, read.min(axis=0, where=read >= 0, initial=99), write.max(axis=0)) == (1, 1)
    read[0, 1] = 3                                           # B reads before A's write lands: a hazard
    assert count_hazards(pixel, read, write) == (1, 1)


@pytest.mark.parametrize("name,params", [("bucket-depth-peeling", {}), ("bucket-depth-peeling", {"passes": 2}),
                                         ("adaptive-bucket-depth-peeling", {}), ("multipass-kbuffer", {"k": 3})])
def test_every_timing_level_runs(deep, name, params):
    gpu = load_gpu("gtx280")
    cycles = {}
    for level in ("analytic", "sampled", "full"):
        result, record, _, _ = replay(deep, name, params, level, gpu)
        timing = record["timing"]
        assert [p["name"] for p in timing["passes"]] == [p.name for p in result.passes]
        assert all(p["cycles"] >= 0 for p in timing["passes"]) and timing["cycles"] > 0
        cycles[level] = timing["cycles"]
    assert 0.2 < cycles["analytic"] / cycles["full"] < 5 and 0.2 < cycles["sampled"] / cycles["full"] < 5
    if name != "multipass-kbuffer":
        assert timing["rmw_hazards"] == 0                   # blending at the ROP: never a hazard


def test_multipass_kbuffer_hazards_are_the_kbuffers_pass_by_pass(deep):
    # with k past every pixel's depth one peel pass does what the k-buffer's capture does: the same hazards
    gpu = load_gpu("gtx280")
    _, mp, _, _ = replay(deep, "multipass-kbuffer", {"k": 16}, "full", gpu)
    _, kb, _, _ = replay(deep, "kbuffer", {"k": 16}, "full", gpu)
    assert mp["timing"]["rmw_hazards"] == kb["timing"]["rmw_hazards"] > 0
    # in three passes a fragment's windows are per pass: no more hazards than RMW reads less the first of each
    # pixel in each pass, and the timed image replays every pass
    result, rec, _, _ = replay(deep, "multipass-kbuffer", {"k": 4}, "full", gpu)
    t = rec["timing"]
    participants = result.accesses["kbuffer"]["rmw_read"] // 4
    assert 0 < t["rmw_hazards"] <= participants - deep.pixel_count
    assert t["rmw_replay"]["lost_entries"] > 0
    assert t["rmw_replay"]["stored_entries"] + t["rmw_replay"]["lost_entries"] == len(deep)
