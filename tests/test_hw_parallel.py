"""Passes replayed in parallel processes give exactly the serial figures, errors included."""

from __future__ import annotations

import numpy as np
import pytest

from gpusim.errors import GpusimError
from gpusim.hw import FIDELITIES, load_gpu
from gpusim.hw.lower import Workload, lower
from gpusim.hw.machine import Machine, NoProgress
from gpusim.hw.parallel import plan_shares
from gpusim.opplan import OpPlan, Pass, layout_bases
from gpusim.scene import load_scene, trace_scene
from gpusim.schemes import make_scheme

from test_hw_units import SIMPLE


@pytest.fixture(scope="module")
def small():
    scene, base = load_scene("nested-spheres", ["screen.width=48", "screen.height=48"])
    return trace_scene(scene, base)


def machine_for(result, trace, gpu):
    work = Workload.of(result, trace)
    return Machine(gpu, lower(work, gpu), work.width)


@pytest.mark.parametrize("scheme, params", [
    ("depth-peeling", {}),                            # ROP depth tests, 20 peels
    ("freepipe-mdts", {}),                            # atomic chains
    ("kbuffer", {"k": 8}),                            # RMW through textures: hazards from event times
    ("kbuffer", {"k": 8, "order": "centroid", "batch": 16}),   # flush passes
    ("kbuffer", {"k": 8, "hw": "scoreboard"}),
])
def test_parallel_passes_give_the_serial_record(small, scheme, params):
    result = make_scheme(scheme, params).run(small)
    out = []
    for workers in (1, 2, 3):
        gpu = load_gpu("gtx280", [f"runner.workers={workers}"])
        shares = plan_shares(machine_for(result, small, gpu))
        assert len(shares) == workers                                          # really split
        assert sorted(i for s in shares for i in s) == list(range(len(result.plan.passes)))
        rec, image = FIDELITIES["full"](result, small, gpu)
        rec.pop("event_seconds")
        out.append((rec, None if image is None else image.tobytes()))
    assert out[0] == out[1] == out[2]
    if scheme == "kbuffer" and params.get("hw") is None and params.get("order") is None:
        assert out[0][0]["rmw_hazards"] > 0                  # the shifted RMW times still meet


def test_shares_stay_serial_where_they_cannot_gain_or_must_not(small):
    result = make_scheme("depth-peeling", {}).run(small)
    assert len(plan_shares(machine_for(result, small, load_gpu("gtx280", ["runner.workers=1"])))) == 1
    # the L2's contents carry from pass to pass
    assert len(plan_shares(machine_for(result, small, load_gpu("modern", ["runner.workers=2"])))) == 1
    # auto: a small program is not worth a fork
    assert len(plan_shares(machine_for(result, small, load_gpu("gtx280")))) == 1
    # shares are balanced: largest passes first, each to the least loaded share
    m = machine_for(result, small, load_gpu("gtx280", ["runner.workers=2"]))
    weight = [p.instructions for p in m.program.passes]
    loads = [sum(weight[i] for i in s) for s in plan_shares(m)]
    assert abs(loads[0] - loads[1]) <= max(weight)


def two_pass_plan():
    plan = OpPlan([Pass("first", "fullscreen", "pixel"), Pass("second", "fullscreen", "pixel")], ["a", "d", "fb"])
    plan.add(0, "store", "a", 3200, 1, lambda i, s: i * 64, 64)
    return plan


def simulate(plan, sizes, threads, extra):
    gpu = load_gpu("gtx280", SIMPLE + extra)
    work = Workload(plan, layout_bases(plan.structures, sizes), 64, 64, np.zeros(threads, np.int64),
                    np.arange(threads), triangles=0)
    return Machine(gpu, lower(work, gpu), 64).run()


def test_a_failing_share_reruns_serially_with_the_serial_diagnosis():
    # pass 1 deadlocks (a warp waits for itself at the ROP), pass 0 is a plain stream
    plan = two_pass_plan()
    plan.add(1, "depth_test", "d", np.array([0]), 1, lambda i, s: i * 0, 4)
    plan.add(1, "depth_test", "fb", np.array([1]), 1, lambda i, s: i * 0, 4)
    plan.add(1, "blend", "fb", np.array([0]), 1, lambda i, s: i * 0, 4, dep=True)
    sizes = {"a": 3200 * 64, "d": 4, "fb": 4}
    messages = []
    for workers in (1, 2):
        with pytest.raises(NoProgress) as e:
            simulate(plan, sizes, 3200, ["runner.no_progress_cycles=5000", f"runner.workers={workers}"])
        messages.append(str(e.value))
    assert messages[0] == messages[1]
    assert "(pass 1)" in messages[0]


def test_max_cycles_guard_names_the_pass_that_crossed_it():
    # each pass streams for 6,500 cycles: the second crosses 10,000
    plan = two_pass_plan()
    plan.add(1, "store", "a", 3200, 1, lambda i, s: i * 64, 64)
    sizes = {"a": 3200 * 64, "d": 4, "fb": 4}
    assert simulate(plan, sizes, 3200, ["runner.workers=2"]) == 13_000
    for workers in (1, 2):
        with pytest.raises(GpusimError, match=r"runner.max_cycles = 10,000 cycles before finishing \(pass 1 of 2\)"):
            simulate(plan, sizes, 3200, ["runner.max_cycles=10000", f"runner.workers={workers}"])


@pytest.mark.parametrize("scheme, params", [
    ("freepipe-mdts", {}),                            # triangle blocks, atomic chains held as the run's
    ("kbuffer", {"k": 8}),                            # RMW hazards scaled from each replicate's
    ("wboit", {}),
])
def test_parallel_replicates_give_the_serial_record(small, scheme, params):
    """The sampled level's replicates, one per process, give exactly the serial figures (each lowers and
    replays its sample in a forked process; what they share is counted once before the fork)."""
    result = make_scheme(scheme, params).run(small)
    out = []
    for workers in (1, 2, 3):
        gpu = load_gpu("gtx280", [f"runner.workers={workers}", "sample.min_tiles=1"])
        rec, _ = FIDELITIES["sampled"](result, small, gpu)
        rec.pop("event_seconds")
        rec["sample"].pop("wall_seconds")             # where the wall time went: not a figure
        out.append(rec)
    assert out[0] == out[1] == out[2]
    assert out[0]["sample"]["share"] < 1


def test_fork_map_keeps_order_and_gives_up_on_a_failure():
    from gpusim.hw.parallel import fork_map, fork_workers
    assert fork_map(lambda x: x * x, list(range(7)), 3) == [x * x for x in range(7)]

    def fails_on_4(x):
        if x == 4:
            raise ValueError("four")
        return x
    assert fork_map(fails_on_4, list(range(7)), 2) is None        # the caller redoes it serially
    assert fork_workers(1, 4, 1e9, 1) == 1                        # serial asked for
    assert fork_workers(0, 4, 10, 100) == 1                       # auto: too small to gain
    assert fork_workers(3, 2, 10, 100) == 2                       # no more processes than jobs
