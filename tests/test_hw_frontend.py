"""The geometry front end, helper lanes of 2x2 quads, the software rasterizer and the driver's pass cost,
against hand-computed timelines."""

from __future__ import annotations

import numpy as np
import pytest

from gpusim.hw import load_gpu
from gpusim.hw.analytic import analytic_timing
from gpusim.hw.lower import Workload, fragment_lanes, lower
from gpusim.hw.machine import Machine
from gpusim.hw.raster import bbox_pixels, emission, per_triangle_cycles, quad_ids
from gpusim.opplan import OpPlan, Pass, layout_bases

from test_hw_units import SIMPLE

WIDTH = 64


class _Result:
    """What the analytic level reads from a scheme result."""

    def __init__(self, plan, bases):
        self.plan, self._bases = plan, bases

    def bases(self):
        return self._bases


def _draw(pixels, prims, triangles, software=False, extra=()):
    """One geometry pass in which every fragment stores 4 bytes at its pixel."""
    plan = OpPlan([Pass("draw", "geometry", "fragment", software=software)], ["fb"])
    pixels = np.asarray(pixels, np.int64)
    plan.add(0, "store", "fb", len(pixels), 1, lambda i, s: pixels[i] * 4, 4)
    gpu = load_gpu("gtx280", SIMPLE + list(extra))
    bases = layout_bases(plan.structures, {"fb": WIDTH * WIDTH * 4})
    work = Workload(plan, bases, WIDTH, WIDTH, pixels, np.asarray(prims, np.int64), triangles=triangles)
    return plan, gpu, work, bases


def _run(gpu, work):
    m = Machine(gpu, lower(work, gpu), WIDTH)
    return m.run(), m


def test_a_pass_lasts_as_long_as_its_front_end():
    # 1,000 triangles submitted, 10 of them cover one pixel each: setup at 0.5 triangles/cycle takes 2,000 cycles,
    # far more than the 10 fragments' stores (one warp, 100 cycles of latency)
    plan, gpu, work, _ = _draw(np.arange(10) * 2, np.arange(10) * 100, 1000,
                               extra=["raster.triangles_per_cycle=0.5", "raster.vertex_instructions=0",
                                      "raster.vertex_bytes=0"])
    assert per_triangle_cycles(gpu) == 2.0
    cycles, m = _run(gpu, work)
    assert cycles == 2000
    assert m.units["raster"].summary(cycles)["requests"] == 1000


def test_the_slowest_front_end_stage_decides():
    # vertex shading on the one SM's 32 lanes: 3 vertices x 64 instructions / 32 lanes = 6 cycles per triangle;
    # fetch: 3 x 64 B at 32 B/cycle = 6 cycles; setup 1 cycle: 6 cycles per triangle
    extra = ["raster.triangles_per_cycle=1", "raster.vertices_per_triangle=3", "raster.vertex_instructions=64",
             "raster.vertex_bytes=64"]
    _, gpu, _, _ = _draw([0], [0], 1, extra=extra)
    assert per_triangle_cycles(gpu) == 6.0
    _, gpu, _, _ = _draw([0], [0], 1, extra=extra + ["raster.vertex_lanes=96"])      # dedicated vertex lanes
    assert per_triangle_cycles(gpu) == 6.0                                              # fetch still 6
    _, gpu, _, _ = _draw([0], [0], 1, extra=extra + ["raster.vertex_lanes=96", "raster.vertex_bytes=16"])
    assert per_triangle_cycles(gpu) == 2.0                                              # 3 x 64 / 96


def test_vertices_from_host_memory_cross_the_bus():
    # client-side arrays: 3 x 4 B of indices and half a 16 B vertex per triangle (a closed mesh's vertex array),
    # 20 B at 4 B/cycle = 5 cycles per triangle, whatever the post-transform cache and the DRAM channels do;
    # 1,000 triangles keep the pass's 10 stores waiting 5,000 cycles
    extra = ["raster.triangles_per_cycle=1", "raster.vertex_instructions=0", "raster.vertex_bytes=16",
             "raster.vertices_per_triangle=3", "raster.vertex_source=host", "raster.host_bytes_per_cycle=4"]
    plan, gpu, work, bases = _draw(np.arange(10) * 2, np.arange(10) * 100, 1000, extra=extra)
    assert per_triangle_cycles(gpu) == 5.0
    cycles, _ = _run(gpu, work)
    assert cycles == 5000
    assert analytic_timing(_Result(plan, bases), work, gpu)["passes"][0]["bound"] == "raster"
    _, gpu, _, _ = _draw([0], [0], 1, extra=extra[:-2])                     # the same mesh from device memory
    assert per_triangle_cycles(gpu) == 3 * 16 / 32


