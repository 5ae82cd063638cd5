"""Extreme inputs through every scheme and the timing model (issue 18).

The traces come from tests/extremes.py: depth complexity 1, 2, 1,000 and 10,000 on one pixel; a full screen
at depth complexity 64; one pixel of 10^4 fragments beside a million one-fragment pixels; equal depths at
0, 0.5 and 1; depths that collide after FreePipe's packing; -0.0 in a CSV; hundreds of layers of alpha
0.01, 0.99, 1e-6 and 1 - 1e-6. Every run must give the image its model defines (:func:`model_image`, the
README's table of error bounds and tie orders) or count exactly what it dropped or misordered, with finite
images and stats and integer counts. The event model must give the same cycles whatever the creation
order of simultaneous events, finish stiff configurations in whole cycles within a bounded number of
events, and add exactly a pass's own cost when a pass is split in two.
"""

from __future__ import annotations

import heapq
from types import SimpleNamespace

import numpy as np
import pytest
from extremes import (build, constant_alpha, equal_depths, from_histogram, hot_pixel, layer_stack, one_pixel,
                      packed_depth_collisions, stored_as)
from simpy.core import NORMAL
from simpy.events import Event
from test_hw_units import SIMPLE, simulate
from test_mlab_mboit import convex_bound, mlab_reference
from test_properties import (EPS32, ROUND, SPECS, assert_close, blend_rounding, check_counts_and_stats, composite,
                             documented_drops, documented_order, f32_tolerance, has_ties, per_pixel, rebuilt,
                             rounding_bound, transmittance_in_front, wboit_order_tolerance)

import gpusim.hw.machine as machine_module
from gpusim.hw import load_gpu
from gpusim.hw.core import flush_cycles
from gpusim.hw.driver import pass_overhead_cycles
from gpusim.hw.lower import Workload
from gpusim.hw.machine import KEY_SHIFT, OrderedEnvironment
from gpusim.hw.timing import run_analytic
from gpusim.metrics import composite_exact
from gpusim.opplan import OpPlan, Pass, layout_bases
from gpusim.replay import run_timing
from gpusim.schemes import make_scheme, scheme_names
from gpusim.schemes.common.depthkey import depth_key, packed_depth
from gpusim.trace_csv import read_csv_trace

ALL = scheme_names()
GPU = ["runner.workers=1"]


# ---------------------------------------------------------------------- each scheme's model
def lucidraster_emitted(trace, depth_filter: int) -> np.ndarray:
    """LucidRaster's emitted order (seed 002, docs/schemes.md), rebuilt here for traces with one fragment per
    triangle: a pixel's samples arrive sorted by the top 22 bits of their depth key (ties: triangle order);
    a ``depth_filter``-entry priority queue emits the nearest (ties: arrival) when a sample arrives at a full
    queue, then drains nearest first."""
    assert len(np.unique(trace.prim)) == len(trace)
    pix, key = trace.pixel_ids(), depth_key(trace.z).astype(np.int64)
    arrival = np.lexsort((trace.prim, key >> 10, pix))
    pa = pix[arrival]
    starts = np.flatnonzero(np.r_[True, pa[1:] != pa[:-1]]) if len(pa) else np.zeros(0, np.int64)
    out = []
    for lo, hi in zip(starts, np.r_[starts[1:], len(pa)]):
        queue, emitted = [], []
        for pos in range(lo, hi):
            entry = (int(key[arrival[pos]]), pos)
            if len(queue) < depth_filter:
                heapq.heappush(queue, entry)
            else:
                emitted.append(heapq.heappushpop(queue, entry))
        emitted += sorted(queue)
        out += [arrival[pos] for _, pos in emitted]
    return np.asarray(out, np.int64)


