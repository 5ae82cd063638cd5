"""The analytic level's pass schedule (gpusim.hw.pass_schedule): which passes it times, which it counts again,
which it interpolates, and how far that lands from timing every pass."""

from __future__ import annotations

import numpy as np
import pytest

import gpusim.hw.pass_schedule as ps
from gpusim.hw import load_gpu
from gpusim.hw.analytic import analytic_timing
from gpusim.hw.lower import Workload
from gpusim.hw.pass_schedule import INTERPOLATE_MIN_PASSES, TERMS, Family, Schedule, interpolated
from gpusim.replay import run_functional

from extremes import hot_pixel, layer_stack, one_pixel


def _family(threads, whole: int = 0) -> Family:
    """One group's threads per pass (and, when ``whole``, a group on every thread of every pass)."""
    t = np.asarray(threads, np.int64)
    sizes = t[:, None] if not whole else np.stack([np.full(len(t), -1), t], axis=1)
    return Family(np.arange(len(t)) * 2, sizes, t + whole)


class _Timer:
    """A pass's record from bound functions of its threads (what the analytic level's timer gives)."""

    def __init__(self, family: Family, bounds: dict, extra: int = 100):
        self.family, self.bounds, self.extra, self.calls = family, bounds, extra, []

    def record(self, p: int) -> dict:
        t = float(self.family.threads[list(self.family.passes).index(p)])
        terms = {k: float(f(t)) for k, f in self.bounds.items()}
        limit = max(terms, key=terms.get)
        return {"name": f"p{p}", "kind": "geometry", "cycles": int(np.ceil(terms[limit])) + self.extra,
                "warps": int(t // 32), "bound": limit, TERMS: (terms, self.extra)}

    def __call__(self, p: int) -> dict:
        self.calls.append(p)
        return self.record(p)


def _cycles(schedule: Schedule, p: int) -> int:
    how = schedule.how[p]
    if how[0] == "timed":
        return schedule.records[p]["cycles"]
    if how[0] == "repeat":
        return schedule.records[how[1]]["cycles"]
    _, at, w = how
    return interpolated([schedule.records[q] for q in at], at, w)["cycles"]


def _reference_rule(family: Family, timer: _Timer) -> dict:
    """The repeat rule written plainly, pass after pass: counted as the last timed pass again when every group's
    threads are within the tolerance of its, or (a volume bound deciding it) all of them are; else timed."""
    how, anchor = {}, None
    for i, p in enumerate(family.passes.tolist()):
        if anchor is not None:
            ref, rows = family.sizes[anchor], family.sizes[i]
            more = np.abs(rows - ref)
            same = ((rows < 0) == (ref < 0)).all()
            near = (more <= ps.REPEAT_TOLERANCE * np.abs(ref)).all() or (
                timer.record(int(family.passes[anchor]))["bound"] in ps.VOLUME_BOUNDS
                and more.sum() <= ps.REPEAT_TOLERANCE * family.threads[anchor])
            if same and near:
                how[p] = ("repeat", int(family.passes[anchor]))
                continue
        how[p] = ("timed",)
        anchor = i
    return how


@pytest.mark.parametrize("n", [5, INTERPOLATE_MIN_PASSES - 1])
def test_a_short_family_is_taken_pass_by_pass_as_the_repeat_rule_says(n):
    f = _family(np.linspace(10_000, 2_000, n).astype(int), whole=5_000)
    timer = _Timer(f, {"rop": lambda t: 3 * t, "raster": lambda t: 14_000.0})
    assert Schedule([f], timer).how == _reference_rule(f, timer)


def test_without_interpolation_a_long_family_follows_the_repeat_rule():
    f = _family(np.linspace(60_000, 100, 500).astype(int), whole=20_000)
    timer = _Timer(f, {"dram": lambda t: 2.5 * t, "latency": lambda t: 900.0})
    assert Schedule([f], timer, interpolate=False).how == _reference_rule(f, timer)


def test_a_straight_family_is_timed_at_its_ends_and_midpoint_and_interpolated_exactly():
    f = _family(np.linspace(50_000, 1_000, 400).astype(int))
    timer = _Timer(f, {"dram": lambda t: 2.0 * t + 3_000})
    s = Schedule([f], timer)
    assert len(timer.calls) == 3
    for p in f.passes.tolist():
        assert abs(_cycles(s, p) - timer.record(p)["cycles"]) <= 1


def test_a_bend_from_one_bound_to_another_is_followed_with_the_bound_named():
    """Depth peeling's passes: the ROP bound falls with the layers left until the front end's fixed cost decides."""
    f = _family(np.linspace(40_000, 16, 1_000).astype(int), whole=40_000)
    timer = _Timer(f, {"rop": lambda t: 0.9 * t, "raster": lambda t: 45_000.0, "latency": lambda t: 0.01 * t})
    s = Schedule([f], timer)
    assert len(timer.calls) < 12
    for p in f.passes.tolist():
        want = timer.record(p)
        how = s.how[p]
        got = interpolated([s.records[q] for q in how[1]], how[1], how[2]) if how[0] == "interpolated" else None
        assert abs(_cycles(s, p) - want["cycles"]) <= 1
        if got is not None:
            assert got["bound"] == want["bound"]


def test_a_curved_family_is_split_until_each_span_is_straight_within_the_tolerance():
    f = _family(np.linspace(100_000, 10, 2_000).astype(int))
    timer = _Timer(f, {"issue": lambda t: t * t / 1e3 + 5_000})
    s = Schedule([f], timer)
    assert 3 < len(timer.calls) < len(f.passes) // 4
    errors = [abs(_cycles(s, p) / timer.record(p)["cycles"] - 1) for p in f.passes.tolist()]
    assert max(errors) <= 2 * ps.INTERPOLATE_TOLERANCE


def test_a_family_whose_threads_grow_is_not_interpolated():
    f = _family(np.r_[np.linspace(9_000, 100, 100), np.linspace(100, 9_000, 100)].astype(int))
    timer = _Timer(f, {"dram": lambda t: 3.0 * t})
    s = Schedule([f], timer)
    assert not any(h[0] == "interpolated" for h in s.how.values())
    assert s.how == _reference_rule(f, timer)


GPU = load_gpu("gtx280", ["runner.workers=1"])
DEEP = {"one pixel 1,500 deep": lambda: one_pixel(1_500),
        "hot pixel of 1,200 in 48x48": lambda: hot_pixel(1_200, 48, 48),
        "12x12 at 200 layers": lambda: layer_stack(12, 12, 200)}
SCHEMES = [("depth-peeling", {}), ("dual-depth-peeling", {}), ("r-buffer", {}), ("multipass-kbuffer", {"k": 2})]


@pytest.fixture(scope="module", params=list(DEEP))
def deep(request):
    return DEEP[request.param]()


@pytest.mark.parametrize("scheme,params", SCHEMES, ids=[s for s, _ in SCHEMES])
def test_interpolated_cycles_lie_within_half_a_percent_of_timing_every_pass(deep, scheme, params, monkeypatch):
    result = run_functional(deep, scheme, params)[0]
    work = Workload.of(result, deep)
    fast = analytic_timing(result, work, GPU)
    monkeypatch.setattr(ps, "REPEAT_TOLERANCE", 0.0)        # only passes with exactly the same threads repeat
    exact = analytic_timing(result, work, GPU, interpolate=False)
    assert len(fast["passes"]) == len(exact["passes"])
    assert abs(fast["total"] / exact["total"] - 1) <= ps.INTERPOLATE_TOLERANCE
    timed = sum(1 for p in fast["passes"] if "repeat_of" not in p and "interpolated" not in p)
    assert timed <= max(40, len(fast["passes"]) // 10)
    assert fast["repeated_passes"] + fast["interpolated_passes"] + timed == len(fast["passes"])


def test_passes_that_make_the_same_work_again_as_new_groups_are_counted_again():
    """The multi-pass k-buffer's resolve passes of the same deep pixels are new groups each pass."""
    trace = one_pixel(400)
    result = run_functional(trace, "multipass-kbuffer", {"k": 4})[0]
    rec = analytic_timing(result, Workload.of(result, trace), GPU, interpolate=False)
    resolves = [p for p in rec["passes"] if p["name"].startswith("resolve")]
    assert len(resolves) == 100
    assert sum("repeat_of" in p for p in resolves) >= 97
    assert {p["cycles"] for p in resolves[1:-1]} == {resolves[1]["cycles"]}


def test_a_family_of_passes_with_nothing_to_time_is_timed_or_counted_again():
    # a long shrinking family whose records carry no bounds (passes with nothing to time, every one the same
    # cycles): no pass is interpolated, for there are no bounds to interpolate, and every pass has its cycles
    f = _family(np.arange(INTERPOLATE_MIN_PASSES + 8, 0, -1) * 64)

    def empty(p):
        return {"name": f"p{p}", "kind": "geometry", "cycles": 50, "warps": 0, "bound": "empty"}

    s = Schedule([f], empty)
    assert all(how[0] in ("timed", "repeat") for how in s.how.values())
    assert {_cycles(s, p) for p in f.passes.tolist()} == {50}
