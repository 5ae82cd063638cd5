"""The sampled fidelity level (gpusim.hw.sample): replicate stratified samples on a GPU cut down to a share of its
SMs, the 95% confidence interval from the replicates and the scale check, and the whole run when the fraction is 1."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from gpusim.hw import load_gpu
from gpusim.hw.lower import Census, Workload, _run_loads, _run_words, lower, plan_pieces, submission_warps
from gpusim.hw.memory.coalescer import memory_bytes
from gpusim.hw.sample import Keep, Replicates, run_traffic, sampled_sms, scaled_gpu, t_quantile
from gpusim.replay import replay, run_functional
from gpusim.scene import load_scene, trace_scene


@pytest.fixture(scope="module")
def spheres():
    """Ten nested spheres at 64x64 (depth complexity up to 20)."""
    scene, base = load_scene("nested-spheres", ["screen.width=64", "screen.height=64"])
    return trace_scene(scene, base, progress=False)


@pytest.mark.parametrize("dof, quantile", [(1, 12.7062), (2, 4.3027), (3, 3.1824), (4, 2.7764), (10, 2.2281),
                                           (30, 2.0423)])
def test_t_quantile_is_students(dof, quantile):
    # the two-sided 95% points of Student's t (any statistics table)
    assert t_quantile(0.975, dof) == pytest.approx(quantile, abs=1e-4)
    assert t_quantile(0.95, 1) == pytest.approx(6.3138, abs=1e-4)


@pytest.mark.parametrize("scheme, params", [("kbuffer", {"k": 8}), ("freepipe-abuffer", {}), ("linked-list", {}),
                                            ("depth-peeling", {})])
def test_a_fraction_of_one_is_the_full_level_with_a_zero_width_interval(spheres, scheme, params):
    gpu = load_gpu("gtx280", ["runner.workers=1", "sample.min_tiles=1"])
    whole = load_gpu("gtx280", ["runner.workers=1", "sample.fraction=1"])
    full = replay(spheres, scheme, params, "full", gpu)[1]["timing"]
    sampled = replay(spheres, scheme, params, "sampled", whole)[1]["timing"]
    assert sampled["cycles"] == full["cycles"]
    assert [p["cycles"] for p in sampled["passes"]] == [p["cycles"] for p in full["passes"]]
    assert sampled["cycles_ci95_low"] == sampled["cycles_ci95_high"] == full["cycles"]
    assert sampled["cycle_error_estimate"] == 0
    assert sampled["rmw_hazards"] == full["rmw_hazards"]
    for name, unit in full["units"].items():
        for key in ("requests", "busy_cycles"):
            if key in unit:
                assert sampled["units"][name][key] == pytest.approx(unit[key]), (name, key)
    # a smaller fraction is another figure, inside its own interval's reach of the full one's order
    part = replay(spheres, scheme, params, "sampled", gpu)[1]["timing"]
    assert part["sample"]["sms"] == 1 and part["cycles_ci95_low"] <= part["cycles"] <= part["cycles_ci95_high"]
    assert 0.5 < part["cycles"] / full["cycles"] < 2


def test_a_whole_sample_counts_a_multi_pass_schemes_hazards_in_every_pass():
    # the multi-pass k-buffer reads a pixel's entries again in each pass: more hazards than fragments, which a
    # sample that keeps the whole run reports as the full level does
    scene, base = load_scene("stress-layers", ["screen.width=16", "screen.height=16", "objects.1.layers=64"])
    deep = trace_scene(scene, base, progress=False)
    full = replay(deep, "multipass-kbuffer", {"k": 4}, "full", load_gpu("gtx280", ["runner.workers=1"]))[1]["timing"]
    whole = load_gpu("gtx280", ["runner.workers=1", "sample.fraction=1"])
    sampled = replay(deep, "multipass-kbuffer", {"k": 4}, "sampled", whole)[1]["timing"]
    assert full["rmw_hazards"] > len(deep.x)
    assert sampled["rmw_hazards"] == full["rmw_hazards"]
    assert sampled["rmw_hazard_pixels"] == full["rmw_hazard_pixels"]


def test_replicates_are_disjoint_stratified_samples(spheres):
    gpu = load_gpu("gtx280", ["sample.fraction=0.0625"])
    result, _, _ = run_functional(spheres, "kbuffer", {"k": 8})
    work = Workload.of(result, spheres)
    sms = sampled_sms(gpu)
    assert sms == 2
    reps = Replicates(work, gpu, sms / gpu.core.sms)
    tiles = reps.tiles
    assert tiles.shape[0] == gpu.sample.replicates
    present = reps.info["tiles"]
    assert (tiles.sum(axis=1) == round(present * sms / gpu.core.sms)).all()       # one tile per stratum
    overlap = tiles.sum(axis=0)
    deepest = reps.tile_of(reps.deepest)
    assert overlap[deepest] == gpu.sample.replicates              # the deepest pixel's tile: in every replicate
    assert (np.delete(overlap, deepest) <= 1).all()               # the others: in one replicate at most
    # the scale check's sample: replicates 0 and 1's together, pass by pass
    groups = [np.arange(len(work.frag_pixel))]
    pair = Keep(reps, (0, 1))(0, groups)[0]
    assert (pair == (Keep(reps, 0)(0, groups)[0] | Keep(reps, 1)(0, groups)[0])).all() and pair.any()


def test_a_sample_keeps_the_runs_load_on_each_shared_instance_and_word(spheres):
    # the linked list's global node counter: the sample keeps 1/30 of its increments, each holding the word 30
    # times as long, so its chain is the run's; each partition's load times its factor is the run's
    gpu = load_gpu("gtx280")
    result, _, _ = run_functional(spheres, "linked-list", {})
    work = Workload.of(result, spheres)
    small = scaled_gpu(gpu, 1)
    reps = Replicates(work, gpu, 1 / 30)
    pieces = plan_pieces(work)
    program = lower(work, small, Keep(reps, 0), pieces=pieces)
    whole = lower(work, gpu)
    rows, every = program.rows_of("atomic"), whole.rows_of("atomic")
    counter = np.bincount(np.unique(every.address, return_inverse=True)[1]).argmax()
    word = np.unique(every.address)[counter]
    hits = rows.address == word
    assert hits.any() and program.hold_scale[hits].sum() == pytest.approx((every.address == word).sum())
    # per pass and partition: the kept bytes times the factor are the run's bytes
    from gpusim.hw.atomic import DRAM_RMW_BYTES
    from gpusim.hw.unit import interleave
    assert gpu.atomic.dram_rmw
    mem = gpu.memory
    loads = []
    for prog in (program, whole):
        rws, (_, _, wi_row) = prog.rows_of("coalescer"), prog.storage("coalescer")
        load = np.zeros((len(prog.passes), mem.partitions))
        np.add.at(load, (prog.wi_pass[wi_row], interleave(rws.address, mem.interleave_bytes, mem.partitions)),
                  np.broadcast_to(rws.nbytes, rws.address.shape))
        # gtx280's atomics read and write their sectors in DRAM (atomic.dram_rmw): 64 B each on its partition
        arws, (_, _, awi_row) = prog.rows_of("atomic"), prog.storage("atomic")
        np.add.at(load, (prog.wi_pass[awi_row], interleave(arws.address, mem.interleave_bytes, mem.partitions)),
                  DRAM_RMW_BYTES)
        loads.append(load)
    has = loads[0] > 0
    assert has.sum() > 8 and np.allclose((loads[0] * program.occupancy["memory"])[has], loads[1][has])
    # the sample's own load, whose product with the factor less itself is the rest of the GPU's (gpusim.hw.background)
    assert np.allclose(program.own_load["memory"], loads[0])


def test_the_sampled_record_and_text_give_the_interval(tmp_path, spheres, capsys):
    from gpusim.cli import main
    from gpusim.trace_io import save_trace
    path = tmp_path / "s.npz"
    save_trace(spheres, path)
    assert main(["replay", str(path), "--scheme", "zbuffer", "--fidelity", "sampled"]) == 0
    text = capsys.readouterr().out
    assert "95% CI" in text and "the whole run, simulated once: its 60 tiles are too few" in text
    assert main(["replay", str(path), "--scheme", "zbuffer", "--fidelity", "sampled",
                 "--gpu-set", "sample.min_tiles=1"]) == 0
    text = capsys.readouterr().out
    assert "from 4 replicates of 1 SM each, 2 of 60 tiles" in text
    assert "from replicates 0 and 1 together on 2 SMs" in text
    assert main(["replay", str(path), "--scheme", "zbuffer", "--fidelity", "sampled",
                 "--gpu-set", "sample.min_tiles=1", "--gpu-set", "sample.scale_check=false"]) == 0
    text = capsys.readouterr().out
    assert "(error estimate" in text and ": standard error over the cycles, from 4 replicates" in text
    assert "machine-size bias" not in text and "thinned" not in text
    assert main(["replay", str(path), "--scheme", "zbuffer", "--fidelity", "sampled", "--gpu-set", "sample.tile=4",
                 "--gpu-set", "sample.min_tiles=1", "--gpu-set", "sample.thin=0.25",
                 "--gpu-set", "sample.thin_min_tiles=1"]) == 0
    text = capsys.readouterr().out
    assert "of their SMs' work and extrapolated to the whole by the work checks" in text
    assert "s on the whole run (its operations counted, its traffic sampled)" in text and "s replaying them" in text


def test_the_scale_check_takes_a_pass_end_to_grow_as_the_log_of_the_sms():
    # replicates 0 and 1 at 1,000 and 1,040 cycles on 2 SMs each, together 1,100 on 4, on a GPU of 32 SMs:
    # beta = (1,100 - 1,020) / ln 2, and the replicates' bias -beta x ln(32 / 2) = -80 x 4 = -320 cycles
    from gpusim.hw.sample import scale_check
    check = scale_check(np.array([1000.0, 1040.0, 990.0, 1010.0]), [2, 2, 2, 2], ({"cycles": [600, 500]}, 4), 32)
    assert check["bias_estimate"] == pytest.approx(-320.0)
    assert (check["sms"], check["cycles"], check["pair_cycles"], check["pair_sms"]) == (4, 1100, 1020.0, 2.0)
    assert scale_check(np.array([1000.0, 1040.0]), [2, 2], None, 32) is None


def test_a_replicate_is_thinned_only_where_it_keeps_enough_tiles():
    from gpusim.hw.sample import thinning
    gpu = load_gpu("gtx280", ["sample.thin=0.25", "sample.thin_min_tiles=16"])     # 30 SMs
    # a replicate on 1 SM of 2,304 tiles keeps 76.8 a share; a quarter of that is over 16 tiles
    assert thinning(gpu, 2304, 1) == 0.25
    assert thinning(gpu, 1000, 1) == pytest.approx(16 / (1000 / 30))      # raised to keep 16 tiles: 0.48
    assert thinning(gpu, 900, 1) == 1.0                  # 0.53: over 0.5, the work check would cost the gain
    assert thinning(gpu, 2304, 30) == 1.0                # the replicate is the run
    assert thinning(load_gpu("gtx280"), 2304, 1) == 0.25  # on by default
    assert thinning(load_gpu("gtx280", ["sample.thin=1"]), 2304, 1) == 1.0   # off
    # a software rasterizer's run samples triangle blocks too, and keeps as many of them: 188 blocks are 6.3 an SM
    assert thinning(gpu, 2304, 1, blocks=188) == 1.0
    assert thinning(gpu, 2304, 1, blocks=1500) == pytest.approx(16 / 50)
    assert thinning(gpu, 2304, 1, blocks=99_999) == 0.25  # the tiles decide


def test_the_intervals_degrees_of_freedom_count_the_work_checks_slope():
    # Welch-Satterthwaite: standard errors 3 (3 degrees of freedom) and 4 (1): (9 + 16)^2 / (81 / 3 + 256) =
    # 625 / 283 = 2.2, rounded down to 2; either alone keeps its own
    from gpusim.hw.sample import welch_dof
    assert welch_dof(3.0, 3, 4.0, 1) == 2
    assert welch_dof(3.0, 3, 0.0, 1) == 3 and welch_dof(0.0, 3, 4.0, 1) == 1
    assert welch_dof(1.0, 3, 100.0, 1) == 1                # the slope's doubt dominates: t(0.975, 1) = 12.7


def test_the_work_check_extrapolates_each_pass_linearly_to_the_whole_work():
    # four replicates thinned to a quarter of pass 0 (pass 1 kept whole); replicates 0 and 1 together, at half,
    # take 180 cycles: the slope is (180 - 105) / (0.5 - 0.25) = 300 cycles per whole work, so each replicate's
    # pass 0 gains 300 x 0.75 = 225; the slopes against replicate 0 or 1 alone are 320 and 280, so the slope's
    # standard error on a total is (320 - 280) / 2 x 0.75 = 15
    from gpusim.hw.sample import work_check
    cycles = np.array([[100.0, 50], [110, 50], [105, 50], [95, 50]])
    theta = np.array([[0.25, 1.0]] * 4)
    slope, se, info = work_check(cycles, theta, [(np.array([180.0, 50]), np.array([0.5, 1.0]))])
    assert slope.tolist() == [300, 0] and se == pytest.approx(15)
    assert (cycles + slope * (1 - theta))[:, 0].tolist() == [325, 335, 330, 320]
    assert info["pairs"] == [[0, 1]] and info["cycles"] == [230] and info["pair_cycles"] == [155]
    assert work_check(cycles, theta, [])[:2] == (pytest.approx([0, 0]), 0.0)
    # replicates 2 and 3 together at half take 170: slope (170 - 100) / 0.25 = 280; the mean slope is 290, its
    # standard error (300 - 280) / 2 = 10, times 0.75 on a total
    slope, se, info = work_check(cycles, theta, [(np.array([180.0, 50]), np.array([0.5, 1.0])),
                                                 (np.array([170.0, 50]), np.array([0.5, 1.0]))])
    assert slope.tolist() == [290, 0] and se == pytest.approx(7.5) and info["pairs"] == [[0, 1], [2, 3]]


def test_a_thinned_sample_stands_for_the_gpu_on_a_thinned_frame(spheres):
    # a replicate that keeps a share theta of its SMs' work: the shared units' load from the rest of the GPU,
    # the atomic words' chains and the front end's cycles per triangle are theta of the run's
    from gpusim.hw.raster import per_triangle_cycles
    from gpusim.hw.sample import thinned
    gpu = load_gpu("gtx280", ["sample.thin=0.25", "sample.thin_min_tiles=1", "sample.min_tiles=1", "sample.tile=4"])
    for scheme in ("linked-list", "zbuffer"):
        work = Workload.of(run_functional(spheres, scheme, {})[0], spheres)
        reps = Replicates(work, gpu, 1 / 30 / 4)
        program = lower(work, scaled_gpu(gpu, 1), Keep(reps, 0), pieces=plan_pieces(work))
        thin, theta = thinned(program, gpu, 1)
        share = np.array([p.operations / p.operations_total * 30 for p in program.passes])
        assert np.allclose(theta, np.minimum(share, 1)) and (theta < 1).any()
        for name, factor in program.occupancy.items():
            assert np.allclose(thin.occupancy[name], np.maximum(factor * theta[:, None], 1)), name
        assert thin.front_end_cycles == pytest.approx(list(per_triangle_cycles(gpu) * theta))
        if program.hold_scale is not None:
            row_pass = program.wi_pass[program.storage("atomic")[2]]
            assert np.allclose(thin.hold_scale, np.maximum(program.hold_scale * theta[row_pass], 1))


@pytest.mark.parametrize("scheme", ["zbuffer", "linked-list"])
def test_a_thinned_sampled_run_extrapolates_to_the_whole_work(spheres, scheme):
    # thinning off (the default) is the sampled level as it was; on, the replicates keep a share of their SMs'
    # work, the work checks run replicates 0 and 1, and 2 and 3, together on one SM, and each pass's cycles are
    # extrapolated from them to the whole work
    base = ["runner.workers=1", "sample.min_tiles=1", "sample.tile=4"]
    full = replay(spheres, scheme, {}, "full", load_gpu("gtx280", base))[1]["timing"]
    off = replay(spheres, scheme, {}, "sampled", load_gpu("gtx280", base))[1]["timing"]
    on = replay(spheres, scheme, {}, "sampled", load_gpu("gtx280", base + ["sample.thin=0.25",
                                                                          "sample.thin_min_tiles=1"]))[1]["timing"]
    assert off["sample"]["thin"] == 1 and off["sample"]["work_check"] is None
    assert off["sample"]["replicate_thinning"] == pytest.approx([1] * 4, abs=0.5)
    s = on["sample"]
    assert 0.25 <= s["thin"] <= 0.5 and s["share"] == pytest.approx(s["thin"] / 30)
    assert all(0 < t < 1 for t in s["replicate_thinning"]) and s["work_check"]["pairs"] == [[0, 1], [2, 3]]
    assert on["cycles"] == sum(p["cycles"] for p in on["passes"])
    assert on["cycles_ci95_low"] <= on["cycles"] <= on["cycles_ci95_high"]
    assert 0.8 < on["cycles"] / full["cycles"] < 1.25
    # the thinned replicates' own cycles are the thinned frame's: shorter than the extrapolated figure
    assert max(s["work_check"]["pair_cycles"]) < on["cycles"]
    # an experiment's stats table holds the thinning and the work check; without thinning, neither
    from gpusim.experiment.execute import timing_stat_rows
    rows = {r["stat"]: r["value"] for r in timing_stat_rows(on) if r["unit"] == "sample"}
    assert rows["thin"] == s["thin"] and rows["work_checks"] == 2
    assert rows["slope_std_error"] == pytest.approx(s["work_check"]["slope_std_error"])
    assert not {"thin", "work_checks"} & {r["stat"] for r in timing_stat_rows(off)}
    # where the level's wall time went: the whole run's part, the samples' lowering and events, the rest
    for timing in (off, on):
        parts = timing["sample"]["wall_seconds"]
        assert set(parts) == {"run", "programs", "events", "other"} and min(parts.values()) >= 0
        assert parts["events"] > 0 and sum(parts.values()) <= timing["event_seconds"] + 1e-3
    walls = {r["labels"]: r["value"] for r in timing_stat_rows(on) if r["stat"] == "wall_seconds"}
    assert walls == {f"part={k}": v for k, v in on["sample"]["wall_seconds"].items()}


@pytest.mark.parametrize("scheme", ["zbuffer", "depth-peeling"])
def test_a_thinned_samples_shared_units_and_front_end_are_as_busy_as_the_runs(spheres, scheme):
    # a thinned replicate stands for the GPU on a frame thinned to theta of each pass: its front end's and
    # shared units' busy cycles over theta are the run's (they were theta of them), and a sample of a few tiles,
    # which reaches only some ROPs or partitions in a pass, stands for the run's load on the others too
    base = ["runner.workers=1", "sample.min_tiles=1", "sample.tile=4"]
    full = replay(spheres, scheme, {}, "full", load_gpu("gtx280", base))[1]["timing"]
    on = replay(spheres, scheme, {}, "sampled", load_gpu("gtx280", base + ["sample.thin=0.25",
                                                                          "sample.thin_min_tiles=1"]))[1]["timing"]
    assert on["sample"]["thin"] < 1
    for unit in ("raster", "rop", "dram"):
        assert on["units"][unit]["busy_cycles"] == pytest.approx(full["units"][unit]["busy_cycles"], rel=0.03), unit


@pytest.mark.parametrize("scheme, unit", [("linked-list", "atomic"), ("depth-peeling", "rop")])
def test_a_sampled_runs_atomic_and_rop_requests_are_the_runs_operations(spheres, scheme, unit):
    # the census counts every operation of the run on the atomic units and ROPs: their requests, exactly
    base = ["runner.workers=1", "sample.min_tiles=1", "sample.tile=4"]
    full = replay(spheres, scheme, {}, "full", load_gpu("gtx280", base))[1]["timing"]
    sampled = replay(spheres, scheme, {}, "sampled", load_gpu("gtx280", base))[1]["timing"]
    assert sampled["sample"]["share"] < 1
    assert sampled["units"][unit]["requests"] == full["units"][unit]["requests"]


@pytest.mark.parametrize("scheme", ["zbuffer", "freepipe-abuffer"])
def test_with_an_l2_the_drams_figures_are_the_warmings_of_the_run(spheres, scheme):
    # the L2's functional warming replays every request of the run: the DRAM's requests (the misses) and busy
    # cycles are its, and the L2's misses; on this small case they are the full level's
    base = ["runner.workers=1", "sample.min_tiles=1", "sample.tile=4"]
    full = replay(spheres, scheme, {}, "full", load_gpu("laptop-ampere", base))[1]["timing"]["units"]
    sampled = replay(spheres, scheme, {}, "sampled", load_gpu("laptop-ampere", base))[1]["timing"]
    units = sampled["units"]
    assert sampled["sample"]["share"] < 1
    assert units["dram"]["requests"] == pytest.approx(full["dram"]["requests"], rel=0.02)
    assert units["dram"]["busy_cycles"] == pytest.approx(full["dram"]["busy_cycles"], rel=0.02)
    assert units["l2"]["misses"] == units["dram"]["requests"]
    assert units["l2"]["hits"] + units["l2"]["misses"] == units["l2"]["requests"]
    assert units["dram"]["utilisation_mean"] == pytest.approx(
        units["dram"]["busy_cycles"] / (sampled["cycles"] * units["dram"]["instances"]))


def test_the_largest_triangles_block_stands_for_itself_alone():
    # every replicate keeps the block of a software rasterizer's largest triangle, whose warp loops over the
    # triangle's pixels with its other lanes idle: scaled up with the rest of the sample, it put the SMs' busy
    # cycles, instructions and the coalesced requests at several times the run's
    scene, base = load_scene("bunny", ["screen.width=96", "screen.height=96"])
    bunny = trace_scene(scene, base, progress=False)
    base = ["runner.workers=1", "sample.min_tiles=1", "sample.tile=4"]
    full = replay(bunny, "freepipe-mdts", {}, "full", load_gpu("gtx280", base))[1]["timing"]["units"]
    sampled = replay(bunny, "freepipe-mdts", {}, "sampled", load_gpu("gtx280", base))[1]["timing"]["units"]
    for unit, key in (("core", "busy_cycles"), ("core", "requests"), ("coalescer", "requests"),
                      ("coalescer", "bytes"), ("dram", "requests")):
        assert sampled[unit][key] == pytest.approx(full[unit][key], rel=0.05), (unit, key)


def test_the_runs_busy_cycles_count_the_load_on_instances_a_sample_does_not_reach():
    from gpusim.hw.lower import reached_share
    from gpusim.hw.unit import run_held
    run = np.array([[4.0, 2.0, 2.0], [0.0, 0.0, 0.0], [1.0, 1.0, 2.0]])
    mine = np.array([[1.0, 0.0, 1.0], [0.0, 0.0, 0.0], [0.0, 0.0, 1.0]])
    assert reached_share(run, mine).tolist() == [0.75, 1.0, 0.5]
    program = dataclasses.make_dataclass("P", ["passes", "thinning", "reached"])(
        [0, 1, 2], np.array([0.5, 1.0, 0.25]), {"rop": reached_share(run, mine)})
    held = np.array([30, 10, 10])
    assert run_held(held, np.array([0, 1, 2]), program, "rop").tolist() == [80, 10, 80]
    assert run_held(held, np.array([0, 1, 2]), program, "memory").tolist() == [60, 10, 40]


@pytest.mark.parametrize("scheme", ["zbuffer", "freepipe-abuffer"])
def test_the_interval_holds_the_replicates_spread_and_the_scale_checks_bias(spheres, scheme):
    # the check runs replicates 0 and 1's samples together on their SMs together (their figures are its own,
    # not in the estimate): the interval is the t interval of the replicates widened by the bias it gives
    gpu = load_gpu("gtx280", ["runner.workers=1", "sample.min_tiles=1"])
    on = replay(spheres, scheme, {}, "sampled", gpu)[1]["timing"]
    off = replay(spheres, scheme, {}, "sampled", gpu.replace(
        sample=dataclasses.replace(gpu.sample, scale_check=False)))[1]["timing"]
    check, s = on["sample"]["scale_check"], on["sample"]
    assert off["sample"]["scale_check"] is None and on["cycles"] == off["cycles"]
    assert check["sms"] == 2 * s["replicate_sms"][0] and check["replicates"] == [0, 1]
    assert check["pair_cycles"] == pytest.approx(np.mean(s["replicate_cycles"][:2]))
    mean, half = np.mean(s["replicate_cycles"]), s["t_quantile"] * on["cycles_std_error"]
    assert off["cycles_ci95_low"] == math.floor(min(off["cycles"], mean - half))
    assert on["cycles_ci95_low"] == math.floor(min(on["cycles"], mean - half - abs(check["bias_estimate"])))
    assert on["cycles_ci95_high"] == math.ceil(max(on["cycles"], mean + half + abs(check["bias_estimate"])))
    assert on["cycle_error_estimate"] == pytest.approx(math.hypot(on["cycles_std_error"], check["bias_estimate"])
                                                       / mean)
    # an experiment's stats table holds the check's SMs and bias
    from gpusim.experiment.execute import timing_stat_rows
    rows = {r["stat"]: r["value"] for r in timing_stat_rows(on) if r["unit"] == "sample"}
    assert rows["scale_check_sms"] == check["sms"] and rows["scale_bias"] == pytest.approx(check["bias_estimate"])


def test_a_long_sampled_hold_is_waiting_not_a_deadlock():
    """A sampled request holds its unit for the full run's load over the sample's, so no instruction may issue
    for far longer than ``runner.no_progress_cycles`` while the run is only waiting on timed work. The watchdog
    must not call that a deadlock (on the default scene at 512x512 it did at the default 1,000,000 cycles);
    the cycles do not depend on the watchdog's limit."""
    from gpusim.replay import run_timing
    trace = trace_scene(*load_scene("default", ["screen.width=96", "screen.height=96"]), progress=False)
    result, _, reference = run_functional(trace, "freepipe-abuffer", {})
    cycles = [run_timing(result, trace, "sampled", load_gpu("gtx280", ["runner.workers=1",
                                                                        f"runner.no_progress_cycles={limit}"]),
                         reference)[0]["cycles"] for limit in (2_000, 1_000_000)]
    assert cycles[0] == cycles[1] > 100_000


