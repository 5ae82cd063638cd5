"""The ALU work (OpPlan.compute) each scheme declares, against hand counts from gpusim.schemes.common.alu.

The tiny traces: a 4x2 screen, pixel 0 with fragments at depths 0.5, 0.2, 0.9
(fragments 0, 1, 3), pixel 1 with 0.7, 0.3 (fragments 2, 4), pixel 6 with 0.4
(fragment 5); the opaque variant adds an opaque fragment at depth 0.5 on
pixel 1, submitted last (fragment 6). Per pixel: 3, 2, 0, 0, 0, 0, 1, 0.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from conftest import make_trace

from gpusim.schemes import make_scheme, scheme_names
from gpusim.schemes.common.alu import (COMPARE_EXCHANGE, COMPOSITE, DUAL_PEEL_TEST, HALF_BLOCK_START,
                                       L1_SPAN_LOADS, LEADING_ZEROS, LEADING_ZEROS_DECODE, PACK_DEPTH_COLOUR,
                                       PEEL_TEST, PREMULTIPLY, RECIRCULATE_TEST, SHADE_SAMPLE, SHADE_STEP,
                                       UNPACK_RGBA8, UNPACK_ROW_SAMPLE, UNPACK_ROWS, UNPACK_SEGMENT,
                                       UNPACK_SPLIT_RGB24, WBOIT_RESOLVE, WBOIT_WEIGHT, WEIGHT_FACTOR_PAIR,
                                       compare_exchange, finish_work, lucid_sort_work, reduce_step,
                                       weight_factor_work)
from gpusim.schemes.common.kbuffer_entries import DEPTH_CUE

COUNT = np.array([3, 2, 0, 0, 0, 0, 1, 0])      # fragments per pixel of the tiny trace


def tiny(opaque=False):
    xs, ys, zs = [0, 0, 1, 0, 1, 2], [0, 0, 0, 0, 0, 1], [0.5, 0.2, 0.7, 0.9, 0.3, 0.4]
    op = [False] * 6
    if opaque:
        xs, ys, zs, op = xs + [1], ys + [0], zs + [0.5], op + [True]
    return make_trace(xs, ys, zs, width=4, height=2, opaque=op)


def run(name, trace=None, **params):
    return make_scheme(name, params).run(tiny() if trace is None else trace)


def computes(result):
    """The compute groups in program order, one entry per group and pass: (pass, {thread: instructions})."""
    out = []
    for g in result.plan.groups:
        if g.is_compute:
            i, seq = g.expand_ops()          # a group spanning passes (seq_pass) runs its work once in each
            threads, work = g.thread_ids()[i], np.asarray(g.instructions)[i]
            passes = np.broadcast_to(g.pass_of(i, seq), threads.shape)
            for p in np.unique(passes):
                sel = passes == p
                assert len(np.unique(threads[sel])) == sel.sum()
                out.append((int(p), dict(zip(threads[sel].tolist(), work[sel].tolist()))))
    return out


def per_pixel(values):
    return dict(enumerate(np.asarray(values).tolist()))


def test_compare_exchange_moves_the_payload_registers_and_weight_factors_count_pairs():
    assert compare_exchange(4) == COMPARE_EXCHANGE          # a packed rgba8 colour: one register
    assert compare_exchange(8) == 7 and compare_exchange(16) == 11
    assert weight_factor_work(np.array([0, 1, 3])).tolist() == [0, COMPOSITE, 3 * WEIGHT_FACTOR_PAIR + 3 * COMPOSITE]
    assert WBOIT_WEIGHT["constant"] == 0 and WBOIT_WEIGHT["eq10"] == 6


def test_freepipe_mdts_resolve_unpacks_and_composites_each_stored_entry():
    res = run("freepipe-mdts")                                 # rgba8 colour_array, second colour pass
    assert computes(res) == [(3, per_pixel(COUNT * (COMPOSITE + UNPACK_RGBA8)))]
    assert computes(run("freepipe-mdts", colour_format="rgba32f")) == [(3, per_pixel(COUNT * COMPOSITE))]
    # packing: each fragment packs its two words before the chains; the resolve re-joins the 12-bit halves
    res = run("freepipe-mdts", packing=True, layers=2, alpha=0.5)
    kept = np.minimum(COUNT, 2)
    assert computes(res) == [(1, {f: 2 * PACK_DEPTH_COLOUR for f in range(6)}),
                             (2, per_pixel(kept * (COMPOSITE + UNPACK_SPLIT_RGB24)))]
    assert res.plan.groups[2].is_compute and res.plan.groups[3].op == "atomic_min"   # before the chains


def test_kbuffer_inserts_with_k_compare_exchanges_of_its_entry_format():
    res = run("kbuffer", k=2)                                  # rgba32f entries: 11 instructions an exchange
    assert computes(res) == [(1, {f: 2 * 11 for f in range(6)}), (2, per_pixel(np.minimum(COUNT, 2) * COMPOSITE))]
    ops = [g.op for g in res.plan.groups]
    assert ops.index("compute") == ops.index("rmw_read") + 1 and ops[ops.index("compute") + 1] == "rmw_write"
    # sort-blend: the fragment that finds both entries full (fragment 3, third at pixel 0) composites the nearest
    res = run("kbuffer", k=2, mode="sort-blend", colour_format="rgba8")
    assert computes(res)[0] == (1, {0: 10, 1: 10, 2: 10, 3: 10 + COMPOSITE, 4: 10, 5: 10})
    # batches: the fragment work runs in each fragment's batch pass
    batched = computes(run("kbuffer", k=2, batch=2))
    assert [p for p, _ in batched] == [1, 3, 5, 6]
    assert sorted(t for _, w in batched[:3] for t in w) == list(range(6))
    # the programmable blender runs the program in the ROP: only the resolve is SM work
    assert computes(run("kbuffer", k=2, hw="blender")) == [(2, per_pixel(np.minimum(COUNT, 2) * COMPOSITE))]
    # RGBZ entries move 3 colour registers beside the depth (9 an exchange); Z-only entries the depth alone (3),
    # and the resolve makes each entry's grey 1 - z (DEPTH_CUE) before compositing it
    kept = np.minimum(COUNT, 2)
    assert computes(run("kbuffer", k=2, entry="rgbz")) == [(1, {f: 2 * 9 for f in range(6)}),
                                                           (2, per_pixel(kept * COMPOSITE))]
    assert computes(run("kbuffer", k=2, entry="z")) == [(1, {f: 2 * 3 for f in range(6)}),
                                                        (2, per_pixel(kept * (COMPOSITE + DEPTH_CUE)))]
    assert computes(run("kbuffer", k=2, entry="z", mode="sort-blend"))[0] == (
        1, {0: 6, 1: 6, 2: 6, 3: 6 + COMPOSITE + DEPTH_CUE, 4: 6, 5: 6})


def test_register_sorts_of_the_linked_list_and_the_stencil_routed_abuffer():
    # insertion sort, worst case m (m - 1) / 2 compare-exchanges of depth + rgba8, each node unpacked and composited
    ins = COUNT * (COUNT - 1) // 2
    assert computes(run("linked-list")) == [(2, per_pixel(ins * COMPARE_EXCHANGE + COUNT * (COMPOSITE + UNPACK_RGBA8)))]
    # a 2-entry local array: the walk stops at 2 nodes; bitonic sort of 2 is one compare-exchange
    short = np.minimum(COUNT, 2)
    assert computes(run("linked-list", resolve_max=2, sort="bitonic")) == [
        (2, per_pixel((short == 2) * COMPARE_EXCHANGE + short * (COMPOSITE + UNPACK_RGBA8)))]
    # SRAB: bitonic of 3 samples pads to 4: 2 x 2 x 3 / 2 = 6 compare-exchanges; of 2, one; texture reads
    assert computes(run("stencil-routed-abuffer")) == [(3, per_pixel([6 * 5 + 3 * COMPOSITE, 5 + 2 * COMPOSITE, 0, 0,
                                                                      0, 0, COMPOSITE, 0]))]
    assert computes(run("stencil-routed-abuffer", overflow_pass=False, colour_format="rgba16f", sort="insertion")) == [
        (2, per_pixel([3 * 7 + 3 * COMPOSITE, 7 + 2 * COMPOSITE, 0, 0, 0, 0, COMPOSITE, 0]))]


def test_wboit_evaluates_its_weight_per_fragment_and_divides_per_pixel():
    res = run("wboit")                                         # eq10, no opaque fragment: no pre-pass
    every = {f: WBOIT_WEIGHT["eq10"] + PREMULTIPLY for f in range(6)}
    assert computes(res) == [(0, every), (1, per_pixel([WBOIT_RESOLVE + COMPOSITE] * 8))]
    res = run("wboit", tiny(opaque=True), weight="eq7", near=1.0, far=10.0)
    # the pre-pass culls fragment 2 (0.7, behind the opaque 0.5); the framebuffer blend mixes in the opaque colour
    assert computes(res) == [(1, {f: WBOIT_WEIGHT["eq7"] + PREMULTIPLY for f in (0, 1, 3, 4, 5)}),
                             (2, per_pixel([WBOIT_RESOLVE] * 8))]
    assert computes(run("wboit", weight="constant"))[0][1] == {f: PREMULTIPLY for f in range(6)}
    assert computes(run("alpha-blend")) == [] and computes(run("alpha-blend", tiny(opaque=True))) == []


def test_peeling_tests_every_fragment_in_each_pass_after_the_first():
    res = run("depth-peeling")            # 3 layers: peel 0, blend 0, peel 1, blend 1, peel 2, blend 2
    everyone = {f: PEEL_TEST for f in range(6)}
    assert computes(res) == [(2, everyone), (4, everyone)]
    ops = [g.op for g in res.plan.groups]
    assert ops[:3] == ["load", "compute", "depth_test"]     # one group over the passes, between load and test
    query = run("depth-peeling", termination="occlusion-query")         # one more pass finds nothing left
    assert [p for p, _ in computes(query)] == [2, 4, 6]
    res = run("dual-depth-peeling")       # 2 peels: init, peel 1, peel 2, final
    assert computes(res) == [(1, {f: DUAL_PEEL_TEST for f in range(6)}), (2, {f: DUAL_PEEL_TEST for f in range(6)}),
                             (3, per_pixel([COMPOSITE] * 8))]


def test_rbuffer_compares_every_read_with_the_second_z():
    res = run("r-buffer")
    # passes until a fragment is blended (farthest first): pixel 0: 0.9 in 1, 0.5 in 2, 0.2 in 3; pixel 1: 0.7, 0.3
    assert computes(res) == [(2, {f: RECIRCULATE_TEST for f in range(6)}),
                             (3, {0: RECIRCULATE_TEST, 1: RECIRCULATE_TEST, 4: RECIRCULATE_TEST}),
                             (4, {1: RECIRCULATE_TEST})]
    reads = res.plan.accesses()["r_buffer"]["load"]
    assert sum(sum(w.values()) for _, w in computes(res)) == RECIRCULATE_TEST * reads


@pytest.mark.parametrize("name", ["tfss", "weight-factor"])
def test_weight_factors_compare_each_pair_of_visible_fragments(name):
    res = run(name, tiny(opaque=True))
    # the opaque 0.5 hides fragment 2 after it was stored: 3, 1 and 1 visible fragments on pixels 0, 1, 6
    wf = {0: 3 * WEIGHT_FACTOR_PAIR + 3 * COMPOSITE, 1: COMPOSITE, 6: COMPOSITE}
    assert computes(res) == [(2, wf)]
    if name == "tfss":
        res = run(name, tiny(opaque=True), leading_zero_elimination="fixed")
        assert computes(res) == [(1, {f: LEADING_ZEROS for f in range(6)}),
                                 (2, {0: wf[0] + 3 * LEADING_ZEROS_DECODE, 1: wf[1] + LEADING_ZEROS_DECODE,
                                      6: wf[6] + LEADING_ZEROS_DECODE})]


def test_lucidraster_sorts_each_block_and_filters_each_shaded_sample():
    # LucidRaster's counts follow its shaders stage by stage (tests/test_lucidraster.py checks each stage); here
    # one bin, one 8x8 block of 6 tri-blocks: more than the depth filter's 3, so its subgroup (the raster pass's
    # warp 0) sorts them, 6 keys padded to 32, with subgroup shuffles
    res = run("lucidraster")
    sort = lucid_sort_work(np.array([6]), np.array([32]), np.array([32]))[0]
    warp0 = {lane: sort for lane in range(32)}
    assert (4, warp0) in computes(res)
    assert (4, warp0) not in computes(run("lucidraster", depth_filter=6))     # the filter orders 6 itself
    # phase 3: the half-block's 6 samples in one step of 32 (shadeSample on every lane), pixel 0's 3 samples
    # through reduceSample in 3 iterations, one unpack iteration of the half-block's 6 tri-half-blocks
    unpack = UNPACK_SEGMENT + UNPACK_ROWS + UNPACK_ROW_SAMPLE
    for df in (1, 3):
        shade = (HALF_BLOCK_START + 2 * df + unpack + SHADE_STEP + SHADE_SAMPLE + L1_SPAN_LOADS
                 + 3 * reduce_step(df) + finish_work(df, 3))
        assert (4, {lane: shade for lane in range(32)}) in computes(run("lucidraster", depth_filter=df))


# access counts of the tiny traces as each scheme reported them before it declared any ALU work
BEFORE = json.loads((Path(__file__).parent / "fixtures" / "scheme_accesses_before_alu.json").read_text())["runs"]


def test_every_scheme_with_alu_work_here_is_checked_for_its_access_counts():
    # zbuffer came after the fixture was recorded and declares no ALU work; mlab, mboit and the bucket and
    # multi-pass k-buffer schemes came with their ALU work (their own tests assert their access counts)
    later = {"zbuffer", "mlab", "mboit", "bucket-depth-peeling", "adaptive-bucket-depth-peeling", "multipass-kbuffer"}
    assert {r["scheme"] for r in BEFORE} == set(scheme_names()) - {"freepipe-abuffer"} - later


# LucidRaster's plan was rebuilt from its shaders later (issue 17), with the memory operations they make:
# tests/test_lucidraster.py holds its counts
@pytest.mark.parametrize("before", [r for r in BEFORE if r["scheme"] != "lucidraster"],
                         ids=lambda r: f"{r['scheme']}-{r['params']}-opaque={r['opaque']}")
def test_declaring_alu_work_leaves_the_access_counts_as_they_were(before):
    res = run(before["scheme"], tiny(before["opaque"]), **before["params"])
    accesses = res.plan.accesses()
    assert accesses == before["accesses"]
    assert res.opstream().counts() == accesses
