"""Generators of extreme traces (issue 18), in one place for the tests that use them.

Each returns a :class:`~gpusim.trace.FragmentTrace` built in memory, deterministic for its seed:
distinct depths unless the generator is about ties, colours uniform in [0, 1], submission order
shuffled. The bundled stress scenes (configs/scenes/stress-layers, coplanar, alpha-extremes, slivers)
rasterize real geometry; these reach the values a rasterizer rarely gives: a depth complexity of exactly
n, a million one-fragment pixels beside one hot pixel, depths that collide only after a scheme's packing.
"""

from __future__ import annotations

import numpy as np

from conftest import make_trace
from gpusim.trace import FragmentTrace

BACKGROUND = [0.2, 0.4, 0.6]


def _distinct_depths(rng, n: int) -> np.ndarray:
    """``n`` distinct float32 depths in (0, 1), in random order."""
    z = np.unique(rng.random(2 * n + 16).astype(np.float32))
    z = z[(z > 0) & (z < 1)]
    assert len(z) >= n
    return rng.permutation(z[np.sort(rng.choice(len(z), n, replace=False))])


def build(pix, z, width: int, height: int, alpha=None, seed: int = 0, rgb=None) -> FragmentTrace:
    """A trace of fragments at pixel ids ``pix`` with depths ``z``, random colours (or ``rgb``) and ``alpha``
    (a scalar, an array, or None: uniform in [0, 1])."""
    pix = np.asarray(pix, np.int64)
    n = len(pix)
    rng = np.random.default_rng(seed + 1)
    rgb = rng.random((n, 3)) if rgb is None else np.broadcast_to(rgb, (n, 3))
    a = rng.random(n) if alpha is None else np.broadcast_to(np.asarray(alpha, np.float64), (n,))
    return make_trace(pix % width, pix // width, np.asarray(z, np.float32), np.c_[rgb, a], width=width,
                      height=height, meta={"background": BACKGROUND})


def one_pixel(n: int, alpha=None, seed: int = 0, width: int = 2, height: int = 1) -> FragmentTrace:
    """Depth complexity ``n`` on pixel 0 (distinct depths, random order) of an otherwise empty screen."""
    rng = np.random.default_rng(seed)
    return build(np.zeros(n, np.int64), _distinct_depths(rng, n), width, height, alpha, seed)


def layer_stack(width: int, height: int, layers: int, alpha=None, seed: int = 0) -> FragmentTrace:
    """Every pixel of the screen at depth complexity ``layers``: each layer is a full-screen primitive at
    its own depth (the layers submitted in random order, a pixel's depths a random permutation)."""
    rng = np.random.default_rng(seed)
    P = width * height
    z = _distinct_depths(rng, layers * P).reshape(layers, P)
    pix = np.tile(np.arange(P), layers)
    order = np.argsort(np.repeat(rng.permutation(layers), P), kind="stable")
    return build(pix[order], z.reshape(-1)[order], width, height, alpha, seed)


def hot_pixel(hot: int, width: int, height: int, seed: int = 0) -> FragmentTrace:
    """One pixel of ``hot`` fragments (a stiff chain of operations on one address) beside every other pixel
    of the screen with exactly one fragment (a wide, easy load), interleaved at random."""
    rng = np.random.default_rng(seed)
    P = width * height
    pix = np.r_[np.zeros(hot - 1, np.int64), np.arange(P)]
    z = np.r_[_distinct_depths(rng, hot), rng.random(P - 1).astype(np.float32)]
    z = np.r_[z[1:hot], z[0], z[hot:]]               # pixel 0's own fragment is one of its hot ones
    order = rng.permutation(len(pix))
    return build(pix[order], z[order], width, height, None, seed)


def from_histogram(hist: dict[int, int], width: int, height: int, seed: int = 0) -> FragmentTrace:
    """A transparent frame with exactly ``hist[i]`` pixels of depth complexity ``i`` (placed at random),
    distinct depths per pixel, submitted in random order."""
    rng = np.random.default_rng(seed)
    counts = np.repeat(list(hist), list(hist.values())).astype(np.int64)
    pixels = rng.choice(width * height, len(counts), replace=False)
    pix = np.repeat(pixels, counts)
    z = _distinct_depths(rng, len(pix))
    order = rng.permutation(len(pix))
    return build(pix[order], z[order], width, height, None, seed)


def constant_alpha(n: int, alpha: float, pixels: int = 3, seed: int = 0) -> FragmentTrace:
    """``n`` layers of one ``alpha`` on each of ``pixels`` pixels: 0.01 decays the transmittance slowly
    over hundreds of layers, 0.99 saturates it (it underflows float32 after about 20 layers)."""
    rng = np.random.default_rng(seed)
    z = _distinct_depths(rng, n * pixels)
    pix = np.repeat(np.arange(pixels), n)
    order = rng.permutation(n * pixels)
    return build(pix[order], z[order], pixels, 1, alpha, seed)


def equal_depths(n: int, z: float = 0.5, seed: int = 0) -> FragmentTrace:
    """``n`` fragments at exactly depth ``z`` on one pixel, each a different primitive, distinct colours."""
    return build(np.zeros(n, np.int64), np.full(n, z), 1, 1, None, seed)


def packed_depth_collisions(runs: int, run: int = 4, seed: int = 0) -> FragmentTrace:
    """``runs`` x ``run`` fragments on one pixel, one alpha (what packing needs), whose float32 depths all
    differ but come in runs of ``run`` consecutive floats in [0.5, 1) that keep the same 20 bits after
    FreePipe's packing (seed 000 section 4.1.2: 0.5 + 0.5 z, 20 mantissa bits kept; in [0.5, 1) one packed
    step is 16 float32 steps of z)."""
    rng = np.random.default_rng(seed)
    step = np.uint32(1 << 4)                                         # z-ulps per packed step
    lo, hi = np.float32(0.5).view(np.uint32) // step, np.float32(0.99).view(np.uint32) // step
    base = rng.choice(np.arange(lo, hi, dtype=np.uint32), runs, replace=False) * step + step // 4
    z = (np.repeat(base, run) + np.tile(np.arange(run, dtype=np.uint32), runs)).view(np.float32)
    order = rng.permutation(len(z))
    return build(np.zeros(len(z), np.int64), z[order], 1, 1, 0.5, seed)


def stored_as(trace: FragmentTrace, entry: str, alpha: float) -> FragmentTrace:
    """``trace`` with each fragment's colour what a k-buffer entry of format ``entry`` gives its resolve
    (gpusim.schemes.common.kbuffer_entries): ``rgbz`` its RGB, ``z`` the grey 1 - z of its depth, both at
    ``alpha``, none opaque. A scheme storing ``rgbz`` or ``z`` entries must give the image its model gives this
    trace with its float32 colours."""
    rgb = trace.rgba[:, :3] if entry == "rgbz" else np.repeat(np.clip(1 - trace.z, 0, 1)[:, None], 3, axis=1)
    return make_trace(trace.x, trace.y, trace.z, np.c_[rgb, np.full(len(trace), alpha)], width=trace.width,
                      height=trace.height, prim=trace.prim, meta=dict(trace.meta))