def wboit_model(trace) -> tuple[np.ndarray, np.ndarray]:
    """Weighted blended OIT (no opaque fragments) in float64, and the summed w a per pixel: with the eq10
    weight w = a max(1e-2, 3e3 (1 - d)^3), C = sum(w a c) / clamp(sum(w a), 1e-4, 5e4) (1 - prod(1 - a))
    + prod(1 - a) background."""
    pix, P = trace.pixel_ids(), trace.pixel_count
    a = trace.rgba[:, 3].astype(np.float64)
    wa = a * a * np.maximum(1e-2, 3e3 * (1.0 - trace.z.astype(np.float64)) ** 3)
    acc_a = np.bincount(pix, weights=wa, minlength=P)
    acc = np.stack([np.bincount(pix, weights=wa * trace.rgba[:, c], minlength=P) for c in range(3)], axis=1)
    with np.errstate(divide="ignore"):                # alpha 1: log 0 = -inf, exp(-inf) = 0
        reveal = np.exp(np.bincount(pix, weights=np.log1p(-a), minlength=P))[:, None]
    image = acc / np.clip(acc_a, 1e-4, 5e4)[:, None] * (1 - reveal) + trace.background * reveal
    return np.clip(image, 0, 1).reshape(trace.height, trace.width, 3), acc_a.reshape(trace.height, trace.width)


def model_image(name, trace, res) -> tuple[np.ndarray, np.ndarray]:
    """(the image ``name``'s model defines for ``trace``, the bound on the difference the README gives).

    Exact schemes: the float64 composite of the kept fragments in the documented order, colours stored in
    the scheme's format, within float32 error (4m + 8) 2^-23 for m layers, plus the R-buffer's per-blend
    rounding weighted by the transmittance in front. ``stencil-routed-abuffer``: the order its bitonic
    network leaves equal depths in (what it reports in ``lists``; the kept fragments are checked here).
    ``lucidraster``: its depth filter's emitted order (:func:`lucidraster_emitted`). ``alpha-blend``: "over"
    in submission order, within half an 8-bit step per blend weighted by the transmittance of the blends
    after it. ``wboit``: its formula, within the half-float rounding bound while m < 1024 and the weights
    sum below the half-float range (elsewhere no bound: inf). ``zbuffer``: the nearest fragment (the first
    submitted of equal depths) drawn opaque, its colour rounded to rgba8. ``mlab`` and ``mboit``: as
    tests/test_mlab_mboit.py defines them (its re-implementation; the exact reference within its bound)."""
    s, layers = SPECS[name], trace.depth_complexity()
    f32 = f32_tolerance(layers)
    idx, pix = np.arange(len(trace)), trace.pixel_ids()
    if name == "alpha-blend":
        reverse = np.lexsort((-idx, pix))           # blending in submission order = front to back, reversed
        fb_steps = per_pixel(trace, transmittance_in_front(trace, reverse) * (0.5 / 255 + 2 * EPS32), reverse)
        background = float(np.abs(ROUND["rgba8"](trace.background.astype(np.float32)) - trace.background).max())
        return composite(trace, reverse), f32 + fb_steps + background
    if name == "wboit":
        image, weight = wboit_model(trace)
        tol = np.where((layers < 1024) & (weight < 6e4), wboit_order_tolerance(trace, orders=1), np.inf)
        if (weight < 6e4).all():
            assert res.stats["accumulation_overflow"].value == 0
        return image, tol
    if name == "lucidraster":
        order = lucidraster_emitted(trace, int(s.limit))
        key = depth_key(trace.z[order]).astype(np.int64)
        descent = np.r_[False, (pix[order][1:] == pix[order][:-1]) & (key[1:] < key[:-1])]
        assert res.stats["invalid_samples"].value == int(descent.sum())
        assert res.stats["invalid_pixels"].value == len(np.unique(pix[order][descent]))
        assert np.array_equal(res.lists.fragment, order)
        return composite(trace, order), f32
    if name == "mlab":                              # tests/test_mlab_mboit.py's per-pixel re-implementation
        return mlab_reference(trace, int(s.limit), s.fmt), np.full(layers.shape, 1e-6)
    if name == "mboit":                             # approximate: within the convex bound of the reference
        bound = convex_bound(trace, res)
        black = (res.image == 0).all(axis=-1)       # every T a underflowed its target: left to the stat
        assert res.stats["zero_weight_pixels"].value <= int(black.sum())
        return composite_exact(trace), np.where(black & (res.stats["zero_weight_pixels"].value > 0), np.inf, bound)
    if name == "zbuffer":                           # the nearest fragment, drawn opaque
        nearest = np.lexsort((idx, depth_key(trace.z), pix))
        nearest = nearest[np.r_[True, pix[nearest][1:] != pix[nearest][:-1]][:len(nearest)]]
        opaque = rebuilt(trace, idx)
        opaque.opaque[:] = True
        return composite(opaque, nearest, s.fmt), f32
    if name == "stencil-routed-abuffer":
        order = res.lists.fragment
        kept = documented_order(name, trace)        # the first `samples` to arrive, nearest first
        assert np.array_equal(np.sort(order), np.sort(kept))
        assert np.array_equal(depth_key(trace.z[order]), depth_key(trace.z[kept]))   # sorted up to ties
        return composite(trace, order, s.fmt), f32
    if not s.exact or s.ties is None:
        pytest.fail(f"{name}: no model here; add it to model_image and its bound to the README's table")
    order = documented_order(name, trace)
    return composite(trace, order, s.fmt, s.round_background), f32 + blend_rounding(name, trace, order)