def test_a_sampled_run_over_max_operations_refuses_before_building_anything(monkeypatch):
    """The sampled level lowers every operation of a chunk of passes before it samples: a run over
    ``runner.max_operations`` that the full level could not stream either (a pass over the limit; more
    operations per fragment than it streams) must be refused in one line before the pieces holding them are
    built (stress-layers' depth peeling, 420M operations, ran out of memory there)."""
    from gpusim.errors import GpusimError
    from gpusim.hw import sample
    from gpusim.replay import run_timing

    def built(*_args, **_kwargs):
        raise AssertionError("plan_pieces ran for a run over the limit")
    monkeypatch.setattr(sample, "plan_pieces", built)
    trace = trace_scene(*load_scene("default", ["screen.width=32", "screen.height=32"]), progress=False)
    result, _, reference = run_functional(trace, "depth-peeling", {})
    gpu = load_gpu("gtx280", ["runner.workers=1", "runner.max_operations=1000"])
    with pytest.raises(GpusimError, match=r"would lower [\d,]+ operations, over runner.max_operations.*"
                                          r"--fidelity analytic") as e:
        run_timing(result, trace, "sampled", gpu, reference)
    assert "\n" not in str(e.value)


@pytest.mark.parametrize("scheme", ["kbuffer", "linked-list", "depth-peeling"])
def test_a_sample_that_keeps_all_the_work_runs_on_the_whole_gpu(scheme):
    """Every fragment on one pixel: each replicate keeps that pixel's tile, all of the graphics pipeline's work,
    so it runs on every SM and gives the full level's cycles (it ran on 1/32 of them, 6.8x the full level's
    k-buffer capture, with an interval of zero width). (A software rasterizer's triangle blocks are still a
    share of the work.) 500 fragments: depth peeling's 500 passes."""
    from extremes import one_pixel
    trace = one_pixel(500)
    gpu = load_gpu("gtx280", ["runner.workers=1"])
    full = replay(trace, scheme, {}, "full", gpu)[1]["timing"]
    sampled = replay(trace, scheme, {}, "sampled", gpu)[1]["timing"]
    assert sampled["sample"]["replicate_sms"] == [gpu.core.sms] * gpu.sample.replicates
    assert sampled["cycles"] == full["cycles"]


