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
          "memory.partitions=1", "memory.interconnect_latency=0", "coalescer.segment_bytes=32",
          "dram.latency=100", "dram.bytes_per_cycle=32.0", "atomic.latency=50", "atomic.ops_per_cycle=100.0",
          "atomic.same_address_cycles=10", "rop.units=1", "rop.latency=0", "rop.ops_per_cycle=1.0",
          "runner.no_progress_cycles=100000", "driver.pass_us=0", "atomic.dram_rmw=false"]


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
    assert m.built_units() == ["core", "coalescer", "dram"]


def test_two_warps_on_one_address_serialize():
    # 64 atomics on one word, 10 cycles each; warp 1 reaches the unit at cycle 1, behind warp 0's 32
    plan = compute_plan(["c"])
    plan.add(0, "atomic_inc", "c", 64, 1, lambda i, s: i * 0, 4)
    cycles, m = simulate(plan, {"c": 4}, 64)
    assert cycles == 63 * 10 + 50        # last start 630, latency 50
    assert m.built_units() == ["core", "atomic"]
    assert m.units["atomic"].summary(cycles)["hottest_address_ops"] == 64


def test_atomics_that_read_and_write_dram_hold_its_channel():
    # atomic.dram_rmw: each atomic reads and writes its 32-byte sector, 64 B at 32 B/cycle = 2 cycles of the one
    # channel. Warp 0's 32 atomics on distinct words take it from cycle 0 to 64; warp 1's reach it at cycle 1 and
    # start at 64 (latency 50: done at 114), holding it to 128, when the pass ends
    plan = compute_plan(["c"])
    plan.add(0, "atomic_inc", "c", 64, 1, lambda i, s: i * 4, 4)
    cycles, m = simulate(plan, {"c": 256}, 64, ["atomic.dram_rmw=true"])
    assert cycles == 128
    assert m.built_units() == ["core", "dram", "atomic"]
    dram = m.unit_summaries(cycles)["dram"]
    assert dram["requests"] == 64 * 2 and dram["busy_cycles"] == 128
    # without it the unit serves them at 100 a cycle and the pass ends with warp 1's latency: 1 + 50
    plain, m2 = simulate(plan, {"c": 256}, 64)
    assert plain == 51 and m2.built_units() == ["core", "atomic"]


def test_dram_atomics_queue_with_the_cores_loads():
    # warp 0: 32 atomics on distinct words (64 cycles of the channel from cycle 0); warp 1: a load of 32 x 4 B,
    # 4 sectors = 128 B = 4 cycles, reaching the channel at cycle 1 behind the atomics: 64 + 4 + 100 latency
    plan = compute_plan(["c", "a"])
    plan.add(0, "atomic_inc", "c", np.arange(32), 1, lambda i, s: i * 4, 4)
    plan.add(0, "load", "a", np.arange(32, 64), 1, lambda i, s: (i - 32) * 4, 4)
    cycles, m = simulate(plan, {"c": 128, "a": 128}, 64, ["atomic.dram_rmw=true"])
    assert cycles == 64 + 4 + 100
    assert m.unit_summaries(cycles)["dram"]["busy_cycles"] == 64 + 4


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
    # (framebuffer traffic off: the reorder buffer alone; test_rop_framebuffer_traffic_takes_dram_bandwidth)
    roomy, m1 = simulate(plan, sizes, 64, ["core.sms=2", "rop.reorder_entries=64", "rop.memory_traffic=false"])
    # with room for all 32, warp 1 issues its load at cycle 1: done by 102; the ROPs drain at 165
    assert roomy == 165
    assert m1.units["rop"].summary(roomy)["stalls"] == 0
    tight, m2 = simulate(plan, sizes, 64, ["core.sms=2", "rop.reorder_entries=8", "rop.memory_traffic=false"])
    # 8 entries: warp 1 stalls until warp 0's blends commit (placed at cycle 101), its load then ends at 202
    assert tight == 101 + 1 + 100
    s = m2.units["rop"].summary(tight)
    assert s["stalls"] >= 1 and s["max_reorder_occupancy"] == 8


