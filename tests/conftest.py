"""Shared fixtures: small traces built in memory, and a bundled experiment run into a folder."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).parent))

from gpusim.trace import FragmentTrace  # noqa: E402


def make_trace(xs, ys, zs, rgba=None, opaque=None, width=8, height=8, prim=None, meta=None):
    n = len(xs)
    rgba = np.full((n, 4), 0.5, np.float32) if rgba is None else np.asarray(rgba, np.float32)
    return FragmentTrace(np.asarray(xs, np.uint16), np.asarray(ys, np.uint16), np.asarray(zs, np.float32),
                         rgba, np.arange(n, dtype=np.uint32) if prim is None else np.asarray(prim, np.uint32),
                         np.zeros(n, bool) if opaque is None else np.asarray(opaque, bool),
                         width, height, meta or {})


@pytest.fixture
def random_trace():
    rng = np.random.default_rng(42)
    n = 5000
    return make_trace(rng.integers(0, 16, n), rng.integers(0, 12, n), rng.random(n),
                      rng.random((n, 4)), rng.random(n) < 0.1, width=16, height=12,
                      meta={"background": [0.2, 0.3, 0.4]})


def ran_experiment(name: str, out):
    """Bundled experiment ``name`` run into ``out`` in this process, every run finished: ``out``."""
    from gpusim.experiment import load_experiment
    from gpusim.experiment.runner import run_experiment
    summary = run_experiment(load_experiment(name), out, workers=1, quiet=True)
    assert summary.failed == 0 and summary.ok == summary.runs
    return out


#: the test modules that take longest (seconds of one core, measured on the 2-core reference machine with
#: nothing else running, pytest's junit times): run
#: first, so that ``pytest -n 2 --dist loadfile`` (scripts/test.sh) does not start one of them when the other
#: worker is nearly done; scripts/test.sh passes --no-loadscope-reorder, which keeps this order instead of
#: xdist's (files with the most tests first)
SLOW_FIRST = ("test_timing_golden.py",    # ~200 s: the golden table, one module fixture
              "test_stability.py",        # ~75 s: every scheme and level on every built-in scene
              "test_papers.py",           # ~60 s: the seeds' CI experiments
              "test_hw_stream.py",        # ~55 s
              "test_fidelity_report.py",  # ~45 s: the fidelity corpus at CI size
              "test_experiment.py",       # ~30 s
              "test_stability_report.py",  # ~30 s
              "test_properties.py",       # ~20 s
              "test_hw_timing.py",        # ~20 s
              "test_extremes.py")         # ~16 s


def pytest_collection_modifyitems(config, items):
    rank = {name: i for i, name in enumerate(SLOW_FIRST)}
    items.sort(key=lambda item: rank.get(item.path.name, len(SLOW_FIRST)))     # stable: the rest as collected