def test_a_sample_of_its_share_of_the_work_runs_on_its_share_of_the_sms(spheres):
    # (one tile at least a replicate: the 1-SM design on this small scene)
    gpu = load_gpu("gtx280", ["runner.workers=1", "sample.min_tiles=1"])
    rec = replay(spheres, "freepipe-abuffer", {}, "sampled", gpu)[1]["timing"]
    assert set(rec["sample"]["replicate_sms"]) <= {sampled_sms(gpu), sampled_sms(gpu) + 1}


def test_the_lru_model_gives_each_request_its_outcome():
    # one set of 2 ways: A (write), B, A hits, C evicts B (the least recent; clean), B evicts A (dirty from its
    # write): MISS_DIRTY; an instruction's second segment of a line takes the first's outcome and shares its miss
    from gpusim.hw.memory import warming
    order = np.arange(5)
    seg_lo, seg_hi = np.array([0, 1, 2, 3, 4]), np.array([1, 2, 3, 4, 6])
    set_of = np.zeros(6, np.int64)
    tag_of = np.array([10, 11, 10, 12, 11, 11])
    writes = np.array([True, False, False, False, False])
    expect = [warming.MISS, warming.MISS, warming.HIT, warming.MISS, warming.MISS_DIRTY, warming.MISS_DIRTY]
    for kernel in (warming._lru_outcomes, warming.compiled_once([], warming._lru_outcomes)):
        if kernel is None:
            continue
        code, lanes = np.zeros(6, np.uint8), np.zeros(6, np.uint16)
        kernel(seg_lo[order], seg_hi[order], set_of, tag_of, writes[order], 1, 2, code, lanes)
        assert code.tolist() == expect
        assert lanes.tolist() == [1, 1, 1, 1, 2, 2]          # the last instruction's two segments share B