def test_quads_bound_the_rasterizer():
    # one triangle covering a 16x16 block: 64 quads at 0.5 quads/cycle = 128 cycles
    px = (np.arange(16)[:, None] * WIDTH + np.arange(16)[None, :]).ravel()
    plan, gpu, work, bases = _draw(px, np.zeros(len(px)), 1, extra=["raster.quads_per_cycle=0.5"])
    prog = lower(work, gpu)
    assert prog.passes[0].quads == 64
    m = Machine(gpu, prog, WIDTH)
    assert m.run() >= 128
    rec = analytic_timing(_Result(plan, bases), work, gpu)
    assert rec["passes"][0]["bound"] == "raster"


def test_partial_quads_fill_warps_with_helper_lanes():
    # 32 fragments in 8 full quads fill one warp; 32 fragments each alone in its quad need 4 warps (128 lanes)
    full = np.array([2 * (q // 8) * WIDTH + 2 * (q % 8) + dy * WIDTH + dx for q in range(8)
                     for dy in (0, 1) for dx in (0, 1)])
    sparse = np.arange(32) * 2
    for pixels, quads, warps in ((full, 8, 1), (sparse, 32, 4)):
        _, gpu, work, _ = _draw(pixels, np.zeros(32), 1)
        prog = lower(work, gpu)
        assert (prog.passes[0].quads, prog.passes[0].warps) == (quads, warps)


TILES = ["raster.warp_packing=tiles"]


def test_tile_owners_fill_warps_with_their_own_quads():
    # warp_packing = tiles: 32 fragments in 8 full quads of one 8x8 tile fill one warp; 32 fragments each alone
    # in its quad (every other pixel of row 0, x = 0..62) are 4 quads in each of 8 tiles, dealt to 8 owners
    # (10 on gtx280): a warp each, 8 warps
    full = np.array([(2 * (q // 4) + dy) * WIDTH + 2 * (q % 4) + dx for q in range(8)
                     for dy in (0, 1) for dx in (0, 1)])
    sparse = np.arange(32) * 2
    for pixels, quads, warps in ((full, 8, 1), (sparse, 32, 8)):
        plan, gpu, work, bases = _draw(pixels, np.zeros(32), 1, extra=TILES)
        prog = lower(work, gpu)
        assert (prog.passes[0].quads, prog.passes[0].warps) == (quads, warps)
        assert analytic_timing(_Result(plan, bases), work, gpu)["passes"][0]["warps"] == warps
    # with one owner the 32 quads pack 8 to a warp, whatever their tile
    _, gpu, work, _ = _draw(sparse, np.zeros(32), 1, extra=[*TILES, "raster.tile_owners=1"])
    assert lower(work, gpu).passes[0].warps == 4


def test_rasterizer_emits_a_triangle_tile_by_tile_in_morton_order():
    # one triangle over a 16x2 block, its fragments in the trace's row order: the rasterizer emits the left tile's
    # 16 fragments (quads in Morton order, each quad's 4 pixels in Morton order), then the right tile's
    x, y = np.meshgrid(np.arange(16), np.arange(2))
    pixels = (y * WIDTH + x).ravel()
    order, owner, _ = emission(np.zeros(32, np.int64), pixels, WIDTH, WIDTH, 8, 2)
    ex, ey = pixels[order] % WIDTH, pixels[order] // WIDTH
    assert list(zip(ex[:8], ey[:8])) == [(0, 0), (1, 0), (0, 1), (1, 1), (2, 0), (3, 0), (2, 1), (3, 1)]
    assert (ex[:16] < 8).all() and (ex[16:] >= 8).all()
    assert (owner[order] == np.repeat([0, 1], 16)).all()
    # the two tiles have two owners: a warp each (8 quads would fit, 4 are there)
    _, gpu, work, _ = _draw(pixels, np.zeros(32), 1, extra=TILES)
    assert lower(work, gpu).passes[0].warps == 2


def test_an_owner_packs_quads_of_its_tiles_from_several_triangles():
    # 6 one-quad triangles: tiles (0, 0), (0, 0), (1, 0), (0, 0), (2, 0), (0, 0) on 2 owners (x + y mod 2): owner 0
    # takes 5 quads (tiles 0 and 2), owner 1 one; at warp_size 32 (8 quads a warp) one warp each, numbered by
    # their first quads (owner 0's first); at warp_size 8 (2 quads a warp) owner 0 fills 3 warps, in the order
    # their quads come: 0 1 | owner 1's | 3 4 | 5
    quad = np.array([0, 1, WIDTH, WIDTH + 1])
    at = [(0, 0), (2, 0), (8, 0), (4, 0), (16, 0), (6, 0)]
    pixels = np.concatenate([quad + yy * WIDTH + xx for xx, yy in at])
    prims = np.repeat(np.arange(6), 4)
    _, owner, _ = emission(prims, pixels, WIDTH, WIDTH, 8, 2)
    assert list(owner[::4]) == [0, 0, 1, 0, 0, 0]
    for extra, warps in (([], [0, 0, 1, 0, 0, 0]), (["core.warp_size=8", "scoreboard.entries=8"],
                                                    [0, 0, 1, 2, 2, 3])):
        _, gpu, work, _ = _draw(pixels, prims, 6, extra=[*TILES, "raster.tile_owners=2", *extra])
        got = fragment_lanes(work, gpu, np.arange(24))
        assert list(got.warp[np.argsort(got.keys)][::4]) == warps
        assert lower(work, gpu).passes[0].warps == max(warps) + 1


def test_a_warp_never_holds_two_tiles_that_share_an_edge():
    # random small triangles: on every owner count above 1 no warp holds quads of two edge-adjacent tiles, in the
    # run or in a sample of whole tiles (whose warps then coalesce as the run's do: no segment of one tile row
    # is shared with a neighbour's lanes)
    rng = np.random.default_rng(3)
    n_tri = 400
    prims = np.repeat(np.arange(n_tri), 12)
    cx, cy = rng.integers(0, WIDTH - 4, n_tri), rng.integers(0, WIDTH - 3, n_tri)
    pixels = np.concatenate([(cy[t] + np.arange(3))[:, None] * WIDTH + cx[t] + np.arange(4) for t in range(n_tri)]
                            ).ravel()
    tx, ty = pixels % WIDTH // 8, pixels // WIDTH // 8
    tile = ty * (WIDTH // 8) + tx
    kept = np.flatnonzero(np.isin(tile, [3, 4, 9, 10, 11, 27, 40, 63]))
    for owners in (2, 3, 10):
        _, gpu, work, _ = _draw(pixels, prims, n_tri, extra=[*TILES, f"raster.tile_owners={owners}"])
        for lanes in (np.arange(len(pixels)), kept):
            got = fragment_lanes(work, gpu, lanes)
            assert sorted(got.keys) == list(lanes) and (np.diff(got.warp) >= 0).all()
            for w in np.unique(got.warp):
                mine = got.keys[got.warp == w]
                assert len(np.unique(quad_ids(prims[mine], pixels[mine], WIDTH, WIDTH))) <= 8
                tiles = set(zip(tx[mine], ty[mine]))
                assert not any((a + 1, b) in tiles or (a, b + 1) in tiles for a, b in tiles)


def test_software_rasterizer_runs_every_submitted_triangle():
    # 40 triangles submitted, only triangle 0 covers pixels (a 3x2 box): 2 warps of triangle threads, each
    # loading indices then vertices, the first scanning 6 pixels
    pixels = [0, 1, 2, WIDTH, WIDTH + 1, WIDTH + 2]
    _, gpu, work, _ = _draw(pixels, np.zeros(6), 40, software=True,
                            extra=["raster.setup_instructions=50", "raster.pixel_instructions=5"])
    prog = lower(work, gpu)
    assert prog.passes[0].warps == 2
    first, second = prog.warp(0), prog.warp(1)
    assert [i.op for i in first[:2]] == ["load", "load"] and first[2].cycles == 50 + 5 * 6
    assert [i.op for i in second[:2]] == ["load", "load"] and second[2].cycles == 50 + 5 * 1
    assert len(second) == 3                          # no fragments: loads and setup only
    assert list(bbox_pixels(np.zeros(6, np.int64), np.asarray(pixels), WIDTH, 3)) == [6, 1, 1]


def test_bounding_boxes_the_same_in_triangle_order_and_out_of_it():
    # fragments grouped by triangle take the runs' reductions, shuffled ones the scatter: the same boxes, and a
    # triangle without fragments (id 3) tests one pixel either way
    rng = np.random.default_rng(1)
    prim = np.sort(rng.choice(np.array([0, 1, 2, 4]), 200))
    pixel = rng.integers(0, 64 * 64, 200)
    grouped = bbox_pixels(prim, pixel, 64, 5)
    shuffle = rng.permutation(200)
    assert list(grouped) == list(bbox_pixels(prim[shuffle], pixel[shuffle], 64, 5))
    assert grouped[3] == 1 and (grouped[[0, 1, 2, 4]] > 1).all()


def test_setup_waits_for_the_vertices():
    # one warp, one triangle: the index load (1 segment + 100 latency), the vertex load after it (48 B: 2 segments
    # + 100), setup, then the fragment's store (1 + 100). Setup works on the vertices, so it cannot hide in the
    # loads' latency: each of its cycles adds one.
    def cycles(setup):
        _, gpu, work, _ = _draw([0], [0], 1, software=True,
                                extra=[f"raster.setup_instructions={setup}", "raster.pixel_instructions=0"])
        return _run(gpu, work)[0]
    assert cycles(0) == (1 + 100) + (2 + 100) + (1 + 100)
    assert cycles(50) == cycles(0) + 50


def test_the_driver_pays_each_pass():
    plan = OpPlan([Pass("a", "fullscreen", "pixel"), Pass("b", "fullscreen", "pixel")], ["fb"])
    plan.add(0, "store", "fb", 32, 1, lambda i, s: i * 4, 4)
    plan.add(1, "store", "fb", 32, 1, lambda i, s: i * 4, 4)
    bases = layout_bases(plan.structures, {"fb": 128})
    base = None
    for us in (0.0, 1.0):
        gpu = load_gpu("gtx280", SIMPLE + [f"driver.pass_us={us}", "core.clock_mhz=1000"])
        work = Workload(plan, bases, WIDTH, WIDTH, np.zeros(0, np.int64), np.zeros(0, np.int64), triangles=0)
        cycles, _ = _run(gpu, work)
        ana = analytic_timing(_Result(plan, bases), work, gpu)["total"]
        if base is None:
            base, ana_base = cycles, ana
    assert cycles - base == 2 * 1000                  # 1 us at 1,000 MHz before each of the 2 passes
    assert ana - ana_base == 2 * 1000


def test_alu_work_runs_as_long_as_the_busiest_lane():
    # a resolve thread per pixel: load (100 latency), then 10 / 30 / 0 ALU instructions on its value, then a store;
    # the warp issues the busiest lane's 30 after the load returns
    plan = OpPlan([Pass("resolve", "fullscreen", "pixel")], ["fb"])
    plan.add(0, "load", "fb", 3, 1, lambda i, s: i * 4, 4)
    plan.compute(0, 3, [10, 30, 0])
    plan.add(0, "store", "fb", 3, 1, lambda i, s: i * 4, 4, dep=True)
    assert plan.accesses() == {"fb": {"load": 3, "store": 3}} and plan.total_ops() == 6
    bases = layout_bases(plan.structures, {"fb": 64})
    gpu = load_gpu("gtx280", SIMPLE)
    work = Workload(plan, bases, WIDTH, WIDTH, np.zeros(0, np.int64), np.zeros(0, np.int64), triangles=0)
    prog = lower(work, gpu)
    from gpusim.hw.program import Compute
    assert prog.warp(0)[1] == Compute(30)
    assert prog.operations == 6
    cycles, _ = _run(gpu, work)
    assert cycles == (1 + 100) + 30 + (1 + 100)
    rec = analytic_timing(_Result(plan, bases), work, gpu)
    assert rec["passes"][0]["cycles"] >= 30


def test_alu_instructions_issue_at_the_lanes_issue_width():
    # the same resolve on lanes that issue 4 ALU instructions a cycle (G71's two co-issuing vec4 units): the
    # busiest lane's 30 take ceil(30 / 4) = 8 cycles; a memory instruction keeps its cycle of the port, and the 4
    # ALU instructions around it (core.instructions_per_op) hold the port 1 cycle more
    plan = OpPlan([Pass("resolve", "fullscreen", "pixel")], ["fb"])
    plan.add(0, "load", "fb", 3, 1, lambda i, s: i * 4, 4)
    plan.compute(0, 3, [10, 30, 0])
    plan.add(0, "store", "fb", 3, 1, lambda i, s: i * 4, 4, dep=True)
    bases = layout_bases(plan.structures, {"fb": 64})
    work = Workload(plan, bases, WIDTH, WIDTH, np.zeros(0, np.int64), np.zeros(0, np.int64), triangles=0)
    gpu = load_gpu("gtx280", SIMPLE + ["core.alu_issue_width=4"])
    from gpusim.hw.program import Compute
    assert lower(work, gpu).warp(0)[1] == Compute(8)
    cycles, _ = _run(gpu, work)
    assert cycles == (1 + 100) + 8 + (1 + 100)
    gpu = load_gpu("gtx280", SIMPLE + ["core.alu_issue_width=4", "core.instructions_per_op=4"])
    assert gpu.core.op_issue_cycles == 1 + 1 and gpu.core.alu_cycles(np.array([30, 3])).tolist() == [8, 1]
    assert analytic_timing(_Result(plan, bases), work, gpu)["passes"][0]["cycles"] >= 8 + 2 * 2


def test_software_rasterizer_through_an_l2():
    # the vertex buffers sit above every structure, and their segments must stay addressable on the L2 path
    # (32-byte segments on `modern`)
    plan, _, work, _ = _draw(np.arange(40) % 7, np.arange(40) // 2, 64, software=True)
    gpu = load_gpu("modern", ["driver.pass_us=0"])
    cycles, m = _run(gpu, work)
    assert cycles > 0 and m.units["l2"].summary(cycles)["requests"] > 0


def test_quads_so_far_in_one_pass_is_the_sorts():
    """The compiled one-pass count of the quads emitted so far (triangles in order) gives what the stable sort of
    (triangle, quad) keys gives, and a trace whose triangles are out of order takes the sort."""
    from types import SimpleNamespace

    import gpusim.hw.lower as lower_module
    rng = np.random.default_rng(4)
    for trial in range(60):
        w, h = (int(v) for v in rng.integers(1, 30, 2))
        n = int(rng.integers(1, 2000))
        prim = np.sort(rng.integers(0, int(rng.integers(1, 100)), n))
        if trial % 3 == 0:
            prim = rng.permutation(prim)                      # out of order: the sort path
        work = SimpleNamespace(frag_prim=prim, frag_pixel=rng.integers(0, w * h, n), width=w, height=h)
        keys = np.arange(n)
        q = quad_ids(prim, work.frag_pixel, w, h)
        expected = np.cumsum(np.isin(np.arange(n), np.unique(q, return_index=True)[1]))   # each quad's first
        assert np.array_equal(lower_module._quads_so_far(work, keys), expected), trial
        quad = q - prim * ((w + 1) // 2 * ((h + 1) // 2))
        if trial % 3:
            first = lower_module._first_in_quads(prim.astype(np.int64), quad, (w + 1) // 2 * ((h + 1) // 2))
            assert np.array_equal(np.cumsum(first), expected), trial       # the kernel's numpy-free source


def test_jit_start_runs_once_and_leaves_the_kernels_results_alone(monkeypatch):
    """gpusim.jit.start starts numba once per process (an experiment's task calls it before what it times)."""
    import gpusim.jit as jit
    calls = []
    monkeypatch.setattr(jit, "_STARTED", [])
    monkeypatch.setattr(jit, "njit", lambda f: calls.append(f) or f)
    jit.start()
    jit.start()
    assert calls == [jit._ping] and jit._STARTED == [True]
    assert jit._ping(1) == 2
