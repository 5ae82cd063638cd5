"""The analytic level's terms, each on a hand-computed small case where it decides, beside the full model."""

from __future__ import annotations

import numpy as np
import pytest

from gpusim.hw import load_gpu
from gpusim.hw.analytic import _PassTimer, _fed, analytic_timing
from gpusim.hw.lower import Workload, lower
from gpusim.hw.machine import Machine
from gpusim.opplan import OpPlan, Pass, layout_bases
from gpusim.schemes.result import Structure

from test_hw_units import SIMPLE

# an L2 of 32 lines of 128 B (8 sets of 4 ways, every set reachable: one partition), 20 cycles a hit, 16 B/cycle
L2 = ["l2.size_bytes=4096", "l2.line_bytes=128", "l2.ways=4", "l2.latency=20", "l2.bytes_per_cycle=16"]


class _Result:
    """What the analytic level reads from a scheme result: the plan, the structures and their layout."""

    def __init__(self, plan, sizes):
        self.plan, self.sizes = plan, sizes
        self.structures = [Structure(name, 1, size, size, "") for name, size in sizes.items()]

    def bases(self):
        return layout_bases(self.plan.structures, self.sizes)


def _both(plan, sizes, threads, extra=()):
    """(full cycles, analytic record, each pass's analytic bounds and the cycles added to the largest)."""
    gpu = load_gpu("gtx280", SIMPLE + list(extra))
    result = _Result(plan, sizes)
    work = Workload(plan, result.bases(), 64, 64, np.zeros(threads, np.int64), np.arange(threads), triangles=0)
    full = Machine(gpu, lower(work, gpu), 64).run()
    timer = _PassTimer(result, work, gpu)
    return full, analytic_timing(result, work, gpu), [timer.time(p)["terms"] for p in range(len(plan.passes))]


def _stream():
    # 3,200 stores of 64 B at consecutive addresses: 6,400 requests of 32 B (two segments each), 1,600 lines
    plan = OpPlan([Pass("stream", "fullscreen", "pixel")], ["a"])
    plan.add(0, "store", "a", 3200, 1, lambda i, s: i * 64, 64)
    return plan


def test_every_request_holds_its_l2_slice():
    # 204,800 B through one slice at 16 B/cycle: 12,800 cycles, slower than the DRAM's 32 B/cycle for the misses;
    # plus the expected round trip: a quarter of the requests (a line's first) miss, 20 + 0.25 x 100 cycles
    full, rec, terms = _both(_stream(), {"a": 3200 * 64}, 3200, L2)
    (bounds, extra), = terms
    assert rec["passes"][0]["bound"] == "l2" and bounds["l2"] == 12800
    assert extra == 20 + 25 and rec["total"] == 12800 + 45
    assert abs(rec["total"] / full - 1) < 0.01, (rec["total"], full)


def test_a_miss_that_evicts_a_dirty_line_writes_it_back():
    # the same stream through a fast slice: each of the 1,600 lines misses once (32 B to the DRAM), and once the
    # 32 lines of the L2 are full (all written: dirty) each miss writes a 128 B line back, (1,600 - 32) of them
    full, rec, terms = _both(_stream(), {"a": 3200 * 64}, 3200, L2 + ["l2.bytes_per_cycle=1000"])
    (bounds, _), = terms
    assert rec["passes"][0]["bound"] == "dram"
    assert bounds["dram"] == pytest.approx((1600 * 32 + (1600 - 32) * 128) / 32)
    assert abs(rec["total"] / full - 1) < 0.02, (rec["total"], full)


def _store_then_chain():
    # pass 0 stores 10 words per thread (lanes 40 B apart: a request each); pass 1 loads them back, each load
    # waiting for the one before (a list walk)
    plan = OpPlan([Pass("write", "fullscreen", "pixel"), Pass("walk", "fullscreen", "pixel")], ["a"])
    plan.add(0, "store", "a", 32, 10, lambda i, s: (i * 10 + s) * 4, 4)
    plan.add(1, "load", "a", 32, 10, lambda i, s: (i * 10 + s) * 4, 4, dep=True)
    return plan