def test_the_run_is_replayed_in_a_sliding_window_of_resident_warps():
    # 4 warps of 3 instructions: with 4 resident, warp w's instruction k at w x 3/4 + k (a warp starts three
    # quarters of an instruction after the one before); with one, warp after warp
    from types import SimpleNamespace
    from gpusim.hw.memory.warming import issue_order
    wi = np.arange(12)
    prog = SimpleNamespace(wi_warp=wi // 3, wi_pass=np.zeros(12, np.int64),
                           passes=[SimpleNamespace(instructions=12, warps=4, first_warp=0)])
    many = SimpleNamespace(core=SimpleNamespace(sms=1, warps_per_sm=4))
    one = SimpleNamespace(core=SimpleNamespace(sms=1, warps_per_sm=1))
    assert issue_order(prog, many, wi).tolist() == [0, 3, 1, 6, 4, 2, 9, 7, 5, 10, 8, 11]
    assert issue_order(prog, one, wi).tolist() == list(range(12))


def test_a_sample_takes_its_l2_misses_from_the_run(spheres):
    # the k-buffer's 8 entries of 20 B a pixel (655 KB) through an L2 of 4 x 64 KB: the run thrashes (50,824
    # misses). The sample's requests take their lanes' share of the run's misses (functional warming): 38,948
    # scaled up (the replay's issue order finds 44,424; the replicates' 3 tiles carry a little less than
    # their share) and the cycles 1.00x; a slice cut to the sample's share of the run's lines had missed
    # 13,537 times, at 0.92x the cycles
    gpu = load_gpu("laptop-ampere", ["runner.workers=1", "sample.min_tiles=1", "l2.size_bytes=65536"])
    full = replay(spheres, "kbuffer", {}, "full", gpu)[1]["timing"]
    sampled = replay(spheres, "kbuffer", {}, "sampled", gpu)[1]["timing"]
    assert sampled["sample"]["share"] < 0.1
    assert sampled["units"]["l2"]["misses"] == pytest.approx(full["units"]["l2"]["misses"], rel=0.25)
    assert sampled["cycles"] == pytest.approx(full["cycles"], rel=0.03)