def check_run(name, trace, res) -> None:
    """A scheme's result is its model's image within the README's bound, with finite values, integer counts,
    and exactly the documented drops; an exact scheme that keeps every fragment is within its storage
    rounding of the exact reference."""
    assert res.image.shape == (trace.height, trace.width, 3)
    assert np.isfinite(res.image).all() and (res.image >= 0).all() and (res.image <= 1 + 1e-6).all()
    check_counts_and_stats(res)
    if SPECS[name].capacity != "filter":
        assert (res.dropped_fragments, res.overflowed_pixels) == documented_drops(name, trace)
    expected, tol = model_image(name, trace, res)
    assert_close(res.image, expected, tol, f"{name}: its model")
    s = SPECS[name]
    same_order = not has_ties(trace) or (s.ties == "submission" and not s.opaque_first)   # as the reference's
    if s.exact and same_order and res.dropped_fragments == 0 and s.capacity != "filter" and s.ties is not None:
        order = documented_order(name, trace)
        assert_close(res.image, composite_exact(trace), tol + rounding_bound(name, trace, order), f"{name}: exact")


def check_timing(rec: dict) -> None:
    """Whole cycles, per pass too, and finite unit figures."""
    assert type(rec["cycles"]) is int and rec["cycles"] > 0
    assert all(type(p["cycles"]) is int and p["cycles"] >= 0 for p in rec["passes"])
    for unit, figures in rec.get("units", {}).items():
        for k, v in figures.items():
            if isinstance(v, (int, float)):
                assert np.isfinite(v), (unit, k, v)


def run(name, trace, **params):
    """``name`` with the parameters the properties' documented model assumes (SPECS), and ``params``."""
    return make_scheme(name, dict(SPECS[name].params) | params).run(trace)


# ---------------------------------------------------------------------- depth complexity
@pytest.mark.parametrize("n", [1, 2, 1000, 10_000])
def test_depth_complexity_on_one_pixel(n):
    """Every scheme on one pixel of depth complexity n beside an empty one. n <= 2 also through the full
    event model; 1,000 and 10,000 through the analytic level only: at 10,000 the per-layer schemes would
    lower over runner.max_operations and the thesis schemes' per-pixel sort takes minutes in the event
    model."""
    trace = one_pixel(n, seed=n)
    gpu = load_gpu("gtx280", GPU)
    for name in ALL:
        res = run(name, trace)
        check_run(name, trace, res)
        for level in ("analytic", "full") if n <= 2 else ("analytic",):
            check_timing(run_timing(res, trace, level, gpu)[0])


def test_full_screen_at_depth_complexity_64():
    """Every pixel of a 16x16 screen at depth complexity 64, functional models and the analytic level (the
    stability matrix runs the full level on the bundled stress scenes)."""
    trace = layer_stack(16, 16, 64)
    assert (trace.depth_complexity() == 64).all()
    gpu = load_gpu("gtx280", GPU)
    for name in ALL:
        res = run(name, trace)
        check_run(name, trace, res)
        check_timing(run_timing(res, trace, "analytic", gpu)[0])