def test_rop_framebuffer_traffic_takes_dram_bandwidth():
    # 100 warps x 32 lanes blend 4-byte pixels one after another: a warp instruction touches 4 sectors of 32 B,
    # each read and written: 256 B at 32 B/cycle = 8 cycles of the one DRAM channel. The ROP (100 ops/cycle)
    # would take 32 cycles in all; the DRAM serves the 100 instructions back to back from cycle 0: 800 cycles.
    plan = compute_plan(["fb"])
    plan.add(0, "blend", "fb", 3200, 1, lambda i, s: i * 4, 4)
    fast = ["rop.ops_per_cycle=100.0"]
    cycles, m = simulate(plan, {"fb": 3200 * 4}, 3200, fast)
    assert cycles == 800
    assert m.built_units() == ["core", "coalescer", "dram", "rop"]
    dram = m.unit_summaries(cycles)["dram"]
    assert dram["requests"] == 100 * 4 * 2 and dram["busy_cycles"] == 800
    assert m.unit_summaries(cycles)["coalescer"]["requests"] == 0      # the SM's own requests: none
    # without the traffic the ROP and the issue of the warps decide, and no memory unit is built
    ideal, m2 = simulate(plan, {"fb": 3200 * 4}, 3200, fast + ["rop.memory_traffic=false"])
    assert ideal < 200 and m2.built_units() == ["core", "rop"]


def test_stiff_hot_word_and_latency_range_are_exact():
    # 10,000 atomics on one word beside one on another; latencies from 1 to 10,000 cycles
    plan = compute_plan(["c"])
    plan.add(0, "atomic_inc", "c", 10_001, 1, lambda i, s: np.where(i < 10_000, 0, 4), 4)
    extra = ["atomic.same_address_cycles=3", "atomic.latency=10000", "dram.latency=1",
             "runner.no_progress_cycles=1000000"]
    cycles, m = simulate(plan, {"c": 8}, 10_001, extra)
    assert cycles == 9_999 * 3 + 10_000
    assert isinstance(cycles, int)
    assert m.units["atomic"].summary(cycles)["hottest_address_ops"] == 10_000


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
    assert m.units["scoreboard"].summary(cycles)["max_held"] == 1
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


@pytest.mark.parametrize("override, message", [
    ("core.warp_size=33", "--gpu-set core.warp_size=33: core.warp_size: must be a power of two from 1 to 1024"),
    ("core.smss=4", "--gpu-set core.smss=4: core.smss: unknown key (valid: sms, warp_size, lanes_per_sm"),
    ("sample.fraction=0", "--gpu-set sample.fraction=0: sample.fraction: must be > 0, got 0.0"),
    ("sample.replicates=1", "--gpu-set sample.replicates=1: sample.replicates: must be >= 2"),
    ("sample.tile=0", "--gpu-set sample.tile=0: sample.tile: must be >= 1"),
    ("scoreboard.entries=8", "--gpu-set scoreboard.entries=8: scoreboard.entries (8) must be >= core.warp_size"),
])
def test_a_bad_override_names_the_override_not_the_preset(override, message):
    with pytest.raises(ConfigError) as exc:
        load_gpu("gtx280", [override])
    assert str(exc.value).startswith(message) and "gtx280.toml" not in str(exc.value)


def test_warp_sizes_are_powers_of_two():
    assert load_gpu("gtx280", ["core.warp_size=64", "scoreboard.entries=64"]).core.warp_size == 64
    assert load_gpu("gtx280", ["core.warp_size=1"]).core.issue_cycles == 1


@pytest.mark.parametrize("text", ["", "# nothing but a comment\n"])
def test_an_empty_gpu_file_is_an_error_naming_it(tmp_path, text):
    path = tmp_path / "empty.toml"
    path.write_text(text)
    with pytest.raises(ConfigError, match="empty.toml: the GPU file is empty"):
        load_gpu(str(path))


def test_presets_load_and_unknown_preset_lists_valid():
    for name in ("gtx280", "geforce7900gtx", "laptop-ampere", "modern"):
        g = load_gpu(name)
        assert g.name == name
    assert load_gpu("gtx280").core.sms == 30 and load_gpu("gtx280").memory.partitions == 8
    with pytest.raises(ConfigError, match="valid: geforce7900gtx, gtx280, laptop-ampere, modern"):
        load_gpu("gtx9999")