def test_each_pass_of_a_multi_pass_scheme_takes_its_own_l2_outcomes():
    # depth peeling reads each pixel's depth in every one of its 26 passes; a sample's request takes the run's
    # outcome of the same thread's operation in the same pass (matched on thread, group and loop iteration
    # alone, every pass took the first pass's cold misses: 3,405 misses scaled up against the run's 496, and
    # the cycles 2.0% over)
    scene, base = load_scene("default", ["screen.width=64", "screen.height=64"])
    trace = trace_scene(scene, base, progress=False)
    gpu = load_gpu("modern", ["runner.workers=1", "sample.min_tiles=1"])
    full = replay(trace, "depth-peeling", {}, "full", gpu)[1]["timing"]
    sampled = replay(trace, "depth-peeling", {}, "sampled", gpu)[1]["timing"]
    assert len(full["passes"]) == 26 and sampled["sample"]["share"] < 0.05
    assert sampled["units"]["l2"]["misses"] == pytest.approx(full["units"]["l2"]["misses"], rel=0.3)
    assert sampled["cycles"] == pytest.approx(full["cycles"], rel=0.01)


def test_the_warming_replay_gives_the_same_figures_without_numba(monkeypatch):
    # the LRU replay and the lanes' search run as plain Python where numba is absent: the same record
    from gpusim.hw.memory import warming
    scene, base = load_scene("nested-spheres", ["screen.width=32", "screen.height=32"])
    trace = trace_scene(scene, base, progress=False)
    gpu = load_gpu("laptop-ampere", ["runner.workers=1", "sample.min_tiles=1", "l2.size_bytes=16384"])
    compiled = replay(trace, "kbuffer", {}, "sampled", gpu)[1]["timing"]
    monkeypatch.setattr(warming, "_KERNELS", {"lru": [None], "run_segment": [None]})
    plain = replay(trace, "kbuffer", {}, "sampled", gpu)[1]["timing"]
    assert plain["cycles"] == compiled["cycles"] and plain["units"]["l2"] == compiled["units"]["l2"]