def test_hot_pixel_beside_a_million_single_fragment_pixels():
    """A stiff chain (10^4 fragments on one pixel) beside a wide easy load (999,999 pixels of one fragment).
    Functional models only, and the analytic level for the A-buffer, whose capture is an atomicInc chain on
    the hot pixel's counter: the event model would take minutes, and the analytic level 3-10 s a scheme
    (each scheme's timing of a 10^4 chain is checked on the one-pixel trace of depth 10^4). Each scheme keeps
    the documented fragments, with finite values and integer counts; its model is checked on the hot pixel
    and 2,000 one-fragment pixels, whose images and drops must be those of the scheme run on their fragments
    alone (a pixel depends on its own fragments only). The multi-pass k-buffer runs with k = 64: its functional model
    walks every fragment in each of its passes, 3 x 10^4 / k of them (a minute at its default k = 8)."""
    trace = hot_pixel(10_000, 1000, 1000)
    rng = np.random.default_rng(0)
    pixels = np.r_[0, rng.choice(np.arange(1, trace.pixel_count), 2000, replace=False)]
    sub = trace.subset(np.isin(trace.pixel_ids(), pixels))
    ys, xs = pixels // trace.width, pixels % trace.width
    gpu = load_gpu("gtx280", GPU)
    for name in ALL:
        params = {"k": 64} if name == "multipass-kbuffer" else {}    # distinct depths: the same image at any k
        res = run(name, trace, **params)
        assert np.isfinite(res.image).all() and (res.image >= 0).all() and (res.image <= 1 + 1e-6).all()
        check_counts_and_stats(res)
        alone = run(name, sub, **params)
        check_run(name, sub, alone)
        assert np.array_equal(res.image[ys, xs], alone.image[ys, xs]), name
        # a one-fragment pixel keeps its fragment: what is dropped is the hot pixel's, as on its own
        assert (res.dropped_fragments, res.overflowed_pixels) == (alone.dropped_fragments, alone.overflowed_pixels)
        if name == "freepipe-abuffer":
            check_timing(run_timing(res, trace, "analytic", gpu)[0])


# ---------------------------------------------------------------------- alpha and depth extremes
@pytest.mark.parametrize("alpha", [0.01, 0.99, 1e-6, 1 - 1e-6, 0.0, 1.0])
def test_hundreds_of_layers_of_one_alpha(alpha):
    """300 layers of one alpha on three pixels: 0.01 decays the transmittance over every layer (8 bits store
    it as 3/255, a documented error the bound carries); 0.99 and 1 - 1e-6 saturate it, and it underflows
    float32 after about 20 and 7 layers; 1e-6 and 0 leave it at about 1."""
    trace = constant_alpha(300, np.float32(alpha), seed=int(alpha * 1000))
    for name in ALL:
        check_run(name, trace, run(name, trace))


@pytest.mark.parametrize("entry", ["rgbz", "z"])
def test_kbuffer_entry_formats_give_their_models_image(entry):
    """The k-buffers' RGBZ and Z-only entries (seed 004 Table 1) on extreme traces (depth complexity 1,000, a
    full screen at 64, 300 layers of alpha 0.99, six equal depths, a hot pixel): each image is the scheme's
    model of the trace as its entries store it (extremes.stored_as: the RGB, or the grey 1 - z, at the uniform
    alpha), with the same drops."""
    traces = [one_pixel(1000, seed=1), layer_stack(16, 16, 64), constant_alpha(300, np.float32(0.99), seed=2),
              equal_depths(6, 0.5, seed=3), hot_pixel(100, 8, 8)]
    for trace in traces:
        for name in ("kbuffer", "multipass-kbuffer"):
            for alpha in (0.3, 1.0):
                check_run(name, stored_as(trace, entry, alpha), run(name, trace, entry=entry, uniform_alpha=alpha))


@pytest.mark.parametrize("z", [0.0, 0.5, 1.0])
def test_equal_depths_give_each_schemes_documented_order(z):
    """Six fragments at exactly one depth on one pixel (and the same beside four at distinct depths): each
    scheme composites them in the order the README's table states, the same on every run."""
    ties = equal_depths(6, z, seed=3)
    mixed = build(np.zeros(10, np.int64), np.r_[np.full(6, z), [0.25, 0.75, 0.0, 1.0]], 1, 1, seed=4)
    for trace in (ties, mixed):
        for name in ALL:
            a, b = run(name, trace), run(name, trace)
            assert np.array_equal(a.image, b.image), name
            check_run(name, trace, a)


def test_depth_exactly_zero_cannot_be_stored_by_a_descending_mdts():
    # docs/schemes.md: with direction=max a depth of exactly 0 equals the empty value: such fragments are
    # dropped, and counted
    trace = build(np.zeros(5, np.int64), [0, 0, 0, 0.3, 0.6], 1, 1, alpha=0.5)
    res = run("freepipe-mdts", trace, direction="max")
    assert (res.dropped_fragments, res.overflowed_pixels) == (3, 1)
    assert sorted(res.lists.fragment.tolist()) == [3, 4]