def test_l2_slice_is_lru_and_write_back():
    from types import SimpleNamespace

    from gpusim.hw.memory.l2 import L2Slice
    gpu = load_gpu("modern", ["l2.size_bytes=256", "l2.line_bytes=128", "l2.ways=2"])     # one set of 2 ways
    l2 = L2Slice(gpu.l2, SimpleNamespace(gpu=gpu, level_after=lambda name: None))
    a, b, c = 0, 1, 2                                  # lines of partition 0, all in its only set
    got = [l2.lookup(0, a, True), l2.lookup(0, b, False), l2.lookup(0, a, False), l2.lookup(0, c, False),
           l2.lookup(0, b, False), l2.lookup(0, a, False)]
    # a (dirty) and b miss; a hits; c evicts b (least recent, clean); b evicts a (dirty: written back)
    assert got == [(False, False), (False, False), (True, False), (False, False), (False, True), (False, False)]
    assert (l2.hits[0], l2.misses[0]) == (1, 5)


def test_a_load_through_the_l2_of_the_modern_preset():
    """One warp loads 32 x 4 B at address 0 in two passes on the unmodified `modern` preset (H100: 16 L2 slices of
    128-byte lines, 64 B/cycle, 260 cycles; HBM 105.7 B/cycle, 480 cycles; 40 cycles of interconnect each way;
    3 us of driver time per pass at 1980 MHz = 5940 cycles). The coalescer makes four 32-byte requests, all in
    line 0 of partition 0's slice (256-byte interleave).

    first pass:  request 1 arrives at 40, holds the slice 32/64 = 0.5 cycle, misses: HBM 40.5 -> 40.80 (32 B at
                 105.7 B/cycle), reply at ceil(40.80) + 480 = 521, + 260 = 781; requests 2-4 hit the line request 1
                 allocated: slice until 41, 41.5, 42, replies at ceil + 260 = 301, 302, 302. Done at 781 + 40 = 821.
    second pass: the line is still there: four hits, the last at 42 + 260 = 302, + 40 = 342.
    """
    plan = OpPlan([Pass("first", "fullscreen", "pixel"), Pass("again", "fullscreen", "pixel")], ["a"])
    for p in (0, 1):
        plan.add(p, "load", "a", 32, 1, lambda i, s: i * 4, 4)
    gpu = load_gpu("modern")
    work = Workload(plan, layout_bases(plan.structures, {"a": 128}), 64, 64, np.zeros(32, np.int64), np.arange(32),
                    triangles=0)
    machine = Machine(gpu, lower(work, gpu), 64)
    cycles = machine.run()
    assert machine.built_units() == ["core", "coalescer", "l2", "dram"]
    assert machine.pass_cycles == [5940 + 821, 5940 + 342] and cycles == 13_043
    l2, dram = machine.units["l2"].summary(cycles), machine.units["dram"].summary(cycles)
    assert (l2["requests"], l2["hits"], l2["misses"]) == (8, 7, 1)
    assert l2["busy_cycles"] == 8 * 0.5
    assert dram["requests"] == 1 and dram["busy_cycles"] == pytest.approx(32 / 105.7, abs=2 ** -16)
    assert machine.units["l2"].values(cycles)["hits"] == [7] + [0] * 15      # all in partition 0's slice


def test_sm_placement_is_per_pass_and_every_stat_uses_it():
    # pass A has 1 warp, pass B 3 warps, on 2 SMs: each pass places its warps from SM 0, so SM 0 runs A's warp
    # and B's warps 0 and 2, SM 1 B's warp 1 (numbering warps across passes would have said 2 and 2)
    plan = OpPlan([Pass("a", "fullscreen", "pixel"), Pass("b", "fullscreen", "pixel")], ["m"])
    plan.add(0, "load", "m", 32, 1, lambda i, s: i * 4, 4)
    plan.add(1, "load", "m", 96, 1, lambda i, s: i * 4, 4)
    cycles, m = simulate(plan, {"m": 384}, 96, ["core.sms=2"])
    core = m.units["core"]
    assert core.values(cycles)["requests"] == [3, 1]
    assert core.summary(cycles)["utilisation_max"] == pytest.approx(3 / cycles)
    assert list(core.place(3, 2)) == [0, 1, 0]


