"""TFSS's chained sections with a bit budget (leading-0s elimination): the greedy packing, its two paths.

The packing runs fragment by fragment in a numba kernel where numba is (gpusim.jit), else rank by rank over the
pixels in numpy; both must give the same placement, and the same TFSS results bit for bit.
"""

from __future__ import annotations

import numpy as np
import pytest
from conftest import make_trace

from gpusim.jit import numba_usable
from gpusim.schemes import make_scheme
from gpusim.schemes.common import sections
from gpusim.schemes.common.sections import place, place_runs


def greedy(pix_sorted, bits_sorted, capacity, budget):
    """The packing written out pixel by pixel: (chain, slot, bits before, early breaks)."""
    n = len(pix_sorted)
    chain, slot, before = np.full(n, -1), np.full(n, -1), np.zeros(n, np.int64)
    early = 0
    for p in np.unique(pix_sorted):
        sections_, used, fill = -1, capacity, 0
        for i in np.flatnonzero(pix_sorted == p):
            b = int(bits_sorted[i])
            if b > budget:                        # never fits: dropped, the sections stay as they are
                continue
            if used == capacity or fill + b > budget:
                early += used < capacity
                sections_, used, fill = sections_ + 1, 0, 0
            chain[i], slot[i], before[i] = sections_, used, fill
            used, fill = used + 1, fill + b
    return chain, slot, before, early


def runs(seed, n=600, pixels=40):
    rng = np.random.default_rng(seed)
    pix_sorted = np.sort(rng.integers(0, pixels, n)) * 3          # gaps between the pixel ids
    return pix_sorted, rng.integers(40, 65, n)                    # 40..64 bits, as fixed elimination gives


CASES = [(1, 56), (2, 112), (3, 112), (2, 100), (4, 160), (1, 40), (3, 50), (8, 1000), (2, 39)]


@pytest.fixture(params=["compiled", "numpy"])
def path(request, monkeypatch):
    if request.param == "compiled":
        if not numba_usable():
            pytest.skip("numba is not installed: only the numpy path exists")
    else:
        monkeypatch.setattr(sections, "_KERNEL", [None])
    return request.param


@pytest.mark.parametrize("capacity, budget", CASES)
def test_budget_placement_is_the_greedy_packing(path, capacity, budget):
    for seed in range(3):
        pix_sorted, bits = runs(seed)
        got = place_runs(pix_sorted, capacity, bits, budget)
        chain, slot, before, early = greedy(pix_sorted, bits, capacity, budget)
        assert np.array_equal(got.fits, bits <= budget)
        assert np.array_equal(got.chain, chain) and np.array_equal(got.slot, slot)
        assert np.array_equal(got.bits_before, before) and got.early_breaks == early
        assert got.chain.dtype == got.slot.dtype == got.bits_before.dtype == np.int64


def test_placement_by_fragment_is_the_placement_in_runs(path):
    rng = np.random.default_rng(5)
    n = 500
    pix = rng.integers(0, 30, n)
    by_arrival = np.argsort(pix, kind="stable")[rng.random(n) < 0.8]          # some fragments not given
    bits = rng.integers(40, 65, n)
    for budget in (None, 112, 50):
        pl = place(pix, by_arrival, n, 2, None if budget is None else bits, budget)
        r = place_runs(pix[by_arrival], 2, None if budget is None else bits[by_arrival], budget)
        kept = by_arrival if r.fits is None else by_arrival[r.fits]
        assert np.array_equal(np.flatnonzero(pl.kept), np.sort(kept))
        assert np.array_equal(pl.chain[by_arrival], r.chain) and np.array_equal(pl.slot[by_arrival], r.slot)
        before = np.zeros(len(by_arrival), np.int64) if r.bits_before is None else r.bits_before
        assert np.array_equal(pl.bits_before[by_arrival], before)
        assert pl.early_breaks == r.early_breaks


def test_placement_of_nothing(path):
    got = place_runs(np.zeros(0, np.int64), 2, np.zeros(0, np.int64), 112)
    assert len(got.chain) == len(got.slot) == len(got.bits_before) == 0 and got.early_breaks == 0


def plan_rows(res):
    """Every operation of the plan, with its address and size."""
    rows = []
    for g in res.plan.groups:
        i, seq = g.expand_ops()
        nbytes = g.bytes(i, seq) if callable(g.bytes) else g.bytes
        rows.append((g.op, g.structure, g.dep, np.asarray(g.thread_ids()).tolist(), np.asarray(g.count).tolist(),
                     np.asarray(g.offset(i, seq)).tolist(), np.broadcast_to(nbytes, (len(i),)).tolist(),
                     None if g.instructions is None else np.asarray(g.instructions).tolist()))
    return rows


def tfss_traces():
    rng = np.random.default_rng(11)
    n = 4000
    dark = np.c_[rng.random((n, 3)) * rng.choice([0.05, 0.3, 1.0], (n, 1)), rng.random(n)]
    yield make_trace(rng.integers(0, 12, n), rng.integers(0, 10, n), rng.random(n), rgba=dark,
                     opaque=rng.random(n) < 0.08, width=12, height=10, meta={"background": [0.1, 0.2, 0.3]})
    yield make_trace(np.zeros(300, int), np.zeros(300, int), rng.random(300), rgba=rng.random((300, 4)),
                     width=2, height=1)


@pytest.mark.parametrize("params", [{"leading_zero_elimination": "fixed", "section_bytes": 14},
                                    {"leading_zero_elimination": "variable", "section_bytes": 12, "l_num": 3},
                                    {"leading_zero_elimination": "fixed", "section_bytes": 5, "l_num": 1},
                                    {"section_bytes": 20, "l_num": 3, "read_scan": "all"}])
def test_tfss_compiled_and_numpy_placement_agree_bit_for_bit(monkeypatch, params):
    if not numba_usable():
        pytest.skip("numba is not installed: only the numpy path exists")
    model = make_scheme("tfss", params)
    traces = list(tfss_traces())
    compiled = [model.run(t) for t in traces]
    assert sections._KERNEL and sections._KERNEL[0] is not None
    monkeypatch.setattr(sections, "_KERNEL", [None])
    for trace, got in zip(traces, compiled):
        want = model.run(trace)
        assert np.array_equal(got.image, want.image)
        assert {k: v.value for k, v in got.stats.items()} == {k: v.value for k, v in want.stats.items()}
        assert got.footprint == want.footprint and got.accesses == want.accesses
        assert np.array_equal(got.lists.fragment, want.lists.fragment)
        assert plan_rows(got) == plan_rows(want)
    assert any(r.stats["section_breaks"].value or r.stats["unfit_fragments"].value for r in compiled)


@pytest.mark.parametrize("params", [{}, {"l_num": 3}, {"leading_zero_elimination": "fixed"},
                                    {"leading_zero_elimination": "variable", "section_bytes": 14}])
def test_every_stored_fragment_has_its_own_t_buffer_bytes(params):
    """A section's fragments follow each other in its bytes: no two stores of the capture share an address
    (without a bit budget they were all at the section's start)."""
    rng = np.random.default_rng(3)
    n = 600
    trace = make_trace(rng.integers(0, 6, n), rng.integers(0, 4, n), rng.random(n), rgba=rng.random((n, 4)),
                       width=6, height=4)
    result = make_scheme("tfss", params).simulate(trace)
    plan = result.plan
    stream = plan.expand(result.bases())
    t_buffer = plan.structures.index("t_buffer")
    stores = (stream.structure == t_buffer) & (stream.op == 1)     # OPS[1]: store
    addr = stream.address[stores]
    assert len(addr) and len(np.unique(addr)) == len(addr)
