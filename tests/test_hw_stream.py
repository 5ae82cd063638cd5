"""The full level over runner.max_operations: a chunk of passes at a time, exactly the whole run's figures."""

from __future__ import annotations

import numpy as np
import pytest

from gpusim.errors import GpusimError
from gpusim.hw import FIDELITIES, load_gpu
from gpusim.hw.lower import Workload, lower, ops_in_passes, pass_operations
from gpusim.hw.stream import STREAM_OPS_PER_FRAGMENT, plan_chunks
from gpusim.metrics import composite_exact
from gpusim.scene import load_scene, trace_scene
from gpusim.schemes import make_scheme


@pytest.fixture(scope="module")
def small():
    return trace_scene(*load_scene("nested-spheres", ["screen.width=40", "screen.height=40"]))


def limit_for(result, trace, share: float) -> int:
    """A runner.max_operations that holds the largest pass but ``share`` of the run at most."""
    per_pass = pass_operations(result.plan)
    return max(int(per_pass.max()), int(share * per_pass.sum()))


@pytest.mark.parametrize("scheme, params", [
    ("freepipe-abuffer", {}),                         # atomics, software rasterizer (triangle threads)
    ("depth-peeling", {}),                            # seq_pass groups over 20 peels, ROP depth tests
    ("dual-depth-peeling", {}),                       # pass_fn groups
    ("kbuffer", {"k": 8}),                            # RMW through textures: hazards across chunks
    ("kbuffer", {"k": 8, "order": "centroid", "batch": 16}),   # a pass per batch, flush passes
    ("kbuffer", {"k": 8, "hw": "scoreboard"}),
    ("kbuffer", {"k": 8, "hw": "blender"}),
])
def test_streamed_run_gives_the_whole_runs_record(small, scheme, params):
    result = make_scheme(scheme, params).run(small)
    reference = composite_exact(small)
    out = []
    for limit in (10**9, limit_for(result, small, 0.3), limit_for(result, small, 0.0)):
        gpu = load_gpu("gtx280", ["runner.workers=1", f"runner.max_operations={limit}"])
        chunks = plan_chunks(Workload.of(result, small), gpu)
        assert (chunks is None) == (limit == 10**9)
        rec, image = FIDELITIES["full"](result, small, gpu, reference)
        rec.pop("event_seconds")
        streamed = rec.pop("streamed", None)
        assert (streamed is None) == (chunks is None)
        if streamed is not None:
            assert streamed["chunks"] == len(chunks) > 1
        out.append((rec, None if image is None else image.tobytes()))
    assert out[0] == out[1] == out[2]
    if params == {"k": 8}:
        assert out[0][0]["rmw_hazards"] > 0


def test_lowering_a_range_of_passes_gives_their_instructions(small):
    result = make_scheme("depth-peeling", {}).run(small)
    work = Workload.of(result, small)
    gpu = load_gpu("gtx280")
    whole = lower(work, gpu)
    per_pass = pass_operations(result.plan)
    for p in (0, 1, 7, len(result.plan.passes) - 1):
        part = lower(work, gpu, passes=(p, p + 1))
        assert part.passes[0].name == result.plan.passes[p].name
        assert part.operations == whole.passes[p].operations == per_pass[p]
        assert part.passes[0].warps == whole.passes[p].warps
        assert part.instructions == whole.passes[p].instructions
    for g in result.plan.groups:               # the operations of a range, in expand_ops order
        i, seq = g.expand_ops()
        where = np.asarray(g.pass_of(i, seq))
        got_i, got_seq = ops_in_passes(g, 2, 9)
        sel = (where >= 2) & (where < 9)
        assert np.array_equal(got_i, i[sel]) and np.array_equal(got_seq, np.broadcast_to(seq, i.shape)[sel])


def test_what_cannot_stream_is_refused_in_one_line(small):
    result = make_scheme("depth-peeling", {}).run(small)
    per_pass = pass_operations(result.plan)
    cases = [
        ("gtx280", int(per_pass.max()) - 1, "') would lower"),                      # a pass over the limit
        ("modern", int(per_pass.max()), "carry state from pass to pass"),         # an L2
    ]
    for gpu_name, limit, expect in cases:
        gpu = load_gpu(gpu_name, ["runner.workers=1", f"runner.max_operations={limit}", "sample.min_tiles=1"])
        for level in ("full", "sampled"):             # the sampled level refuses what the full level cannot stream
            with pytest.raises(GpusimError) as exc:
                FIDELITIES[level](result, small, gpu)
            message = str(exc.value)
            assert expect in message and "\n" not in message
            assert "runner.max_operations" in message and "--fidelity analytic" in message
        rec, _ = FIDELITIES["analytic"](result, small, gpu)      # the advice works
        assert rec["cycles"] > 0