def test_a_memory_level_added_from_a_test_file():
    from dataclasses import dataclass

    from gpusim.config import param
    from gpusim.hw.memory import MemoryLevel
    from gpusim.hw.unit import FP, Stat, register_unit, unregister_unit

    @dataclass(frozen=True)
    class ToyConfig:
        latency: int = param(7, unit="cycles", doc="added to every instruction's requests", min=0)

    class Toy(MemoryLevel):
        name = "toy"
        Config = ToyConfig
        STATS = (Stat("requests", "instructions", "instructions passed on"),)

        def __init__(self, config, machine):
            super().__init__(machine)
            self.latency = config.latency

        def access(self, wi, arrive_fp, starts):
            self.requests[0] += 1
            return self.next.access(wi, arrive_fp + self.latency * FP, starts)

    register_unit(Toy)
    try:
        plan = compute_plan(["a"])
        plan.add(0, "load", "a", 32, 1, lambda i, s: i * 4, 4)
        path = "memory.levels=['coalescer', 'toy', 'dram']"
        cycles, m = simulate(plan, {"a": 128}, 32, [path, "toy.latency=9"])
        assert cycles == 104 + 9                       # the single-warp load timeline, 9 cycles later
        assert m.built_units() == ["core", "coalescer", "toy", "dram"]
        rows = [r for r in m.unit_stats(cycles) if r["unit"] == "memory.toy"]
        assert [(r["stat"], r["value"]) for r in rows[:1]] == [("requests", 1)]
        assert simulate(plan, {"a": 128}, 32)[0] == 104      # not on the path: not built, no effect
        with pytest.raises(ConfigError, match="'tpy' is not a memory level.*toy"):
            load_gpu("gtx280", ["memory.levels=['coalescer', 'tpy', 'dram']"])
    finally:
        unregister_unit("toy")
    with pytest.raises(ConfigError, match="memory.levels: 'toy' is not a memory level"):
        load_gpu("gtx280", [path])


def test_program_view_is_typed_instructions():
    # FreePipe's mapping: one thread per triangle, set up in software, looping over its fragments
    plan = OpPlan([Pass("draw", "geometry", "fragment", software=True)], ["a"])
    plan.add(0, "store", "a", 4, 1, lambda i, s: i * 4, 4)
    gpu = load_gpu("gtx280", SIMPLE + ["raster.setup_instructions=10", "raster.pixel_instructions=3",
                                       "raster.vertex_bytes=16"])
    # triangle 0 covers pixels 0 and 65 (a 2x2 bounding box), triangle 1 pixel 1; triangle 2 covers none
    work = Workload(plan, layout_bases(plan.structures, {"a": 16}), 64, 64, np.array([0, 65, 1, 1]),
                    np.array([0, 0, 1, 1]), triangles=3)
    prog = lower(work, gpu)
    from gpusim.hw.program import Compute, MemoryOp
    got = prog.warp(0)
    # every submitted triangle is a thread: it loads its 3 vertices, then sets up and scans its bounding box
    # (the warp lasts as long as its largest box: 4 pixels)
    index, vertices = got[:2]
    assert (index.op, index.lanes, list(index.thread), list(index.nbytes), index.depends) == (
        "load", 3, [0, 1, 2], [16] * 3, False)
    assert (vertices.op, vertices.lanes, list(vertices.nbytes), vertices.depends) == ("load", 3, [48] * 3, True)
    assert got[2] == Compute(10 + 3 * 4)
    assert [type(i) for i in got[3:]] == [MemoryOp, MemoryOp]
    assert [(i.op, i.unit, i.lanes, list(i.thread)) for i in got[3:]] == [("store", "coalescer", 2, [0, 2]),
                                                                           ("store", "coalescer", 2, [1, 3])]


def test_stats_come_from_declarations_into_one_long_table():
    plan = _reorder_plan()
    cycles, m = simulate(plan, {"a": 128, "fb": 4}, 64, ["core.sms=2"])
    rows = m.unit_stats(cycles)
    declared = {(u.path(), s.name): s for u in m.units.values() for s in u.STATS}
    assert {(r["unit"], r["stat"]) for r in rows} == set(declared)
    for r in rows:
        s = declared[(r["unit"], r["stat"])]
        assert (r["unit_of_measure"], r["doc"]) == (s.unit, s.doc)
        assert not any(ch.isdigit() for ch in r["stat"])               # dimensions are labels, not names
        assert r["labels"] == "" or r["labels"].startswith("instance=")
    assert {r["unit"] for r in rows} == {"core", "memory.coalescer", "memory.dram", "rop"}


