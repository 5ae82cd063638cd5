"""The timing model's units against hand-computed timelines, stiff cases and the guards."""

from __future__ import annotations

import numpy as np
import pytest

from gpusim.errors import ConfigError, GpusimError
from gpusim.hw import load_gpu
from gpusim.hw.lower import Workload, lower
from gpusim.hw.machine import Machine, NoProgress
from gpusim.opplan import OpPlan, Pass, layout_bases

# one SM issuing a warp instruction per cycle, one partition, no interconnect
SIMPLE = ["core.sms=1", "core.lanes_per_sm=32", "core.instructions_per_op=0", "core.pipeline_latency=0",
          "memory.partitions=1", "memory.interconnect_latency=0", "memory.segment_bytes=32",
          "dram.latency=100", "dram.bytes_per_cycle=32.0", "atomic.latency=50", "atomic.ops_per_cycle=100.0",
          "atomic.same_address_cycles=10", "rop.units=1", "rop.latency=0", "rop.ops_per_cycle=1.0",
          "runner.no_progress_cycles=100000"]


def simulate(plan: OpPlan, sizes: dict, threads: int, extra=(), width=64):
    gpu = load_gpu("gtx280", SIMPLE + list(extra))
    work = Workload(plan, layout_bases(plan.structures, sizes), width, 64, np.zeros(threads, np.int64),
                    np.arange(threads), triangles=0)
    machine = Machine(gpu, lower(work, gpu), width)
    return machine.run(), machine


def compute_plan(structures):
    return OpPlan([Pass("kernel", "fullscreen", "pixel")], structures)


def test_single_warp_load_timeline():
    # 32 lanes x 4 B at consecutive addresses: 4 segments of 32 B = 128 B at 32 B/cycle = 4 cycles, + 100 latency
    plan = compute_plan(["a"])
    plan.add(0, "load", "a", 32, 1, lambda i, s: i * 4, 4)
    cycles, m = simulate(plan, {"a": 128}, 32)
    assert cycles == 104
    assert m.built_units() == ["dram"]


def test_two_warps_on_one_address_serialize():
    # 64 atomics on one word, 10 cycles each; warp 1 reaches the unit at cycle 1, behind warp 0's 32
    plan = compute_plan(["c"])
    plan.add(0, "atomic_inc", "c", 64, 1, lambda i, s: i * 0, 4)
    cycles, m = simulate(plan, {"c": 4}, 64)
    assert cycles == 63 * 10 + 50        # last start 630, latency 50
    assert m.built_units() == ["atomic"]
    assert m.atomics.summary(cycles)["max_ops_one_address"] == 64


def test_bandwidth_bound_stream():
    # 100 warps x 32 lanes x 64 B, fully coalesced: 204,800 B at 32 B/cycle = 6,400 cycles, + 100 latency
    plan = compute_plan(["a"])
    plan.add(0, "store", "a", 3200, 1, lambda i, s: i * 64, 64)
    cycles, m = simulate(plan, {"a": 3200 * 64}, 3200)
    assert cycles == 6500
    assert m.unit_summaries(cycles)["dram"]["utilisation_max"] == pytest.approx(6400 / 6500)


def _reorder_plan():
    # thread 0..31 (warp 0): a 4-byte load, then a blend on pixel 0 that waits for it;
    # thread 32..63 (warp 1): blends on pixel 0 at once, then a load. Warp 1's blends come later in
    # submission order, so they wait in the reorder buffer for warp 0's.
    plan = compute_plan(["a", "fb"])
    w0, w1 = np.arange(32), np.arange(32, 64)
    plan.add(0, "load", "a", w0, 1, lambda i, s: i * 0, 4)
    plan.add(0, "blend", "fb", w0, 1, lambda i, s: i * 0, 4, dep=True)
    plan.add(0, "blend", "fb", w1, 1, lambda i, s: i * 0, 4)
    plan.add(0, "load", "a", w1, 1, lambda i, s: i * 0 + 64, 4)
    return plan


def test_full_reorder_buffer_stalls_the_core():
    # warp 0: load done at 1 + 100 = 101, its 32 blends commit at 102..133; warp 1's 32 blends commit 134..165.
    plan = _reorder_plan()
    sizes = {"a": 128, "fb": 4}
    roomy, m1 = simulate(plan, sizes, 64, ["core.sms=2", "rop.reorder_entries=64"])
    # with room for all 32, warp 1 issues its load at cycle 1: done by 102; the ROPs drain at 165
    assert roomy == 165
    assert m1.rop.summary(roomy)["stalls"] == 0
    tight, m2 = simulate(plan, sizes, 64, ["core.sms=2", "rop.reorder_entries=8"])
    # 8 entries: warp 1 stalls until warp 0's blends commit (placed at cycle 101), its load then ends at 202
    assert tight == 101 + 1 + 100
    s = m2.rop.summary(tight)
    assert s["stalls"] >= 1 and s["max_reorder_occupancy"] == 8


def test_stiff_hot_word_and_latency_range_are_exact():
    # 10,000 atomics on one word beside one on another; latencies from 1 to 10,000 cycles
    plan = compute_plan(["c"])
    plan.add(0, "atomic_inc", "c", 10_001, 1, lambda i, s: np.where(i < 10_000, 0, 4), 4)
    extra = ["atomic.same_address_cycles=3", "atomic.latency=10000", "dram.latency=1",
             "runner.no_progress_cycles=1000000"]
    cycles, m = simulate(plan, {"c": 8}, 10_001, extra)
    assert cycles == 9_999 * 3 + 10_000
    assert isinstance(cycles, int)
    assert m.atomics.summary(cycles)["max_ops_one_address"] == 10_000