def test_a_triangle_sample_finds_the_lines_other_triangles_brought_in(spheres):
    # FreePipe's A-buffer samples whole blocks of triangles: a pixel's layers come from triangles of many
    # blocks, so the sample's first touch of a line is mostly not the run's first. With the run's outcomes the
    # misses scale to the full level's (a sample's own cache had missed 2.3x as often, at 1.17x the cycles)
    gpu = load_gpu("laptop-ampere", ["runner.workers=1", "sample.min_tiles=1"])
    full = replay(spheres, "freepipe-abuffer", {}, "full", gpu)[1]["timing"]
    sampled = replay(spheres, "freepipe-abuffer", {}, "sampled", gpu)[1]["timing"]
    assert sampled["units"]["l2"]["misses"] == pytest.approx(full["units"]["l2"]["misses"], rel=0.2)
    assert sampled["cycles"] == pytest.approx(full["cycles"], rel=0.1)


def test_the_heaviest_warp_of_a_pass_is_in_every_replicate(spheres):
    # LucidRaster's raster passes run a warp per bin, a few warps per SM: the pass ends with its heaviest warp.
    # Ranked by their operations, that warp is in every replicate and the others in one at most; the sampled
    # cycles then come within 3% of the full level's (2.5% short here; 3.3% when the DRAM channels' pool left
    # out the wait among the rest of the GPU's requests arriving at random, docs/timing-model.md; 10.2% short
    # when warps were ranked by position, none certain)
    gpu = load_gpu("gtx280", ["runner.workers=1", "sample.min_tiles=1"])
    result, _, _ = run_functional(spheres, "lucidraster", {})
    work = Workload.of(result, spheres)
    reps = Replicates(work, gpu, sampled_sms(gpu) / gpu.core.sms)
    pieces = plan_pieces(work)
    p = [pk.name for pk in work.plan.passes].index("raster-high")
    threads = [pc.thread for pc in pieces if pc.pass_index == p]
    lanes, chosen = reps.warps(p, threads)
    ops = np.bincount(np.searchsorted(lanes, np.concatenate(threads)) // gpu.core.warp_size)
    overlap = chosen.sum(axis=0)
    assert overlap[ops.argmax()] == gpu.sample.replicates
    assert (np.delete(overlap, ops.argmax()) <= 1).all()
    full = replay(spheres, "lucidraster", {}, "full", gpu)[1]["timing"]
    sampled = replay(spheres, "lucidraster", {}, "sampled", gpu)[1]["timing"]
    assert sampled["cycles"] == pytest.approx(full["cycles"], rel=0.03)


def test_a_small_run_samples_at_least_min_tiles_and_the_smallest_is_the_run(spheres):
    # gtx280: a replicate on 1 of the 30 SMs samples a thirtieth of the tiles; on fewer than 900 tiles that is
    # under min_tiles = 30, so it runs on ceil(30 x 30 / tiles) SMs, until the 4 replicates would take the 30
    # SMs between them (about 128 tiles): then the run itself, once
    gpu = load_gpu("gtx280", ["runner.workers=1"])
    assert [sampled_sms(gpu, t) for t in (2304, 900, 899, 256, 129, 128, 60, 1)] == [1, 1, 2, 4, 7, 30, 30, 30]
    assert sampled_sms(gpu) == 1
    # nested spheres at 64x64 cover 60 tiles of 8x8: the run itself, the full level's figures exactly
    result, _, _ = run_functional(spheres, "kbuffer", {"k": 8})
    reps = Replicates(Workload.of(result, spheres), gpu)
    tiles = reps.info["tiles"]
    assert tiles == 60 and reps.sms == gpu.core.sms and reps.share == 1
    full = replay(spheres, "kbuffer", {"k": 8}, "full", gpu)[1]["timing"]
    whole = replay(spheres, "kbuffer", {"k": 8}, "sampled", gpu)[1]["timing"]
    assert whole["sample"]["sms"] == gpu.core.sms and whole["sample"]["min_tiles"] == 30
    assert whole["cycles"] == full["cycles"] and whole["cycles_ci95_low"] == whole["cycles_ci95_high"]
    # with min_tiles = 10 a replicate runs on ceil(10 x 30 / 60) = 5 SMs and samples 10 of the 60 tiles
    part = replay(spheres, "kbuffer", {"k": 8}, "sampled", load_gpu("gtx280", ["runner.workers=1",
                                                                              "sample.min_tiles=10"]))[1]["timing"]
    assert part["sample"]["sms"] == 5 and part["sample"]["tiles_per_replicate"] == 10


def _same_piece(a, b) -> bool:
    """Two pieces with the same rows, addresses and bytes."""
    def same(x, y):
        return (x is None) == (y is None) and (x is None or np.array_equal(x, y))
    return ((a.group, a.pass_index) == (b.group, b.pass_index) and np.array_equal(a.thread, b.thread)
            and same(a.k, b.k) and same(a.instructions, b.instructions)
            and np.array_equal(a.address, b.address) and np.array_equal(a.nbytes, b.nbytes))


@pytest.mark.parametrize("scheme, params", [
    ("dual-depth-peeling", {}),                        # fragment passes, then a pixel pass (all its rows)
    ("freepipe-mdts", {}),                             # triangle blocks, atomic chains (the census's words)
    ("kbuffer", {"k": 8, "order": "centroid", "batch": 16}),
    ("tfss", {}),
    ("r-buffer", {}),          # its reads' addresses rank each among all of a pass's (the FIFO sequence)
])
def test_pieces_of_the_candidate_rows_lower_the_same_samples(scheme, params):
    """The sampled level builds the pieces of the rows some replicate may keep (every row of a pass in which
    a replicate holds none: it keeps one of the pass's units), counting every operation in a census: each
    replicate's program is the one the pieces of every row give."""
    from gpusim.hw import sample
    from gpusim.schemes import make_scheme
    trace = trace_scene(*load_scene("nested-spheres", ["screen.width=48", "screen.height=48"]), progress=False)
    result = make_scheme(scheme, params).run(trace)
    work = Workload.of(result, trace)
    gpu = load_gpu("gtx280", ["runner.workers=1", "sample.min_tiles=1"])
    reps, again = Replicates(work, gpu), Replicates(work, gpu)      # one design (a Replicates caches units)
    every = plan_pieces(work)
    some, census, whole = sample._pieces(work, gpu, again, None)
    assert sum(len(pc.thread) for pc in some) < sum(len(pc.thread) for pc in every)
    # the run's pieces are made once; the census counts what the pieces of every row load and their atomic words
    assert len(whole) == len(every) and all(_same_piece(a, b) for a, b in zip(whole, every))
    loads = _run_loads(plan_pieces(work), work.plan, gpu, len(work.plan.passes))["every"]
    assert census.every.keys() == loads.keys()
    assert all(np.array_equal(census.every[k], loads[k]) for k in loads)
    w, v = census.word_ops() or (None, None), _run_words(plan_pieces(work), work.plan) or (None, None)
    assert all(np.array_equal(a, b) for a, b in zip(w, v) if a is not None) and (w[0] is None) == (v[0] is None)
    small = scaled_gpu(gpu, reps.sms)
    for r in range(reps.count):
        a = lower(work, small, Keep(reps, r), pieces=every)
        b = lower(work, small, Keep(again, r), pieces=some)
        for name in ("row_lo", "row_hi", "wi_op", "wi_unit", "wi_cycles", "wi_dep", "wi_warp", "wi_pass", "wi_k"):
            assert np.array_equal(getattr(a, name), getattr(b, name)), name
        assert [(p.operations, p.operations_total, p.warps) for p in a.passes] == \
            [(p.operations, p.operations_total, p.warps) for p in b.passes]
        assert (a.occupancy is None) == (b.occupancy is None)
        for unit in a.occupancy or {}:
            assert np.array_equal(a.occupancy[unit], b.occupancy[unit]), unit
            assert np.array_equal(a.own_load[unit], b.own_load[unit]), unit
        assert (a.hold_scale is None) == (b.hold_scale is None)
        if a.hold_scale is not None:
            assert np.array_equal(a.hold_scale, b.hold_scale)
        for unit, rows in a.row_sets.items():
            assert np.array_equal(rows.address, b.row_sets[unit].address), unit


def test_the_runs_traffic_is_taken_in_the_fragment_shader_passes_only(spheres):
    # TFSS: a clear, the capture (the graphics pipeline's fragment shader: a replicate packs far-apart tiles'
    # fragments into its warps) and the read (pixel threads in the run's own warps)
    gpu = load_gpu("gtx280", ["runner.workers=1", "sample.traffic_share=1"])
    work = Workload.of(run_functional(spheres, "tfss", {})[0], spheres)
    names = [pk.name for pk in work.plan.passes]
    got = run_traffic(work, gpu)
    whole = memory_bytes(lower(work, gpu), gpu)
    capture = names.index("capture")
    assert np.array_equal(got[capture], whole[capture]) and whole[capture].sum() > 0
    others = [p for p in range(len(names)) if p != capture]
    assert np.isnan(got[others]).all()
    # from a lowering at hand (an L2's warming) the same figures; the chunk of passes from the capture on
    assert np.array_equal(run_traffic(work, gpu, None, lower(work, gpu)), got, equal_nan=True)
    assert np.array_equal(run_traffic(work, gpu, (capture, len(names))), got[capture:], equal_nan=True)
    # a software rasterizer keeps the run's warps in every pass: nothing to lower
    mdts = Workload.of(run_functional(spheres, "freepipe-mdts", {})[0], spheres)
    assert run_traffic(mdts, gpu) is None


def test_the_runs_traffic_is_estimated_from_a_sample_of_its_own_warps(spheres, monkeypatch):
    # one warp at random of every 4 consecutive ones of the capture pass, lowered in the run's warps: each
    # partition's bytes are the run's load on it times their bytes per unit of their load there; close to the
    # whole run's, not equal to it
    import gpusim.hw.sample as sample
    monkeypatch.setattr(sample, "MIN_TRAFFIC_WARPS", 8)
    work = Workload.of(run_functional(spheres, "tfss", {})[0], spheres)
    capture = [pk.name for pk in work.plan.passes].index("capture")
    whole = run_traffic(work, load_gpu("gtx280", ["runner.workers=1", "sample.traffic_share=1"]))[capture]
    gpu = load_gpu("gtx280", ["runner.workers=1", "sample.traffic_share=0.25"])
    got = run_traffic(work, gpu)[capture]
    assert not np.array_equal(got, whole)
    assert np.abs(got / whole - 1).max() < 0.05 and abs(got.sum() / whole.sum() - 1) < 0.02
    # the run's load on each partition from the census, where the level has counted it: the same figures
    every = plan_pieces(work)
    census = Census(work.plan, gpu)
    for pc in every:
        if pc.instructions is None:
            census.add(work.plan.groups[pc.group].op, pc.pass_index, pc.address, pc.nbytes)
    assert np.allclose(run_traffic(work, gpu, None, None, every, census)[capture], got, rtol=1e-12)
    # the sample: a quarter of the pass's warps, one of each block of 4, each whole (all of its lanes)
    pieces = sample.Pieces(pc for pc in plan_pieces(work) if pc.pass_index == capture)
    for pc in pieces:
        pc.pass_index = 0
    kept, warps, scale = sample._traffic_warps(work, gpu, pieces, capture, 1)
    lanes = np.unique(np.concatenate([pc.thread for pc in pieces]))
    mine = np.unique(np.concatenate([pc.thread for pc in kept]))
    run_warp = submission_warps(work, gpu, lanes)[0]
    chosen = np.unique(run_warp[np.isin(lanes, mine)])
    assert np.array_equal(np.unique(chosen // 4, return_counts=True)[1], np.ones(len(chosen), int))
    assert len(chosen) == -(-(int(run_warp[-1]) + 1) // 4) or len(chosen) == (int(run_warp[-1]) + 1) // 4
    assert np.isin(lanes[np.isin(run_warp, chosen)], mine).all()        # whole warps
    assert np.array_equal(warps(0, mine), run_warp[np.isin(lanes, mine)] // 4)
    assert (3 < scale).all() and (scale < 5).all()       # the run's load on each partition over the quarter's