def test_lines_an_earlier_pass_left_in_the_l2_hit():
    # the 10 lines fit the L2, so every load of the walk hits: each waits 1 cycle of issue, its 32 requests on the
    # one slice (32 B / 16 B/cycle each: 64 cycles, served back to back) and the hit's 20 cycles
    full, rec, terms = _both(_store_then_chain(), {"a": 32 * 40}, 32, L2)
    bounds, extra = terms[1]
    assert bounds["dram"] == 0 and bounds["latency"] == 10 * (1 + 64 + 20) and extra == 20
    assert rec["passes"][1]["bound"] == "latency"
    assert abs(rec["passes"][1]["cycles"] / 840 - 1) < 0.05          # the full model's walk: 840 cycles
    assert full == 660 + 840


def test_without_an_l2_every_request_pays_the_dram():
    # the same walk with no L2: each load waits for its 32 requests on the DRAM (1 cycle each) and its 100 cycles
    _, rec, terms = _both(_store_then_chain(), {"a": 32 * 40}, 32)
    bounds, extra = terms[1]
    assert "l2" not in bounds and bounds["latency"] == 10 * (1 + 32 + 100) and extra == 100


def test_the_l2_holds_its_whole_capacity():
    # 16 slices of 4 sets x 2 ways (256-byte interleave, 128-byte lines: a partition's lines come two in every
    # 32): a pass touching exactly the 128 lines the slices hold finds them all again in the next pass, in the
    # full level (each slice numbers the lines of its own share, so they fill every set) and in the analytic one
    plan = OpPlan([Pass("first", "fullscreen", "pixel"), Pass("again", "fullscreen", "pixel")], ["a"])
    for p in (0, 1):
        plan.add(p, "load", "a", 128, 1, lambda i, s: i * 128, 4)
    gpu = load_gpu("modern", ["l2.size_bytes=1024", "l2.line_bytes=128", "l2.ways=2"])
    result = _Result(plan, {"a": 128 * 128})
    work = Workload(plan, result.bases(), 64, 64, np.zeros(128, np.int64), np.arange(128), triangles=0)
    machine = Machine(gpu, lower(work, gpu), 64)
    cycles = machine.run()
    l2 = machine.units["l2"].summary(cycles)
    assert (l2["requests"], l2["hits"], l2["misses"]) == (256, 128, 128)
    first, again = (_PassTimer(result, work, gpu).time(p)["terms"][0]["dram"] for p in (0, 1))
    assert first > 0 and again == 0


def test_warps_behind_the_scoreboard_start_once_all_their_cells_are_free():
    # fragments on cells 0, 1, 1, 2, 2, 0: dispatch packs warps {0, 1}, {1, 2}, {2, 0} (no cell twice in a warp),
    # each pair of them sharing a cell, so they run one after another although no cell has more than two:
    # warp 1 waits for warp 0 (cell 1), warp 2 for warp 1 (cell 2); each warp's chain is 205 cycles (the
    # scoreboard, a load of 1 + 1 + 100 cycles and a store waiting for it, 1 + 101)
    pix = np.array([0, 1, 1, 2, 2, 0])
    plan = OpPlan([Pass("capture", "fullscreen", "fragment")], ["a"])
    plan.add(0, "scoreboard", "a", 6, 1, lambda i, s: pix[i] * 4, 0)
    plan.add(0, "load", "a", 6, 1, lambda i, s: pix[i] * 4, 4, dep=True)
    plan.add(0, "store", "a", 6, 1, lambda i, s: pix[i] * 4, 4, dep=True)
    gpu = load_gpu("gtx280", SIMPLE)
    result = _Result(plan, {"a": 64})
    work = Workload(plan, result.bases(), 64, 64, pix, np.arange(6), triangles=0)
    full = Machine(gpu, lower(work, gpu), 64).run()
    rec = _PassTimer(result, work, gpu).time(0)
    bounds, _ = rec["terms"]
    assert rec["warps"] == 3 and bounds["latency"] == 205
    assert bounds["scoreboard"] == 2 * 205 and bounds["scoreboard_conflicts"] == 3 * 205
    assert rec["bound"] == "scoreboard_conflicts"
    assert 3 * 200 <= full <= 3 * 205          # each warp holds its cells 203 cycles: issue, the load, the store