def test_deadlock_fails_with_a_diagnosis():
    # thread 1's depth test on pixel 0 must commit after thread 0's blend of pixel 0, which thread 0
    # issues only after its own depth test: the warp waits for itself.
    plan = compute_plan(["d", "fb"])
    plan.add(0, "depth_test", "d", np.array([0]), 1, lambda i, s: i * 0, 4)
    plan.add(0, "depth_test", "fb", np.array([1]), 1, lambda i, s: i * 0, 4)
    plan.add(0, "blend", "fb", np.array([0]), 1, lambda i, s: i * 0, 4, dep=True)
    with pytest.raises(NoProgress, match=r"no progress for 5,000 cycles.*rop\[0\].*warp 0"):
        simulate(plan, {"d": 4, "fb": 4}, 2, ["runner.no_progress_cycles=5000"])


def test_max_cycles_guard():
    plan = compute_plan(["a"])
    plan.add(0, "store", "a", 3200, 1, lambda i, s: i * 64, 64)
    with pytest.raises(GpusimError, match="runner.max_cycles"):
        simulate(plan, {"a": 3200 * 64}, 3200, ["runner.max_cycles=1000"])


def test_rasterizer_takes_the_triangles_a_pass_submits():
    # two fragments of triangles 500 and 501 of a 1,000-triangle scene, 1 triangle/cycle: a pass submitting the
    # whole scene lasts the 1,000 cycles of rasterizing it; a batch of the two triangles only waits for them
    # (ready at cycle 2, one 32-byte request: 1 cycle, + 100 latency)
    def run(primitives, prims=(500, 501)):
        n = len(prims)
        plan = OpPlan([Pass("draw", "geometry", "fragment", primitives=primitives)], ["a"])
        plan.add(0, "store", "a", n, 1, lambda i, s: i * 4, 4)
        gpu = load_gpu("gtx280", SIMPLE + ["raster.triangles_per_cycle=1.0"])
        work = Workload(plan, layout_bases(plan.structures, {"a": 4 * n}), 64, 64, np.zeros(n, np.int64),
                        np.array(prims), triangles=1000)
        return Machine(gpu, lower(work, gpu), 64).run()
    assert run(None) == 1000
    assert run(2) == 2 + 1 + 100
    # a batch whose fragments come back to a triangle: two distinct triangles spread over its three,
    # the last one out at 3 (not past the batch's end)
    assert run(3, (500, 501, 500)) == 3 + 1 + 100


def test_scoreboard_serializes_a_pixel():
    # 64 fragments of one pixel, each: dispatch, a load and a store. One in flight at a time.
    plan = compute_plan(["k"])
    plan.passes[0] = Pass("frags", "geometry", "fragment")
    plan.add(0, "scoreboard", "k", 64, 1, lambda i, s: i * 0, 0)
    plan.add(0, "rmw_read", "k", 64, 1, lambda i, s: i * 0, 4, dep=True)
    plan.add(0, "rmw_write", "k", 64, 1, lambda i, s: i * 0, 4, dep=True)
    cycles, m = simulate(plan, {"k": 4}, 64)
    # each fragment is alone in its warp (one cell) and takes read 1 + 100, write 1 + 100 cycles
    assert m.scoreboard.summary(cycles)["max_held"] == 1
    assert cycles >= 64 * 202


@pytest.mark.parametrize("key, value, match", [
    ("memory.partitions", 0, "memory.partitions: must be >= 1"),
    ("dram.latency", -5, "dram.latency: must be >= 0"),
    ("core.bogus", 1, "core.bogus: unknown key"),
    ("runner.no_progress_cycles", 10, "must exceed the slowest latency"),
    ("runner.workers", -1, "runner.workers: must be >= 0 processes"),
])
def test_impossible_gpu_config_fails_at_load(key, value, match):
    with pytest.raises(ConfigError, match=match):
        load_gpu("gtx280", [f"{key}={value}"])


def test_presets_load_and_unknown_preset_lists_valid():
    for name in ("gtx280", "geforce7900gtx", "modern"):
        g = load_gpu(name)
        assert g.name == name
    assert load_gpu("gtx280").core.sms == 30 and load_gpu("gtx280").memory.partitions == 8
    with pytest.raises(ConfigError, match="valid: geforce7900gtx, gtx280, modern"):
        load_gpu("gtx9999")


def test_l2_slice_is_lru_and_write_back():
    from gpusim.hw.memory import L2Slices
    gpu = load_gpu("modern", ["l2.size_bytes=256", "l2.line_bytes=128", "l2.ways=2"])     # one set of 2 ways
    l2 = L2Slices(gpu)
    a, b, c = 0, 1, 2                                  # lines of partition 0, all in its only set
    got = [l2.lookup(0, a, True), l2.lookup(0, b, False), l2.lookup(0, a, False), l2.lookup(0, c, False),
           l2.lookup(0, b, False), l2.lookup(0, a, False)]
    # a (dirty) and b miss; a hits; c evicts b (least recent, clean); b evicts a (dirty: written back)
    assert got == [(False, False), (False, False), (True, False), (False, False), (False, True), (False, False)]
    assert (l2.hits[0], l2.misses[0]) == (1, 5)
