"""The event model on the schemes that had no timing test of their own: TFSS, R-buffer, Weight-Factor and
LucidRaster."""

from __future__ import annotations

import numpy as np
import pytest
from conftest import make_trace

from gpusim.hw import load_gpu
from gpusim.replay import replay


@pytest.fixture(scope="module")
def layered():
    """A 64x48 screen, every pixel 1-5 transparent layers, fragments in random pixel order."""
    rng = np.random.default_rng(7)
    depth = rng.integers(1, 6, 64 * 48)
    pix = np.repeat(np.arange(64 * 48), depth)
    rng.shuffle(pix)
    n = len(pix)
    return make_trace(pix % 64, pix // 64, rng.random(n), rng.random((n, 4)) * [1, 1, 1, 0.8] + [0, 0, 0, 0.1],
                      width=64, height=48, prim=np.arange(n) // 2)


def _cycles(trace, scheme, gpu="gtx280", sets=(), **params):
    _, rec, _, _ = replay(trace, scheme, params, "full", load_gpu(gpu, list(sets)))
    return rec["timing"]


def test_thesis_schemes_replay_with_every_pass_timed(layered):
    # R-buffer recirculates its fragment buffer once per layer; TFSS and Weight-Factor walk each pixel's list once
    got = {s: _cycles(layered, s) for s in ("r-buffer", "tfss", "weight-factor")}
    for s, t in got.items():
        assert t["cycles"] == sum(p["cycles"] for p in t["passes"]) and all(p["cycles"] > 0 for p in t["passes"]), s
    assert len(got["r-buffer"]["passes"]) > len(got["tfss"]["passes"])
    # the thesis's order of execution time (section 4.3.2): R-buffer above TFSS, TFSS above Weight-Factor
    assert got["r-buffer"]["cycles"] > got["tfss"]["cycles"] > got["weight-factor"]["cycles"]


def test_lucidraster_stages_are_timed_apart_and_workgroups_use_the_sms():
    # one triangle per 4x4 tile over a 128x64 screen: 8 bins, each a low-raster workgroup
    rng = np.random.default_rng(3)
    xs, ys = np.meshgrid(np.arange(128), np.arange(64))
    xs, ys = xs.ravel(), ys.ravel()
    prim = (ys // 4) * 32 + xs // 4
    trace = make_trace(xs, ys, rng.random(len(xs)), width=128, height=64, prim=prim)
    t = _cycles(trace, "lucidraster")
    names = [p["name"] for p in t["passes"]]
    assert names == ["setup", "bin-count", "bin-offsets", "bin-write", "raster-low", "raster-high"]
    # the bins' workgroups spread over the SMs: one SM takes much longer for the raster stage
    one = _cycles(trace, "lucidraster", sets=["core.sms=1"])
    low = names.index("raster-low")
    assert one["passes"][low]["cycles"] > 2 * t["passes"][low]["cycles"]
