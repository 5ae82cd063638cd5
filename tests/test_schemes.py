"""Scheme models: invariants on random and adversarial traces, footprints, OpStream consistency."""

from __future__ import annotations

import numpy as np
import pytest
from conftest import make_trace
from extremes import stored_as

from gpusim.errors import ConfigError, GpusimError
from gpusim.metrics import composite_exact, image_error
from gpusim.schemes import make_scheme, scheme_names
from gpusim.trace import FragmentTrace

MIB = 2 ** 20
ALL = scheme_names()


def run(name, trace, **params):
    return make_scheme(name, params).run(trace)


def exact(result, trace, tol=1e-5):
    err = image_error(result.image, composite_exact(trace))
    assert err["differing_pixels"] == 0, err
    assert err["max_abs"] < tol, err


def test_registry_lists_every_scheme_and_rejects_unknown_names():
    assert set(ALL) >= {"alpha-blend", "depth-peeling", "dual-depth-peeling", "freepipe-mdts", "freepipe-abuffer",
                        "kbuffer", "stencil-routed-abuffer", "linked-list", "wboit"}
    with pytest.raises(ConfigError, match="unknown scheme .*valid: adaptive-bucket-depth-peeling, alpha-blend"):
        make_scheme("a-buffer")
    with pytest.raises(ConfigError, match="layerz: unknown key .*valid: layers"):
        make_scheme("freepipe-mdts", {"layerz": 3})
    with pytest.raises(ConfigError, match="layers: must be >= 1"):
        make_scheme("freepipe-abuffer", {"layers": 0})
    with pytest.raises(ConfigError, match="'radix' is not a valid choice"):
        make_scheme("freepipe-abuffer", {"sort": "radix"})


@pytest.mark.parametrize("name", ALL)
def test_opstream_rows_match_access_counts_and_program_order(name, random_trace):
    params = {"pool_nodes_per_pixel": 20.0} if name == "linked-list" else {}
    if name == "kbuffer":
        params = {"mode": "sort-blend", "batch": 500, "order": "centroid"}
    res = run(name, random_trace, **params)
    stream = res.opstream()
    assert stream.counts() == res.accesses
    assert len(stream) == sum(sum(v.values()) for v in res.accesses.values())
    key = stream.pass_index.astype(np.int64) * (2 ** 40) + stream.thread
    assert np.all(np.diff(key) >= 0), "rows are ordered by pass, then thread"
    bases = res.bases()
    for s in res.structures:   # every address falls inside its structure
        sel = stream.structure == stream.structures.index(s.name)
        if sel.any():
            lo = stream.address[sel].min()
            hi = (stream.address[sel] + stream.bytes[sel]).max()
            assert lo >= bases[s.name] and hi <= bases[s.name] + s.allocated_bytes, s.name
    frame = stream.to_frame()
    assert len(frame) == len(stream)


LAYOUT_VARIANTS = [(name, {}) for name in ALL] + [
    ("kbuffer", {"hw": "blender"}), ("kbuffer", {"hw": "blender", "mode": "sort-blend"}),
    ("kbuffer", {"hw": "scoreboard", "entry": "rgbz", "k": 4, "uniform_alpha": 0.5}),
    ("kbuffer", {"entry": "z", "k": 16, "uniform_alpha": 0.5}), ("multipass-kbuffer", {"hw": "blender"}),
    ("mlab", {"hw": "rov"}), ("mlab", {"layers": 2})]


@pytest.mark.parametrize("name,params", LAYOUT_VARIANTS, ids=lambda v: v if isinstance(v, str) else
                         "-".join(f"{k}={x}" for k, x in v.items()) or "default")
def test_no_two_operations_of_a_group_overlap_in_part(name, params, random_trace):
    """An operation's bytes either are another's (the same record) or do not meet them: a record that runs
    into its neighbour's is a layout error, and it would let the coalescer and the ROPs' framebuffer traffic
    merge accesses that are apart (a pixel's 4 entries addressed at 8 bytes a pixel)."""
    plan = run(name, random_trace, **params).plan
    for g in plan.groups:
        if g.is_compute:
            continue
        i, seq = g.expand_ops()
        address = np.asarray(g.offset(i, seq), np.int64)
        nbytes = np.broadcast_to(np.asarray(g.bytes(i, seq) if callable(g.bytes) else g.bytes, np.int64),
                                 address.shape)
        starts, first = np.unique(address, return_index=True)
        ends = starts + nbytes[first]
        assert (starts[1:] >= ends[:-1]).all(), f"{name} {params}: a {g.op} on {g.structure} overlaps the next"