def test_depths_that_collide_after_packing_are_counted():
    """Runs of four distinct float32 depths that share FreePipe's 20 packed bits: the packed atomicMin chain
    orders a run by its 12 colour bits, and the scheme counts exactly the adjacent entries whose distinct
    depths collide and those left in the wrong true-depth order."""
    trace = packed_depth_collisions(5, seed=2)            # 20 fragments, within the 20 layers
    res = run("freepipe-mdts", trace, packing=True)
    check_counts_and_stats(res)
    assert res.dropped_fragments == 0
    stored = res.lists.fragment                           # the depth array's entries in their stored order
    packed = packed_depth(trace.z[stored]) >> np.uint32(12)
    z = trace.z[stored]
    assert (np.diff(packed.astype(np.int64)) >= 0).all()
    assert res.stats["packing_depth_collisions"].value == int(np.count_nonzero((np.diff(packed.astype(np.int64)) == 0)
                                                                               & (np.diff(z) != 0))) == 15
    assert res.stats["packing_order_inversions"].value == int(np.count_nonzero(np.diff(z) < 0))


def test_negative_zero_in_a_csv_is_depth_zero_in_every_scheme(tmp_path):
    rows = ["x,y,z,r,g,b,a", "0,0,-0.0,1,0,0,0.5", "0,0,0.0,0,1,0,0.5", "1,0,-0.0,0,0,1,0.25", "1,0,0.5,1,1,0,0.5"]
    neg = tmp_path / "neg.csv"
    neg.write_text("\n".join(rows) + "\n")
    pos = tmp_path / "pos.csv"
    pos.write_text("\n".join(rows).replace("-0.0", "0.0") + "\n")
    a, b = read_csv_trace(neg, 2, 1), read_csv_trace(pos, 2, 1)
    assert (depth_key(a.z) == depth_key(b.z)).all()
    for name in ALL:
        ra, rb = run(name, a), run(name, b)
        assert np.array_equal(ra.image, rb.image), name
        assert (ra.accesses, ra.dropped_fragments) == (rb.accesses, rb.dropped_fragments), name
        check_run(name, a, ra)


# ---------------------------------------------------------------------- the event model
STIFF = GPU + ["core.sms=1", "core.warps_per_sm=64", "memory.partitions=1", "rop.units=1",
               "rop.reorder_entries=1", "dram.latency=1", "l2.latency=100", "rop.latency=3000",
               "atomic.latency=10000", "runner.no_progress_cycles=1000000"]
VARIANTS = [(name, {}) for name in ALL] + [("kbuffer", {"hw": "scoreboard"}), ("kbuffer", {"hw": "blender"})]


class CreationOrderReversed(OrderedEnvironment):
    """Simultaneous events of one owner taken in the reverse of their creation order (and the environments
    made, so a test can count their events)."""

    made: list = []

    def __init__(self):
        super().__init__()
        self.made.append(self)

    def schedule(self, event, priority=NORMAL, delay=0) -> None:
        key = -1 if type(event) is Event else self.key
        heapq.heappush(self._queue, (self._now + delay, priority, (key << KEY_SHIFT) - next(self._eid), event))


def _figures(rec: dict) -> tuple:
    return (rec["cycles"], [p["cycles"] for p in rec["passes"]], rec.get("rmw_hazards"), rec["units"])


@pytest.mark.parametrize("trace", [one_pixel(1), hot_pixel(100, 8, 8)], ids=["one-fragment", "hot-pixel"])
def test_stiff_configs_take_the_same_cycles_whatever_the_event_creation_order(trace, monkeypatch):
    """One SM, one partition, one ROP with a one-entry reorder buffer, latencies from 1 to 10,000 cycles,
    more warp slots than warps; a pass with one fragment, and a hot pixel beside single-fragment pixels.
    Every scheme (and the k-buffer's scoreboard and blender) finishes in whole cycles, with the same figures
    when simultaneous events are created in the reverse order, within 3 events per warp, instruction and
    unit stall plus 8 per pass (no livelock)."""
    gpu = load_gpu("gtx280", STIFF)
    for name, params in VARIANTS:
        res = make_scheme(name, params).run(trace)
        plain, _, _ = run_timing(res, trace, "full", gpu)
        monkeypatch.setattr(machine_module, "OrderedEnvironment", CreationOrderReversed)
        CreationOrderReversed.made.clear()
        reversed_, _, _ = run_timing(res, trace, "full", gpu)
        monkeypatch.undo()
        check_timing(plain)
        assert _figures(plain) == _figures(reversed_), (name, params)
        events = next(CreationOrderReversed.made[0]._eid)
        warps = sum(p["warps"] for p in plain["passes"])
        stalls = sum(u.get("stalls", 0) for u in plain["units"].values())
        bound = 3 * (warps + plain["instructions"] + stalls) + 8 * len(plain["passes"])
        assert events <= bound + plain["cycles"] // gpu.runner.no_progress_cycles, (name, params, events, bound)