def _triangles(pixels, prims, triangles, ops):
    """A software rasterizer's geometry pass: a thread per triangle loops over its fragments, each issuing ``ops``
    (op, structure, byte offset of the fragment's pixel, dep)."""
    plan = OpPlan([Pass("draw", "geometry", "fragment", software=True)], ["fb", "c"])
    pixels = np.asarray(pixels, np.int64)
    for op, structure, dep in ops:
        plan.add(0, op, structure, len(pixels), 1, lambda i, s: pixels[i] * 4, 4, dep=dep)
    gpu = load_gpu("gtx280", SIMPLE + ["raster.setup_instructions=0", "raster.pixel_instructions=0"])
    result = _Result(plan, {"fb": 64 * 64 * 4, "c": 64 * 64 * 4})
    work = Workload(plan, result.bases(), 64, 64, pixels, np.asarray(prims, np.int64), triangles=triangles)
    return Machine(gpu, lower(work, gpu), 64).run(), _PassTimer(result, work, gpu).time(0)


def test_a_triangle_thread_loads_its_indices_and_vertices_before_its_fragments():
    # one triangle, one fragment that stores: the index load (1 cycle of issue, 100 of latency, 1 request of 32 B
    # on the DRAM's 32 B/cycle), the vertex load that needs it (48 B: 2 requests), then the store
    full, rec = _triangles([5], [0], 1, [("store", "fb", False)])
    assert full == (1 + 100) + (2 + 100) + (1 + 100)
    bounds, extra = rec["terms"]
    assert rec["bound"] == "latency" and bounds["latency"] == (1 + 100 + 1) + (1 + 100 + 2) + 1 and extra == 100


def test_lanes_of_one_instruction_on_one_word_serialize():
    # 32 pixel threads increment one counter, then store what it returned: the instruction's 32 operations on
    # the word start 10 cycles apart (atomic.same_address_cycles), so the store waits 31 x 10 + 50 cycles
    plan = OpPlan([Pass("count", "fullscreen", "pixel")], ["c", "fb"])
    plan.add(0, "atomic_inc", "c", 32, 1, lambda i, s: i * 0, 4)
    plan.add(0, "store", "fb", 32, 1, lambda i, s: i * 4, 4, dep=True)
    full, _, terms = _both(plan, {"c": 4, "fb": 128}, 32)
    bounds, extra = terms[0]
    assert full == 31 * 10 + 50 + (4 + 100)               # then the store: its 4 requests and 100 cycles
    assert bounds["latency"] == 1 + (31 * 10 + 50) + 1 and extra == 100


def test_a_triangle_threads_warp_waits_for_its_own_instructions_words():
    # two coplanar triangles of 3 fragments on the same pixels, each fragment an atomicMin on its pixel's word
    # that the next waits for: at each of the warp's 3 iterations its 2 lanes' operations on one word go 10
    # cycles apart; a single triangle of 3 fragments beside them (another warp) waits for none
    pixels, prims = [1, 2, 3, 1, 2, 3] + [70, 71, 72], [0, 0, 0, 1, 1, 1] + [32, 32, 32]
    full, rec = _triangles(pixels, prims, 33, [("atomic_min", "c", True)])
    bounds, _ = rec["terms"]
    prefix = (1 + 100 + 16) + (1 + 100 + 48)       # a warp of 32 triangles' indices (512 B), vertices (1,536 B)
    assert bounds["latency"] == prefix + 3 * (1 + 50) + 3 * 10
    assert abs(bounds["latency"] / full - 1) < 0.02, (bounds["latency"], full)     # the full model: 444


def test_a_pixel_shaders_warps_are_lowerings_helper_lanes_and_all():
    # a triangle's fragments on a diagonal fill one lane of each of their 2x2 quads: 30 fragments, 30 quads, 120
    # lanes in 4 warps; a depth test on every fragment and a store on every third spread over all the warps
    # (a warp issues a group's instruction when any of its lanes has it), as lowering makes them
    n = 30
    pixels = np.arange(n) * (2 * 64 + 2)
    plan = OpPlan([Pass("draw", "geometry", "fragment")], ["fb"])
    plan.add(0, "depth_test", "fb", n, 1, lambda i, s: pixels[i] * 4, 4)
    plan.add(0, "store", "fb", np.arange(0, n, 3), 1, lambda i, s: pixels[i * 3] * 4, 4, dep=True)
    gpu = load_gpu("gtx280", SIMPLE)
    result = _Result(plan, {"fb": 64 * 64 * 4})
    work = Workload(plan, result.bases(), 64, 64, pixels, np.zeros(n, np.int64), triangles=1)
    program = lower(work, gpu)
    rec = analytic_timing(result, work, gpu)
    assert rec["passes"][0]["warps"] == program.passes[0].warps == 4
    assert rec["instructions"] == program.instructions == 4 + 4