@pytest.mark.parametrize("name", ALL)
def test_deterministic_and_empty_trace(name, random_trace):
    a, b = run(name, random_trace), run(name, random_trace)
    assert np.array_equal(a.image, b.image) and a.accesses == b.accesses
    empty = FragmentTrace.empty(4, 3, {"background": [0.1, 0.2, 0.3]})
    res = run(name, empty)
    assert np.allclose(res.image, [0.1, 0.2, 0.3], atol=1 / 255) and res.dropped_fragments == 0


def test_footprints_reproduce_freepipe_section_5_2():
    screen = FragmentTrace.empty(512, 512)
    mdts = run("freepipe-mdts", screen, layers=20).footprint
    assert mdts["depth_array"] == 20 * MIB
    abuf = run("freepipe-abuffer", screen, layers=20).footprint
    assert abuf["depth_array"] == 20 * MIB and abuf["counter"] == 1 * MIB
    dp = run("depth-peeling", screen).footprint
    assert dp["depth_buffer"] + dp["peel_depth"] == 2 * MIB            # Table 3: DP 2 MB
    assert run("dual-depth-peeling", screen).footprint["minmax_depth"] == 4 * MIB   # DDP 4 MB
    assert run("stencil-routed-abuffer", screen, samples=8).footprint["samples"] == 16 * MIB   # SRAB 16 MB


def _pixel_sets(trace):
    pix = trace.pixel_ids()
    return {int(p): np.flatnonzero(pix == p) for p in np.unique(pix)}


@pytest.mark.parametrize("direction", ["min", "max"])
def test_mdts_keeps_the_layers_extreme_depths_sorted_whatever_the_interleaving(direction):
    rng = np.random.default_rng(3)
    n, layers = 3000, 6
    xs, ys = rng.integers(0, 6, n), rng.integers(0, 5, n)
    zs = rng.integers(1, 400, n) / 400.0            # many equal depths
    base = None
    for perm_seed in range(4):
        perm = np.random.default_rng(perm_seed).permutation(n)
        t = make_trace(xs[perm], ys[perm], zs[perm], width=6, height=5)
        res = run("freepipe-mdts", t, layers=layers, direction=direction, colour_format="rgba32f")
        kept = {}
        for p, frags in _pixel_sets(t).items():
            stored = t.z[res.lists.of_pixel(p)]
            want = np.sort(t.z[frags])
            want = want[:layers] if direction == "min" else want[::-1][:layers][::-1]
            assert np.array_equal(stored, want)      # front to back after the resolve
            kept[p] = stored
        base = base or kept
        assert all(np.array_equal(base[p], kept[p]) for p in kept)
        counts = np.bincount(t.pixel_ids())
        formula = sum(sum(min(j, layers) for j in range(1, c + 1)) for c in counts)
        op = "atomic_min" if direction == "min" else "atomic_max"
        assert res.accesses["depth_array"][op] == formula
        assert res.dropped_fragments == int(np.maximum(counts - layers, 0).sum())


def test_mdts_atomic_chain_addresses_walk_the_pixel_array():
    t = make_trace([1, 1, 1, 1], [0, 0, 0, 0], [0.4, 0.2, 0.3, 0.1], width=2, height=1)
    res = run("freepipe-mdts", t, layers=3)
    s = res.opstream()
    capture = s.pass_index == 1
    chain = s.op[capture] == 2                      # atomic_min
    offsets = (s.address[capture][chain] - res.bases()["depth_array"]) // 4
    # pixel 1 owns entries 3..5; the j-th fragment makes min(j, 3) atomics on entries 0..
    assert offsets.tolist() == [3, 3, 4, 3, 4, 5, 3, 4, 5]
    assert s.dep[capture][chain].all()


def test_mdts_equal_depths_collide_in_the_colour_pass():
    rgba = [[1, 0, 0, 0.5], [0, 0, 1, 0.5]]
    t = make_trace([0, 0], [0, 0], [0.5, 0.5], rgba=rgba, width=1, height=1)
    res = run("freepipe-mdts", t, colour_format="rgba32f")
    assert res.stats["colour_collisions"].value == 1
    assert image_error(res.image, composite_exact(t))["differing_pixels"] == 1   # measured, documented artefact
    abuf = run("freepipe-abuffer", t, colour_format="rgba32f")
    exact(abuf, t)