def _two_kinds_plan() -> OpPlan:
    """A wide easy load (3,200 threads storing 64 B each, fully coalesced), then a stiff chain (500 atomics
    on one word) in a pass of its own."""
    plan = OpPlan([Pass("stream", "fullscreen", "pixel"), Pass("chain", "fullscreen", "pixel")], ["a", "c"])
    plan.add(0, "store", "a", 3200, 1, lambda t, s: t * 64, 64)
    plan.add(1, "atomic_inc", "c", 500, 1, lambda t, s: t * 0, 4)
    return plan


def _only(plan: OpPlan, index: int) -> OpPlan:
    alone = OpPlan([plan.passes[index]], plan.structures)
    alone.groups = [g for g in plan.groups if g.pass_index == index]
    for g in alone.groups:
        g.pass_index = 0
    return alone


def _analytic(plan: OpPlan, sizes: dict, extra) -> int:
    gpu = load_gpu("gtx280", SIMPLE + list(extra))
    bases = layout_bases(plan.structures, sizes)
    work = Workload(plan, bases, 64, 64, np.zeros(3200, np.int64), np.arange(3200), triangles=0)
    rec, _ = run_analytic(work, gpu, SimpleNamespace(plan=plan, bases=lambda: bases))
    return rec["cycles"]


@pytest.mark.parametrize("level", ["full", "analytic"])
def test_splitting_a_pass_in_two_adds_exactly_the_pass_cost(level):
    """Passes are barriers on an idle machine: a plan split into two passes takes exactly what each pass
    takes alone, and each pass adds exactly its driver cost (driver.pass_us)."""
    sizes = {"a": 3200 * 64, "c": 4}
    split = _two_kinds_plan()
    totals = []
    for pass_us in (0.0, 1.5):
        extra = [f"driver.pass_us={pass_us}"]
        cycles = (lambda p: simulate(p, sizes, 3200, extra)[0]) if level == "full" else \
            (lambda p: _analytic(p, sizes, extra))
        assert cycles(split) == cycles(_only(split, 0)) + cycles(_only(split, 1))
        totals.append(cycles(split))
    assert totals[1] - totals[0] == 2 * pass_overhead_cycles(load_gpu("gtx280", ["driver.pass_us=1.5"])) == 2 * 1944


def test_kbuffer_batches_add_exactly_each_flush():
    """The k-buffer's batching heuristic splits the capture: each flush pass costs exactly the driver plus a
    pipeline drain (gpusim.hw.core.flush_cycles), at every level, whatever the screen's size."""
    trace = from_histogram({1: 40, 3: 20, 9: 4}, 16, 16, seed=5)
    gpu = load_gpu("gtx280", GPU + ["driver.pass_us=0.5"])
    res = run("kbuffer", trace, batch=40)
    for level in ("analytic", "sampled", "full"):
        rec = run_timing(res, trace, level, gpu)[0]
        assert rec["cycles"] == sum(p["cycles"] for p in rec["passes"])
        flushes = [p for p in rec["passes"] if p["kind"] == "flush"]
        assert len(flushes) == res.stats["batches"].value - 1 > 0
        assert flush_cycles(gpu.core) == gpu.core.pipeline_latency
        assert all(p["cycles"] == pass_overhead_cycles(gpu) + flush_cycles(gpu.core) for p in flushes), level


# ---------------------------------------------------------------------- footprint and accesses
HISTOGRAM = {1: 60, 2: 30, 3: 12, 8: 6, 9: 4, 21: 2, 40: 1}     # pixels of each depth complexity (past 8, 20)