def test_requests_are_the_coalescers_sectors():
    # 32 threads each read 8 entries of 20 B in a row (a k-buffer pixel's): some straddle a 32-byte segment, some
    # two sectors of one; the requests and their bytes are the coalescer's, so is the DRAM's bound
    plan = OpPlan([Pass("read", "fullscreen", "pixel")], ["k"])
    plan.add(0, "load", "k", 32, 8, lambda i, s: i * 160 + s * 20, 20)
    gpu = load_gpu("gtx280", SIMPLE)
    result = _Result(plan, {"k": 32 * 160})
    work = Workload(plan, result.bases(), 64, 64, np.zeros(32, np.int64), np.arange(32), triangles=0)
    machine = Machine(gpu, lower(work, gpu), 64)
    machine.run()
    (bounds, _), = [_PassTimer(result, work, gpu).time(0)["terms"]]
    assert bounds["dram"] * 32 == sum(machine.units["coalescer"].bytes)


def _two_warps(last_triangle, triangles, nbytes):
    """16 full quads (an 8x8 block): two warps of 32 lanes each storing ``nbytes``; the first warp's triangle is
    the first of ``triangles`` at 2 cycles each, the second warp's ``last_triangle``. (full cycles, pass record)"""
    xy = [(x, y) for y in range(8) for x in range(8)]
    order = sorted(range(64), key=lambda i: ((xy[i][1] // 2) * 4 + xy[i][0] // 2, i))
    pixels = np.array([xy[i][1] * 64 + xy[i][0] for i in order])
    plan = OpPlan([Pass("draw", "geometry", "fragment")], ["fb"])
    plan.add(0, "store", "fb", 64, 1, lambda i, s: i * nbytes, nbytes)
    gpu = load_gpu("gtx280", SIMPLE + ["raster.triangles_per_cycle=0.5", "raster.vertex_instructions=0",
                                       "raster.vertex_bytes=0"])
    result = _Result(plan, {"fb": 64 * nbytes})
    prims = np.array([0] * 32 + [last_triangle] * 32)
    work = Workload(plan, result.bases(), 64, 64, pixels, prims, triangles=triangles)
    return Machine(gpu, lower(work, gpu), 64).run(), _PassTimer(result, work, gpu).time(0)


def test_a_unit_serves_a_warps_work_once_the_front_end_has_it_out():
    # the second warp's triangle is the last of 1,000: out at cycle 2,000, and its stores (64 B a lane: 64 cycles
    # of the DRAM a warp) take their 64 cycles after that: the raster bound's tail (the DRAM keeps up)
    full, rec = _two_warps(999, 1000, 64)
    bounds, extra = rec["terms"]
    assert bounds["dram"] == 128 and bounds["raster"] == 2000 + 64 and bounds["front_end"] == 0
    assert rec["bound"] == "raster" and rec["cycles"] == 2064 + extra == full
    # 128 B a lane, the second warp out at cycle 100 of 100: the first warp's 128 cycles of the DRAM are not done
    # when the second's arrive (a backlog), so the DRAM serves both from cycle 2.15 on (the first warp's 8
    # quads at 3.72 a cycle): front_end 2.15 + 256
    full, rec = _two_warps(49, 50, 128)
    bounds, extra = rec["terms"]
    assert bounds["dram"] == 256 and bounds["raster"] == 100 + 1
    assert bounds["front_end"] == pytest.approx(2.15 + 256, abs=0.01)
    assert rec["bound"] == "front_end" and abs(rec["cycles"] / full - 1) < 0.02, (rec["cycles"], full)


def test_a_queue_fed_by_the_front_end():
    # the largest over warps j of when j is out plus the work of the warps from j on, per server
    # (and whether a warp before the last decides: a backlog, not the last warp's own work after the front end)
    ready, demand = np.array([0.0, 0.0, 100.0]), np.array([50.0, 50.0, 10.0])
    assert _fed(ready, demand, 1) == (max(0 + 110, 0 + 60, 100 + 10), False)       # the last warp's too
    assert _fed(ready, np.array([60.0, 50.0, 10.0]), 1) == (120, True)
    assert _fed(ready, demand, 2) == (max(max(0 + 60, 100 + 10), 0 + 50), False)     # warps 0, 2 on one server
    assert _fed(ready, np.array([50.0, 50.0, 50.0]), 1) == (150, False)         # a tie: the front end
    assert _fed(np.array([0.0, 10.0, 500.0]), np.array([5.0, 5.0, 5.0]), 1) == (505, False)


def test_a_triangle_threads_warp_runs_each_iteration_as_long_as_its_longest_lane():
    # two triangles of two fragments in one warp; their fragments loop 3, 1 and 1, 3 times on an atomicMin that
    # waits for its result (1 + 50 cycles each): each lane runs 4, but the warp runs max(3, 1) + max(1, 3) = 6
    pixels, prims = np.array([1, 2, 3, 4]), np.array([0, 0, 1, 1])
    plan = OpPlan([Pass("draw", "geometry", "fragment", software=True)], ["c"])
    plan.add(0, "atomic_min", "c", 4, np.array([3, 1, 1, 3]), lambda i, s: pixels[i] * 4, 4, dep=True)
    gpu = load_gpu("gtx280", SIMPLE + ["raster.setup_instructions=0", "raster.pixel_instructions=0"])
    result = _Result(plan, {"c": 64 * 64 * 4})
    work = Workload(plan, result.bases(), 64, 64, pixels, prims, triangles=2)
    full = Machine(gpu, lower(work, gpu), 64).run()
    bounds, extra = _PassTimer(result, work, gpu).time(0)["terms"]
    prefix = (1 + 100 + 1) + (1 + 100 + 3)         # the warp's 2 triangles' indices (32 B), vertices (96 B)
    assert bounds["latency"] == prefix + 6 * (1 + 50)
    assert abs(bounds["latency"] / full - 1) < 0.02, (bounds["latency"], full)


def test_a_triangle_threads_iteration_runs_each_group_as_often_as_its_busiest_lane():
    # two triangles of one fragment each in one warp: the first's fragment loads 2 words and then stores (the
    # store waits for the loads), the second's loads 40 words and stores nothing (FreePipe MDTS's colour pass:
    # a dropped fragment searches every entry). SIMT: the warp issues the 40 loads, then the store waits for
    # the last of them, whichever lane's: 40 + (100 + 1) + 1 cycles, not the longest lane's max(2 + 101 + 1, 40)
    # (a load's round trip is its instructions' mean: the first 2 send both lanes' requests to one partition,
    # 1.05 requests of a cycle each)
    pixels, prims = np.array([1, 2]), np.array([0, 1])
    plan = OpPlan([Pass("draw", "geometry", "fragment", software=True)], ["a", "fb"])
    plan.add(0, "load", "a", 2, np.array([2, 40]), lambda i, s: (i * 64 + s) * 4, 4)
    writers = np.array([0])
    plan.add(0, "store", "fb", writers, 1, lambda i, s: pixels[writers[i]] * 4, 4, dep=True)
    gpu = load_gpu("gtx280", SIMPLE + ["raster.setup_instructions=0", "raster.pixel_instructions=0"])
    result = _Result(plan, {"a": 2 * 64 * 4, "fb": 64 * 64 * 4})
    work = Workload(plan, result.bases(), 64, 64, pixels, prims, triangles=2)
    full = Machine(gpu, lower(work, gpu), 64).run()
    bounds, extra = _PassTimer(result, work, gpu).time(0)["terms"]
    prefix = (1 + 100 + 1) + (1 + 100 + 3)         # the warp's 2 triangles' indices (32 B), vertices (96 B)
    assert bounds["latency"] == pytest.approx(prefix + 40 + (100 + 1.05) + 1)
    assert abs((bounds["latency"] + extra) / full - 1) < 0.02, (bounds["latency"], extra, full)


def test_a_simt_loop_indexes_its_iterations_densely_or_ranked_alike():
    # three warps of 2-lane loops (fragments' warp instructions from their triangles), two groups: one on every
    # fragment, one on some with counts of their own and a wait; the iterations indexed by warp instruction
    # (dense) or by rank among those run give the same cycles per warp
    from gpusim.hw.analytic import _SimtLoop, _loop_instructions
    tri = np.array([0, 0, 0, 1, 2, 2, 3, 4, 4, 4, 4])
    inst, iterations = _loop_instructions(tri, 2)
    frag_inst = np.zeros(len(tri) + 3, np.int64)
    frags = slice(0, len(tri))
    frag_inst[frags] = inst
    some = np.array([1, 2, 4, 8, 9])
    got = []
    for dense in (True, False):
        loop = _SimtLoop(frags, frag_inst, iterations, 3, dense=dense)
        loop.add(frags, 1, 2.0, 0.0)
        loop.add(some, np.array([3, 1, 5, 2, 4]), 1.0, 10.0)
        got.append(loop.per_warp())
    # warp 0 (triangles 0, 1): iterations 0-2, each 2 + the second group's most there (0, 3, 1), waits on 2
    # warp 1 (2, 3): iterations 0-1, 2 each + (5 + 10) at iteration 0; warp 2 (4): iterations 0-3 + (2, 4) and waits
    assert got[0].tolist() == got[1].tolist() == [3 * 2 + 3 + 1 + 2 * 10, 2 * 2 + 5 + 10, 4 * 2 + 2 + 4 + 2 * 10]


def test_warps_resident_together_go_through_their_groups_in_step():
    # 30 warps, one on each of 30 SMs, walk 4 dependent loads of 64 B (every warp a round trip apart, so the
    # DRAM serves them in turn and they all end the walk together), then each runs 2,000 ALU cycles on its SM,
    # then stores a word: the groups' units do not overlap, the phases add up: 7,680 + 2,000 + 120 cycles
    n = 30 * 32
    plan = OpPlan([Pass("resolve", "fullscreen", "pixel")], ["a", "fb"])
    plan.add(0, "load", "a", n, 4, lambda i, s: (i * 4 + s) * 64, 64, dep=True)
    plan.compute(0, n, np.full(n, 2000))
    plan.add(0, "store", "fb", n, 1, lambda i, s: i * 4, 4, dep=True)
    full, rec, terms = _both(plan, {"a": n * 4 * 64, "fb": n * 4}, n, ["core.sms=30"])
    (bounds, extra), = terms
    assert bounds["phases"] == n * 4 * 64 / 32 + 2000 + n * 4 / 32 and bounds["dram"] == 7800
    assert rec["passes"][0]["bound"] == "phases"
    assert abs(rec["total"] / full - 1) < 0.01, (rec["total"], full)           # the full model: 9,884 cycles


def test_triangle_loops_over_a_screen_wide_triangle_number_their_instructions_past_27_bits():
    """A software rasterizer's thread over a triangle covering the screen loops over a hundred thousand of its
    pixels, so its warps' instructions (warp x iterations + iteration, times a fragment's operations) pass 2**27:
    the coalescer's and the atomic words' keys must not overflow (an internal error on the bunny scene, whose
    opaque wall is two such triangles)."""
    from gpusim.hw.analytic import _instruction_words, _requests
    big = np.array([(1 << 30) + 5, (1 << 30) + 5, 3, (1 << 30) + 5, 3], np.int64)
    word = np.array([8, 8, 8, 12, 8], np.int64)
    inst, per_word = _instruction_words(big, word)
    assert inst.tolist() == [3, (1 << 30) + 5, (1 << 30) + 5] and per_word.tolist() == [2, 2, 1]
    keys, nbytes = _requests(big, word * 4, np.full(5, 4, np.int64), 64)
    assert len(keys) == 2 and (keys >= 0).all()


def _requests_by_loop(inst, addr, nbytes, segment):
    """The coalescer's requests written the plain way: every byte range cut at each segment boundary, summed per
    (instruction, segment), rounded up to 32-byte sectors, at most the segment."""
    touched: dict[tuple[int, int], int] = {}
    for i, a, n in zip(inst.tolist(), addr.tolist(), nbytes.tolist()):
        for s in range(a // segment, (a + n - 1) // segment + 1):
            part = min(a + n, (s + 1) * segment) - max(a, s * segment)
            touched[i, s] = touched.get((i, s), 0) + part
    keys = sorted(touched)
    return (np.array([(i << 36) + s for i, s in keys], np.int64),
            np.array([min(-(-touched[k] // 32) * 32, max(segment, 32)) for k in keys], np.int64))


@pytest.mark.parametrize("widths", [(4,), (20,), (4, 8, 16), (20, 70)])
@pytest.mark.parametrize("seed", range(4))
def test_requests_match_the_plain_coalescing(widths, seed):
    # accesses within a segment, over one boundary, over several; equal or mixed sizes; lanes in any order
    rng = np.random.default_rng(seed)
    n = 500
    inst = rng.integers(0, 40, n).astype(np.int64)
    nbytes = rng.choice(np.array(widths, np.int64), n)
    addr = rng.integers(0, 4096, n).astype(np.int64) * (4 if seed % 2 else 1)
    if seed == 0:
        inst = np.sort(inst)
    from gpusim.hw.analytic import _requests
    for segment in (32, 128):
        keys, got = _requests(inst, addr, nbytes, segment)
        want_keys, want = _requests_by_loop(inst, addr, nbytes, segment)
        np.testing.assert_array_equal(keys, want_keys)
        np.testing.assert_array_equal(got, want)


def test_the_issue_bound_is_the_busiest_scheduler_port():
    # 2 SMs of 4 schedulers: warps 0..5 go to SMs 0,1,0,1,0,1 and keep slots 0,0,1,1,2,2, so ports 0,4,1,5,2,6;
    # SM 0's three warps of 10, 20, 30 cycles sit on three ports: the busiest is 30, not (10 + 20 + 30) / 4
    from types import SimpleNamespace

    from gpusim.hw.analytic import _busiest_port
    c = SimpleNamespace(sms=2, schedulers=4, warps_per_sm=8)
    per_warp = np.array([10.0, 1.0, 20.0, 1.0, 30.0, 1.0])
    assert _busiest_port(per_warp, c) == 30.0
    # more warps than an SM's slots: they take slots as they free, so its schedulers share its issue evenly
    c = SimpleNamespace(sms=2, schedulers=4, warps_per_sm=2)
    assert _busiest_port(per_warp, c) == (10 + 20 + 30) / 4
    # one scheduler: the SM's issue is its port's
    c = SimpleNamespace(sms=2, schedulers=1, warps_per_sm=8)
    assert _busiest_port(per_warp, c) == 60.0


def _blends():
    # 100 warps x 32 lanes blend 4-byte pixels one after another (tests/test_hw_units.py's stream)
    plan = OpPlan([Pass("blend", "fullscreen", "pixel")], ["fb"])
    plan.add(0, "blend", "fb", 3200, 1, lambda i, s: i * 4, 4)
    return plan


def test_rop_framebuffer_traffic_is_a_dram_bound():
    # no L2: each instruction's 4 sectors read and written, 25,600 B at 32 B/cycle = 800 cycles, as at full
    full, rec, terms = _both(_blends(), {"fb": 3200 * 4}, 3200, ["rop.ops_per_cycle=100.0"])
    assert full == 800
    assert rec["units"]["dram"]["busy_cycles"] == pytest.approx(800)
    assert rec["passes"][0]["bound"] == "dram" and rec["total"] == pytest.approx(full, rel=0.15)


def test_rop_framebuffer_traffic_goes_through_the_l2():
    # with the 32-line L2: 800 requests of 32 B through the slice at 16 B/cycle = 1,600 cycles; a line's first
    # read misses (100 lines), the other 7 requests on it hit; 68 of the misses evict a dirty line
    full, rec, terms = _both(_blends(), {"fb": 3200 * 4}, 3200, ["rop.ops_per_cycle=100.0", *L2])
    assert full == pytest.approx(1600, abs=40)
    assert rec["passes"][0]["bound"] == "l2" and rec["total"] == pytest.approx(full, rel=0.1)


def test_atomics_that_read_and_write_dram_load_its_channel():
    # 3,200 atomics on distinct words with atomic.dram_rmw: 64 B each through the one channel at 32 B/cycle,
    # 6,400 cycles, the bound that decides (the unit itself serves 100 a cycle)
    plan = OpPlan([Pass("count", "fullscreen", "pixel")], ["c"])
    plan.add(0, "atomic_inc", "c", 3200, 1, lambda i, s: i * 4, 4)
    full, rec, terms = _both(plan, {"c": 3200 * 4}, 3200, ["atomic.dram_rmw=true"])
    (bounds, _), = terms
    assert bounds["dram"] == 6400 and rec["passes"][0]["bound"] == "dram"
    assert rec["units_built"] == ["dram", "atomic"] and rec["units"]["dram"]["busy_cycles"] == 6400
    assert abs(rec["total"] / full - 1) < 0.02, (rec["total"], full)