def test_mdts_packing_error_is_measured():
    # well separated depths, constant alpha: packing only quantises colour to 8 bits
    rng = np.random.default_rng(5)
    n = 400
    t = make_trace(rng.integers(0, 4, n), rng.integers(0, 4, n), np.linspace(0.05, 0.95, n),
                   rgba=np.c_[rng.random((n, 3)), np.full(n, 0.4)], width=4, height=4)
    res = run("freepipe-mdts", t, packing=True, layers=64)
    assert res.geometry_passes == 1
    assert res.stats["packing_colour_mismatches"].value == 0
    assert res.stats["packing_order_inversions"].value == 0
    assert image_error(res.image, composite_exact(t))["max_abs"] < 2.5 / 255
    # depths closer than the 20 packed bits: the colour halves can come from different fragments
    z = np.float32(0.3)
    close = [z, np.nextafter(z, np.float32(1))]
    rgba = [[1, 1, 1, 0.5], [0, 0, 0, 0.5]]     # white's halves sort after black's
    t2 = make_trace([0, 0], [0, 0], close, rgba=rgba, width=1, height=1)
    res2 = run("freepipe-mdts", t2, packing=True)
    assert res2.stats["packing_order_inversions"].value == 1
    with pytest.raises(GpusimError, match="packing stores no alpha"):
        run("freepipe-mdts", make_trace([0, 0], [0, 0], [0.1, 0.2], rgba=[[1, 1, 1, 0.2], [1, 1, 1, 0.7]]),
            packing=True)


@pytest.mark.parametrize("sort", ["insertion", "bitonic"])
def test_abuffer_with_enough_layers_equals_the_reference(random_trace, sort):
    deepest = int(np.bincount(random_trace.pixel_ids()).max())
    res = run("freepipe-abuffer", random_trace, layers=deepest, colour_format="rgba32f", sort=sort)
    exact(res, random_trace)
    assert res.dropped_fragments == 0
    few = run("freepipe-abuffer", random_trace, layers=4)
    counts = np.bincount(random_trace.pixel_ids())
    assert few.dropped_fragments == int(np.maximum(counts - 4, 0).sum())
    assert few.accesses["counter"]["atomic_inc"] == len(random_trace)


def test_bitonic_sort_reorders_equal_depths_insertion_keeps_them():
    n = 6
    rgba = np.c_[np.eye(3)[np.arange(n) % 3], np.full(n, 0.5)]
    t = make_trace(np.zeros(n), np.zeros(n), np.full(n, 0.5), rgba=rgba, width=1, height=1)
    ins = run("freepipe-abuffer", t, sort="insertion", colour_format="rgba32f")
    assert ins.lists.fragment.tolist() == list(range(n))
    exact(ins, t)
    bit = run("freepipe-abuffer", t, sort="bitonic", colour_format="rgba32f")
    assert sorted(bit.lists.fragment.tolist()) == list(range(n))
    assert bit.stats["sort_compares"].value == 8 // 2 * 6      # m = 8: 6 stages of 4 compare-exchanges


def test_linked_list_visits_every_fragment_once(random_trace):
    res = run("linked-list", random_trace, pool_nodes_per_pixel=100.0, colour_format="rgba32f")
    walk = res.extras["walk"]
    assert sorted(walk.fragment.tolist()) == list(range(len(random_trace)))
    pix = random_trace.pixel_ids()
    assert np.array_equal(pix[walk.fragment], walk.pixel)
    for p in (0, 7, 100):               # walk order: most recent first
        assert np.all(np.diff(walk.of_pixel(p)) < 0)
    assert res.accesses["counter"]["atomic_inc"] == len(random_trace)
    # ties: the stable sort keeps walk order, so equal depths differ from the reference ... measured
    tight = run("linked-list", random_trace, pool_nodes_per_pixel=1.0)
    pool = random_trace.pixel_count
    assert tight.stats["pool_overflow"].value == len(random_trace) - pool
    assert sorted(tight.extras["walk"].fragment.tolist()) == list(range(pool))