def test_line_trace_shows_each_units_state_as_the_run_goes(capsys):
    plan = _reorder_plan()
    cycles, m = simulate(plan, {"a": 128, "fb": 4}, 64, ["core.sms=2", "runner.trace_every=50"])
    lines = capsys.readouterr().err.splitlines()
    assert len(lines) == -(-101 // 50)            # the pass's warps are done at cycle 101 (the last blend issues)
    assert lines[0].startswith("t=0 pass=0 | core: ") and "| memory.coalescer" not in lines[0]
    assert "coalescer: -" in lines[0] and "dram: free" in lines[0] and "rop: held" in lines[-1]
    assert m.line_trace().startswith(f"t={cycles} pass=0")


def test_a_run_too_large_to_lower_is_refused_with_advice_that_works():
    plan = compute_plan(["a"])
    plan.add(0, "store", "a", 3200, 1, lambda i, s: i * 64, 64)
    with pytest.raises(GpusimError, match=r"3,200 operations, over runner.max_operations = 1,000 .*--fidelity analytic"):
        simulate(plan, {"a": 3200 * 64}, 3200, ["runner.max_operations=1000"])


@pytest.mark.parametrize("key, value, match", [
    ("memory.levels", "[]", "memory path is empty"),
    ("core.sms", 10**9, "core.sms: must be <= 4096"),
    ("rop.units", 10**6, "rop.units: must be <= 4096"),
    ("memory.partitions", 5000, "memory.partitions: must be <= 1024"),
])
def test_gpu_configs_no_machine_could_be_fail_at_load(key, value, match):
    with pytest.raises(ConfigError, match=match):
        load_gpu("gtx280", [f"{key}={value}"])


@pytest.mark.parametrize("schedulers, cycles", [(1, 4 * 1000), (2, 2 * 1000), (4, 1000)])
def test_an_sms_schedulers_issue_side_by_side(schedulers, cycles):
    """Four warps of 1,000 ALU instructions each on one SM of 128 lanes: with one scheduler over all of them a
    warp instruction holds the SM's port a cycle and the warps take turns (4,000 cycles); with four (Ampere's
    processing blocks, 32 lanes each) the warps' slots are on different schedulers and issue side by side
    (1,000); with two, two warps share each (2,000)."""
    plan = compute_plan(["a"])
    plan.compute(0, 128, np.full(128, 1000), dep=False)
    got, m = simulate(plan, {"a": 4}, 128, ["core.lanes_per_sm=128", f"core.schedulers={schedulers}"])
    assert got == cycles
    assert m.unit_summaries(got)["core"]["utilisation_mean"] == pytest.approx(1.0)


def test_schedulers_must_divide_the_lanes():
    with pytest.raises(ConfigError, match="schedulers"):
        load_gpu("gtx280", ["core.lanes_per_sm=8", "core.schedulers=3"])


@pytest.mark.parametrize("n", [1, 3, 4, 8, 16, 32])
def test_interleave_spreads_strided_rows_and_keeps_each_share_one_to_one(n):
    from gpusim.hw.unit import interleave, within_instance
    address = np.arange(0, 1 << 22, 4, dtype=np.int64)
    part, offset = interleave(address, 256, n), within_instance(address, 256, n)
    assert len(np.unique(part * (1 << 40) + offset)) == len(address)      # (instance, offset) names one byte
    assert np.array_equal(interleave(np.arange(n) * 256, 256, n), np.arange(n))   # consecutive blocks go round
    # a 128x128 target of 16-byte pixels: its rows are 8 blocks; the 32 middle columns of every row
    x, y = np.meshgrid(np.arange(48, 80), np.arange(128))
    load = np.bincount(interleave((y * 128 + x).ravel() * 16, 256, n), minlength=n)
    assert load.max() <= 1.2 * load.mean()               # a plain b mod 8 put them on 2 of 8 partitions


@pytest.mark.parametrize("granularity,n", [(256, 8), (256, 6), (128, 4), (100, 8), (64, 10)])
def test_interleave_kernel_gives_the_numpy_instances(monkeypatch, granularity, n):
    """A long address array takes the compiled kernel (where numba is usable): the same instances as numpy's."""
    from gpusim.hw import unit
    from gpusim.jit import numba_usable
    address = np.random.default_rng(n).integers(0, 1 << 40, 3 * unit._CHUNK, dtype=np.int64)
    compiled = unit.interleave(address, granularity, n)
    assert not numba_usable() or unit._KERNEL[0] is not None
    monkeypatch.setattr(unit, "_KERNEL", [None])
    plain = unit.interleave(address, granularity, n)
    assert compiled.dtype == plain.dtype and np.array_equal(compiled, plain)