def formulas(hist: dict, W: int, H: int) -> dict:
    """Each scheme's footprint (bytes per structure) and accesses (per structure and operation) at its
    defaults, on a transparent frame of distinct depths with ``hist[i]`` pixels of depth complexity i,
    evaluated from docs/schemes.md and the papers' formulas. The thesis schemes' are in test_thesis (Table
    4-2 and section 4.3.2 on the bundled frames); LucidRaster's depend on its triangles and bins too."""
    P = W * H
    n = sum(i * c for i, c in hist.items())
    L = max(hist)

    def over(f):                                     # the sum over pixels of f(depth complexity)
        return sum(c * f(i) for i, c in hist.items())

    kept20, kept8 = over(lambda i: min(i, 20)), over(lambda i: min(i, 8))
    peels = -(-L // 2)
    return {
        "alpha-blend": ({"framebuffer": 4 * P}, {"framebuffer": {"blend": n}}),
        "wboit": ({"accumulation": 8 * P, "revealage": 2 * P},
                  {"accumulation": {"blend": n, "load": P}, "revealage": {"blend": n, "load": P}}),
        "depth-peeling": ({"depth_buffer": 4 * P, "peel_depth": 4 * P, "layer_colour": 4 * P, "accumulation": 4 * P},
                          {"peel_depth": {"load": n * (L - 1)},       # every pass after the first
                           "depth_buffer": {"depth_test": over(lambda i: i * (i + 1) // 2)},   # until peeled
                           "layer_colour": {"load": n}, "accumulation": {"blend": n}}),
        "dual-depth-peeling": ({"minmax_depth": 16 * P, "front_colour": 4 * P, "back_colour": 4 * P},
                               {"minmax_depth": {"blend": n + over(lambda i: sum(min(d, i - 1 - d) for d in range(i))),
                                                 "load": n * peels},
                                "front_colour": {"blend": over(lambda i: -(-i // 2)), "load": P},
                                "back_colour": {"blend": over(lambda i: i // 2), "load": P}}),
        "freepipe-abuffer": ({"counter": 4 * P, "depth_array": 80 * P, "colour_array": 80 * P},
                             {"counter": {"store": P, "atomic_inc": n, "load": P},
                              "depth_array": {"store": kept20, "load": kept20},
                              "colour_array": {"store": kept20, "load": kept20}}),
        "freepipe-mdts": ({"depth_array": 80 * P, "colour_array": 80 * P},
                          {"depth_array": {"store": 20 * P,
                                           "atomic_min": over(lambda i: sum(min(j, 20) for j in range(1, i + 1))),
                                           # colour pass: walk to the own depth (or all 20); resolve: to the
                                           # first empty entry
                                           "load": over(lambda i: sum(range(1, min(i, 20) + 1)) + 20 * max(i - 20, 0))
                                           + over(lambda i: min(i, 20) + (i < 20)) + (P - sum(hist.values()))},
                           "colour_array": {"store": 20 * P + kept20, "load": kept20}}),
        "kbuffer": ({"kbuffer": 20 * 8 * P},
                    {"kbuffer": {"store": 8 * P, "rmw_read": 8 * n, "rmw_write": 8 * n, "load": 8 * P}}),
        "linked-list": ({"head": 4 * P, "nodes": 12 * 8 * P, "counter": 4},
                        {"head": {"store": P, "atomic_exch": n, "load": P}, "counter": {"store": 1, "atomic_inc": n},
                         "nodes": {"store": 2 * n, "load": n}}),
        "stencil-routed-abuffer": ({"stencil": 8 * P, "samples": 8 * 8 * P},
                                   {"stencil": {"store": 8 * P, "stencil": 8 * n + n},
                                    "samples": {"store": kept8, "load": kept8}}),
    }


@pytest.mark.parametrize("scale", [1, 3])
def test_footprint_and_accesses_follow_each_schemes_formula_of_the_histogram(scale):
    """Exactly, structure by structure and operation by operation, on a histogram and on it scaled up."""
    hist = {i: c * scale for i, c in HISTOGRAM.items()}
    W = H = 16 * scale
    trace = from_histogram(hist, W, H, seed=scale)
    assert np.bincount(np.bincount(trace.pixel_ids()))[list(hist)].tolist() == list(hist.values())
    for name, (footprint, accesses) in formulas(hist, W, H).items():
        res = run(name, trace)
        assert res.footprint == footprint | {"total": sum(footprint.values())}, name
        assert res.accesses == accesses, name