def test_depth_peeling_pass_counts_follow_freepipe_table_3(random_trace):
    layers = int(np.bincount(random_trace.pixel_ids()).max())    # random depths: no ties
    dp = run("depth-peeling", random_trace, colour_format="rgba32f")
    assert dp.geometry_passes == layers                            # known-layers: no final empty pass
    exact(dp, random_trace)
    assert run("depth-peeling", random_trace, termination="occlusion-query").geometry_passes == layers + 1
    ddp = run("dual-depth-peeling", random_trace, colour_format="rgba32f")
    assert ddp.geometry_passes == -(-layers // 2) + 1
    exact(ddp, random_trace)
    capped = run("depth-peeling", random_trace, max_passes=3)
    assert capped.geometry_passes == 3 and capped.dropped_fragments > 0
    # fixed: always max_passes passes, those past the layers peeling nothing (seed 004's multi-pass mode)
    fixed = run("depth-peeling", random_trace, termination="fixed", max_passes=layers + 5, colour_format="rgba32f")
    assert fixed.geometry_passes == layers + 5 and fixed.dropped_fragments == 0
    assert np.array_equal(fixed.image, dp.image)
    assert fixed.plan.accesses()["peel_depth"]["load"] == len(random_trace) * (layers + 4)
    with pytest.raises(GpusimError, match="max_passes >= 1"):
        run("depth-peeling", random_trace, termination="fixed")


def test_mdts_depth_only_capture_is_one_pass_and_the_depth_array(random_trace):
    both = run("freepipe-mdts", random_trace)
    depth = run("freepipe-mdts", random_trace, colour="none", colour_format="rgba32f")
    assert (both.geometry_passes, depth.geometry_passes) == (2, 1)
    assert set(depth.footprint) == {"depth_array", "total"}
    assert depth.footprint["total"] == depth.footprint["depth_array"] == both.footprint["depth_array"]
    assert set(depth.plan.accesses()) == {"depth_array"}
    assert depth.plan.accesses()["depth_array"]["atomic_min"] == both.plan.accesses()["depth_array"]["atomic_min"]
    exact(depth, random_trace)


def test_depth_peeling_loses_equal_depths_dual_peeling_keeps_them():
    rgba = [[1, 0, 0, 0.5], [0, 1, 0, 0.5], [0, 0, 1, 0.5]]
    t = make_trace([0, 0, 0], [0, 0, 0], [0.5, 0.5, 0.2], rgba=rgba, width=1, height=1)
    dp = run("depth-peeling", t, colour_format="rgba32f")
    assert dp.geometry_passes == 2 and dp.stats["tie_losses"].value == 1 and dp.dropped_fragments == 1
    assert dp.overflowed_pixels == 1                  # the pixel that lost the tie lost a fragment
    ddp = run("dual-depth-peeling", t, colour_format="rgba32f")
    assert ddp.dropped_fragments == 0


def test_kbuffer_peel_and_sort_blend(random_trace):
    deepest = int(np.bincount(random_trace.pixel_ids()).max())
    exact(run("kbuffer", random_trace, k=deepest), random_trace)
    few = run("kbuffer", random_trace, k=3)
    assert few.dropped_fragments == int(np.maximum(np.bincount(random_trace.pixel_ids()) - 3, 0).sum())
    assert few.accesses["kbuffer"]["rmw_read"] == 3 * len(random_trace)
    assert few.accesses["kbuffer"]["rmw_write"] == 3 * len(random_trace)
    # one fragment per primitive: the centroid sort makes the stream sorted, so k = 1 blending is exact
    sorted_blend = run("kbuffer", random_trace, k=1, mode="sort-blend", order="centroid")
    exact(sorted_blend, random_trace)
    assert sorted_blend.stats["misordered_pairs"].value == 0 and sorted_blend.stats["max_disorder"].value == 0
    unsorted = run("kbuffer", random_trace, k=1, mode="sort-blend")
    assert unsorted.stats["misordered_pairs"].value > 0 and unsorted.stats["max_disorder"].value > 0
    batched = run("kbuffer", random_trace, batch=1000)
    assert batched.stats["batches"].value == 5
    assert sum(p.kind == "flush" for p in batched.passes) == 4
    assert np.array_equal(batched.image, run("kbuffer", random_trace).image)


def test_kbuffer_batches_count_every_submitted_primitive():
    # 100 primitives submitted, 3 of them (ids 0, 50, 99) cover a pixel: batches of 32 are 4 draws (32, 32, 32, 4
    # primitives); in submission order a primitive's batch is its id // 32, in centroid order (99 nearest, then
    # 50, then 0) the 97 that cover nothing are spread evenly: ranks 0, 1, 2 at slots 0, 33, 66
    from gpusim.schemes.common.reorder import batch_plan, centroid_order
    trace = make_trace([0, 1, 2], [0, 0, 0], [0.9, 0.5, 0.1], prim=[0, 50, 99], meta={"primitives": 100})
    frag_batch, prims = batch_plan(trace, 32, centroid=False)
    assert frag_batch.tolist() == [0, 1, 3] and prims.tolist() == [32, 32, 32, 4]
    sorted_trace = trace.subset(centroid_order(trace))
    frag_batch, prims = batch_plan(sorted_trace, 32, centroid=True)
    assert sorted_trace.prim.tolist() == [99, 50, 0] and frag_batch.tolist() == [0, 1, 2]
    result = run("kbuffer", trace, k=2, batch=32, order="centroid")
    assert result.stats["batches"].value == 4
    assert [p.primitives for p in result.passes if p.kind == "geometry"] == [32, 32, 32, 4]


def test_kbuffer_sort_blend_is_exact_on_k_nearly_sorted_input():
    # depths at most k - 1 positions out of place: a k-buffer of k sorts them
    rng = np.random.default_rng(9)
    n, k = 200, 4
    z = np.linspace(0.1, 0.9, n)
    for i in range(0, n - 3, 3):
        z[i:i + 3] = z[i:i + 3][::-1]                    # displaced by at most 2 <= k - 1
    t = make_trace(np.zeros(n), np.zeros(n), z, rgba=rng.random((n, 4)), width=1, height=1)
    exact(run("kbuffer", t, k=k, mode="sort-blend"), t)


def test_kbuffer_counts_max_disorder_as_its_definition():
    """The scheme's stat (emitted_disorder, from the composited sequence alone) is max_disorder, the definition
    against the depth-sorted sequence, on the hand-made cases below and on random piles with ties."""
    from gpusim.schemes.kbuffer import emitted_disorder, max_disorder
    rng = np.random.default_rng(5)
    for _ in range(200):
        counts = rng.integers(1, 12, rng.integers(1, 6))
        pix = np.repeat(np.arange(len(counts)), counts)
        key = rng.integers(0, 6, len(pix)).astype(np.uint32)          # few values: many equal depths
        by_depth = np.lexsort((key, pix))
        assert emitted_disorder(pix, key) == max_disorder(pix[by_depth], key[by_depth], pix, key)
    assert emitted_disorder(np.zeros(0, np.int64), np.zeros(0, np.uint32)) == 0


def test_kbuffer_max_disorder_counts_positions_out_of_depth_order():
    from gpusim.schemes.kbuffer import max_disorder
    # the function on hand-made sequences: one pixel of 5 distinct depths, reversed, is 4 out of place at the ends
    pix, key = np.zeros(5, np.int64), np.arange(5, dtype=np.uint32)
    assert max_disorder(pix, key, pix, key) == 0
    assert max_disorder(pix, key, pix, key[::-1]) == 4
    assert max_disorder(pix, key, pix, key[[1, 0, 2, 3, 4]]) == 1
    # equal depths in any order are in place; a second pixel's sequence is measured on its own
    two_pix = np.array([0, 0, 0, 1, 1, 1], np.int64)
    sorted_keys = np.array([3, 3, 7, 1, 2, 9], np.uint32)
    assert max_disorder(two_pix, sorted_keys, two_pix, np.array([3, 3, 7, 9, 2, 1], np.uint32)) == 2
    assert max_disorder(two_pix, sorted_keys, two_pix, np.array([7, 3, 3, 1, 2, 9], np.uint32)) == 2
    assert max_disorder(two_pix[:3], sorted_keys[:3], two_pix[:3], sorted_keys[:3]) == 0
    with pytest.raises(ValueError, match="same fragments in both orders"):
        max_disorder(pix, key, pix[:4], key[:4])
    # the scheme: a stream arriving far to near through k = 1 comes out as arrivals 1, 2, 3, 4, then 0 (drained):
    # arrival 1 is composited first but is 4th nearest (|0 - 3|), arrival 4 fourth but nearest (|3 - 0|)
    far_to_near = make_trace(np.zeros(5), np.zeros(5), [0.9, 0.7, 0.5, 0.3, 0.1], width=1, height=1)
    assert run("kbuffer", far_to_near, k=1, mode="sort-blend").stats["max_disorder"].value == 3
    assert run("kbuffer", far_to_near, k=5, mode="sort-blend").stats["max_disorder"].value == 0
    near_to_far = make_trace(np.zeros(5), np.zeros(5), [0.1, 0.3, 0.5, 0.7, 0.9], width=1, height=1)
    assert run("kbuffer", near_to_far, k=1, mode="sort-blend").stats["max_disorder"].value == 0
    ties = make_trace(np.zeros(4), np.zeros(4), [0.5] * 4, width=1, height=1)
    assert run("kbuffer", ties, k=1, mode="sort-blend").stats["max_disorder"].value == 0
    assert "max_disorder" not in run("kbuffer", ties, k=1).stats          # peel mode composites in depth order


@pytest.mark.parametrize("entry,k,slots,slot_bytes", [("rgbz", 4, 4, 16), ("z", 16, 4, 16), ("z", 6, 2, 16),
                                                     ("depth-colour", 4, 4, 20)])
def test_kbuffer_entry_formats_size_its_buffer_and_accesses(random_trace, entry, k, slots, slot_bytes):
    # seed 004 Table 1: 4 RGBZ entries or 16 Z-only ones fill four RGBA32F MRTs (64 B a pixel); a read or write
    # moves one texel: an RGBZ entry, or four depths (k = 6 takes two texels, the second half used)
    res = run("kbuffer", random_trace, k=k, entry=entry, uniform_alpha=0.5)
    P, n = random_trace.pixel_count, len(random_trace)
    assert res.footprint["kbuffer"] == P * slots * slot_bytes
    assert res.structures[0].entry_bytes == {"rgbz": 16, "z": 4, "depth-colour": 20}[entry]
    assert res.accesses["kbuffer"] == {"store": P * slots, "rmw_read": n * slots, "rmw_write": n * slots,
                                       "load": P * slots}
    stream = res.opstream()
    assert set(stream.bytes.tolist()) == {slot_bytes}
    assert int(stream.address.max()) + slot_bytes == P * slots * slot_bytes       # within the MRT planes
    blend = run("kbuffer", random_trace, k=k, entry=entry, mode="sort-blend", uniform_alpha=0.5)
    assert blend.accesses["kbuffer"] == res.accesses["kbuffer"]
    assert blend.footprint["framebuffer"] == 16 * P


def test_kbuffer_rgbz_and_z_entries_give_the_image_of_what_they_store(random_trace):
    t = random_trace.subset(~random_trace.opaque)
    for entry in ("rgbz", "z"):
        for mode in ("peel", "sort-blend"):
            res = run("kbuffer", t, k=3, entry=entry, mode=mode, uniform_alpha=0.25)
            # the same fragments, composited from their stored colour at the uniform alpha
            same = run("kbuffer", stored_as(t, entry, 0.25), k=3, mode=mode)
            assert np.allclose(res.image, same.image, atol=1e-6) and np.array_equal(res.lists.fragment,
                                                                                    same.lists.fragment)
    # every fragment of one alpha, the one composited with (the default): RGBZ entries give the exact image
    uniform = stored_as(t, "rgbz", 0.25)
    exact(run("kbuffer", uniform, k=64, entry="rgbz"), uniform)
    # replayed in event order without a hazard (each fragment's write lands before the next one reads), the
    # timed image is the functional one, of the same entries
    sequential = 2 * np.arange(len(t))
    for entry in ("rgbz", "z"):
        for mode in ("peel", "sort-blend"):
            res = run("kbuffer", t, k=3, entry=entry, mode=mode, uniform_alpha=0.25)
            image, stats = res.extras["rmw_replay"](sequential, sequential + 1)
            assert np.array_equal(image, res.image) and stats["lost_entries"] == 0
    # a Z-only buffer holds no colour: the trace's colours do not reach its image
    recoloured = FragmentTrace(t.x, t.y, t.z, np.random.default_rng(1).random((len(t), 4)).astype(np.float32),
                               t.prim, t.opaque, t.width, t.height, t.meta)
    assert np.array_equal(run("kbuffer", t, entry="z", uniform_alpha=0.5).image,
                          run("kbuffer", recoloured, entry="z", uniform_alpha=0.5).image)
    # the uniform alpha defaults to the trace's single alpha, and fails naming the key where alphas differ
    half = stored_as(t, "rgbz", 0.5)
    assert np.array_equal(run("kbuffer", half, entry="rgbz").image,
                          run("kbuffer", half, entry="rgbz", uniform_alpha=0.5).image)
    with pytest.raises(GpusimError, match="uniform_alpha: entry = 'rgbz' stores no alpha .* set uniform_alpha"):
        run("kbuffer", t, entry="rgbz")
    with pytest.raises(ConfigError, match="colour_format: entry = 'z' stores no colour, not 'rgba8'; leave"):
        make_scheme("kbuffer", {"entry": "z", "colour_format": "rgba8"})
    with pytest.raises(ConfigError, match="uniform_alpha: must be <= 1"):
        make_scheme("kbuffer", {"entry": "z", "uniform_alpha": 1.5})


def test_stencil_routing_keeps_the_first_k_to_arrive(random_trace):
    res = run("stencil-routed-abuffer", random_trace, samples=4)
    pix = random_trace.pixel_ids()
    for p, frags in list(_pixel_sets(random_trace).items())[:20]:
        assert sorted(res.lists.of_pixel(p).tolist()) == sorted(frags[:4].tolist())
    assert res.geometry_passes == 2
    assert res.accesses["stencil"]["stencil"] == 4 * len(random_trace) + len(random_trace)
    assert res.dropped_fragments == int(np.maximum(np.bincount(pix) - 4, 0).sum())


def test_blending_baselines_match_the_reference_where_they_must():
    rng = np.random.default_rng(2)
    n = 50
    z = np.sort(rng.random(n))[::-1]                   # back to front: over-blending in order is exact
    t = make_trace(np.zeros(n), np.zeros(n), z, rgba=rng.random((n, 4)), width=1, height=1)
    exact(run("alpha-blend", t, framebuffer_format="rgba32f"), t)
    single = make_trace(np.arange(6), np.zeros(6), rng.random(6), rgba=rng.random((6, 4)), width=6, height=1)
    exact(run("wboit", single, accum_format="rgba32f", revealage_format="r32f"), single, tol=1e-4)
    multi = run("wboit", t)
    assert image_error(multi.image, composite_exact(t))["max_abs"] > 0    # approximate on layers


def test_opaque_prepass_culls_hidden_fragments():
    t = make_trace([0, 0, 0], [0, 0, 0], [0.6, 0.3, 0.8], rgba=[[1, 0, 0, 0.5], [0, 1, 0, 1], [0, 0, 1, 0.5]],
                   opaque=[False, True, False], width=1, height=1)
    res = run("alpha-blend", t, framebuffer_format="rgba32f")
    assert res.stats["culled_fragments"].value == 2
    exact(res, t)


@pytest.mark.parametrize("name", ALL)
def test_thousands_of_layers_on_one_pixel_and_alpha_extremes(name):
    n = 3000
    rng = np.random.default_rng(11)
    alpha = np.where(rng.random(n) < 0.3, 0.0, np.where(rng.random(n) < 0.05, 1.0, 0.02))
    xs = np.r_[np.zeros(n), [1]]
    t = make_trace(xs, np.zeros(n + 1), np.r_[rng.random(n), 0.5], rgba=np.c_[rng.random((n + 1, 3)), np.r_[alpha, 1]],
                   width=2, height=1)
    params = {"pool_nodes_per_pixel": 2000.0} if name == "linked-list" else {}
    if name in ("freepipe-abuffer", "freepipe-mdts"):
        params = {"layers": n, "colour_format": "rgba32f"}
    res = run(name, t, **params)
    assert np.isfinite(res.image).all() and (res.image >= 0).all() and (res.image <= 1 + 1e-6).all()
    if name in ("freepipe-abuffer", "freepipe-mdts", "linked-list", "depth-peeling", "dual-depth-peeling"):
        assert image_error(res.image, composite_exact(t))["differing_pixels"] == 0


def test_structures_only_where_the_scene_needs_them(random_trace):
    transparent = random_trace.subset(~random_trace.opaque)
    for name in ("alpha-blend", "wboit"):
        assert "depth_buffer" in run(name, random_trace).footprint
        res = run(name, transparent)
        assert "depth_buffer" not in res.footprint and res.passes[0].name == "transparent"
    assert "framebuffer" not in run("kbuffer", random_trace).footprint
    assert "framebuffer" in run("kbuffer", random_trace, mode="sort-blend").footprint
    assert "colour_array" in run("freepipe-mdts", random_trace).footprint