def test_a_run_whose_operations_grow_with_passes_is_refused():
    trace = trace_scene(*load_scene("stress-layers", ["screen.width=16", "screen.height=16",
                                                      "objects.1.layers=512"]))
    result = make_scheme("depth-peeling", {}).run(trace)
    assert result.plan.total_ops() > STREAM_OPS_PER_FRAGMENT * len(trace)
    gpu = load_gpu("gtx280", [f"runner.max_operations={int(pass_operations(result.plan).max())}"])
    with pytest.raises(GpusimError, match="per fragment, too many to replay a chunk of passes at a time"):
        FIDELITIES["full"](result, trace, gpu)


@pytest.mark.parametrize("scheme, params", [
    ("freepipe-abuffer", {}),                         # triangle blocks, atomics
    ("depth-peeling", {}),                            # seq_pass groups over 20 peels
    ("dual-depth-peeling", {}),
    ("kbuffer", {"k": 8}),                            # RMW hazards in the replicates
    ("kbuffer", {"k": 8, "order": "centroid", "batch": 64}),   # a pass per batch, flush passes
])
def test_a_sampled_run_over_max_operations_is_sampled_a_chunk_at_a_time(small, scheme, params):
    """The sampled level takes what the full level streams: each replicate's sample of each chunk of passes,
    on a machine of its own (of the SMs its sample of the whole run takes), gives the figures of its sample
    of the whole run."""
    _same_sampled_figures_streamed(small, scheme, params, [])


@pytest.mark.parametrize("scheme, params", [("depth-peeling", {}), ("kbuffer", {"k": 8})])
def test_a_thinned_sampled_run_is_the_same_streamed(small, scheme, params):
    """Thinned replicates and the work check (gpusim.hw.sample.thinned) give the same figures a chunk of passes
    at a time."""
    rec = _same_sampled_figures_streamed(small, scheme, params, ["sample.thin=0.25", "sample.thin_min_tiles=1", "sample.tile=4"])
    assert rec["sample"]["thin"] < 1 and rec["sample"]["work_check"] is not None


def _same_sampled_figures_streamed(small, scheme, params, options) -> dict:
    result = make_scheme(scheme, params).run(small)
    reference = composite_exact(small)
    out = []
    for limit in (10**9, limit_for(result, small, 0.3), limit_for(result, small, 0.0)):
        gpu = load_gpu("gtx280", ["runner.workers=1", f"runner.max_operations={limit}", "sample.min_tiles=1",
                                  *options])
        rec, _ = FIDELITIES["sampled"](result, small, gpu, reference)
        rec.pop("event_seconds")
        rec["sample"].pop("wall_seconds")             # where the wall time went: not a figure
        streamed = rec.pop("streamed", None)
        assert (streamed is None) == (limit == 10**9)
        if streamed is not None:
            assert streamed["chunks"] > 1
        out.append(rec)
    assert out[0] == out[1] == out[2]
    assert out[0]["sample"]["share"] < 1 and out[0]["cycles_ci95_low"] < out[0]["cycles_ci95_high"]
    return out[0]


@pytest.mark.parametrize("passes", [1, 3])
def test_a_samples_own_windows_count_the_hazards_of_the_runs_windows(passes):
    """A sample's RMW windows over its own threads (hazards.rmw_windows, own=True) count the same hazards and
    hazard pixels as the windows over every thread of the run, in one pass and in several."""
    from gpusim.hw.hazards import count_hazards, rmw_windows
    rng = np.random.default_rng(passes)
    threads, n = 5000, 900
    pixel = rng.integers(0, 40, threads)
    who = rng.choice(threads, n, replace=False)          # a sample's few threads of the run's
    p = rng.integers(0, passes, n)
    read_at = rng.integers(0, 500, n)
    write_at = read_at + rng.integers(1, 200, n)
    reads, writes = (p, who, read_at), (p, who, write_at)
    dense = count_hazards(pixel, *rmw_windows(reads, writes, threads))
    read, write, ids = rmw_windows(reads, writes, threads, own=True)
    assert len(ids) == n and read.shape[-1] == n
    assert count_hazards(pixel[ids], read, write) == dense
    assert dense[0] > 0                                  # the case has hazards to count


def test_a_plans_pass_operations_are_counted_again_once_it_changes():
    """pass_operations keeps its count on the plan: the same count each time (a copy a caller may change), and
    a new count once the plan has another group or pass."""
    from gpusim.opplan import OpPlan, Pass
    plan = OpPlan([Pass("a", "geometry", "fragment"), Pass("b", "fullscreen", "pixel")], ["s"])
    plan.add(0, "load", "s", np.arange(5), 2, lambda i, s: i * 4 + s, 4)
    first = pass_operations(plan)
    assert first.tolist() == [10, 0]
    first[0] = -1                                        # the caller's copy, not the kept count
    assert pass_operations(plan).tolist() == [10, 0]
    plan.add(1, "store", "s", np.arange(3), 1, lambda i, s: i * 4, 4)
    assert pass_operations(plan).tolist() == [10, 3]
    plan.passes.append(Pass("c", "fullscreen", "pixel"))
    assert pass_operations(plan).tolist() == [10, 3, 0]
