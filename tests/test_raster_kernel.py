"""The rasterizer's two paths, compiled kernels (numba) and numpy, give the same traces bit for bit.

The compiled path is used whenever numba imports; the numpy path is the fallback without it.
Both evaluate the formulas of gpusim.raster.kernel; these tests hold them to each other and
to the plain float64 formula, on random triangles (both windings, degenerate, off-screen,
large and small) and on a built-in scene, whole and in small pieces.
"""

from __future__ import annotations

import contextlib
import sys

import numpy as np
import pytest

import gpusim.raster.rasterizer as r
from gpusim.raster import TriangleBatch, kernel, rasterize
from gpusim.scene import load_scene
from gpusim.scene.build import scene_triangles
from test_raster_exact import _batch, _reference, _same_bits

FIELDS = ("x", "y", "z", "rgba", "prim", "opaque")
needs_numba = pytest.mark.skipif(kernel.compiled() is None, reason="numba is not installed")


def _assert_same(a, b):
    assert (a.width, a.height) == (b.width, b.height)
    for name in FIELDS:
        assert _same_bits(getattr(a, name), getattr(b, name)), name


@needs_numba
@pytest.mark.parametrize("cull", ["none", "back", "front"])
def test_compiled_and_numpy_paths_give_the_same_trace(cull):
    w, h = 160, 96
    batch = _batch(11, 400, w, h)
    compiled = rasterize(batch, w, h, cull)
    with kernel.numpy_path():
        plain = rasterize(batch, w, h, cull)
    assert len(compiled) > 10_000
    _assert_same(compiled, plain)


@needs_numba
def test_the_paths_agree_on_a_scene_with_clipped_triangles_and_in_small_pieces(monkeypatch):
    scene, base = load_scene("default", ["camera.eye=[0, 0.4, 1.2]"], size=(96, 64))
    batch = scene_triangles(scene, base)        # the camera inside the scene: near-plane clipping
    compiled = rasterize(batch, 96, 64)
    monkeypatch.setattr(r, "_FRAGMENTS_PER_CALL", 7)   # many emission calls, each a few triangles
    pieces = rasterize(batch, 96, 64)
    monkeypatch.setattr(r, "_ROWS_PER_CHUNK", 5)
    monkeypatch.setattr(r, "_FRAGMENTS_PER_CHUNK", 37)
    with kernel.numpy_path():
        plain = rasterize(batch, 96, 64)
    assert len(compiled) > 1000
    _assert_same(compiled, pieces)
    _assert_same(compiled, plain)


@pytest.mark.parametrize("path", ["compiled", "numpy"])
def test_each_path_is_the_plain_float64_formula_bit_for_bit(path):
    if path == "compiled" and kernel.compiled() is None:
        pytest.skip("numba is not installed")
    w, h = 128, 80
    batch = _batch(7, 300, w, h)
    with kernel.numpy_path() if path == "numpy" else contextlib.nullcontext():
        trace = rasterize(batch, w, h)
    assert len(trace) > 5_000
    z, rgba = _reference(batch, trace, w, h)
    assert _same_bits(trace.z, z)
    assert _same_bits(trace.rgba, rgba)


@needs_numba
def test_the_kernels_float64_values_are_the_plain_formula_before_rounding():
    # a float64 difference of an ulp (a fused multiply-add, a reordered sum, x * (1/w) for x / w)
    # rarely survives rounding to float32: emit into float64 arrays to see the values unrounded
    compiled = kernel.compiled()
    w, h = 128, 80
    batch = _batch(3, 300, w, h)
    trace = rasterize(batch, w, h)
    ints = np.empty((len(batch), kernel.INTS), np.int64)
    floats = np.empty((len(batch), kernel.FLOATS))
    offsets = np.zeros(len(batch) + 1, np.int64)
    compiled.setup(batch.clip, batch.rgba, w, h, kernel.CULL["none"], ints, floats, offsets[1:])
    np.cumsum(offsets, out=offsets)
    n = len(trace)
    assert offsets[-1] == n > 5_000
    x, y, prim, opaque = np.empty(n, np.uint16), np.empty(n, np.uint16), np.empty(n, np.uint32), np.empty(n, bool)
    z, rgba = np.empty(n), np.empty((n, 4))
    compiled.emit(0, len(batch), h, ints, floats, offsets, batch.prim, batch.opaque, x, y, z, rgba.reshape(-1),
                  prim, opaque)
    assert np.array_equal(x, trace.x) and np.array_equal(y, trace.y) and np.array_equal(prim, trace.prim)
    z_ref, rgba_ref = _reference(batch, trace, w, h, np.float64)
    assert _same_bits(z, z_ref)
    assert _same_bits(rgba, rgba_ref)
    assert _same_bits(z.astype(np.float32), trace.z)


@needs_numba
def test_the_kernels_round_every_product_before_adding_it():
    # (1 + 2^-30)^2 = 1 + 2^-29 + 2^-60: rounded, the product cancels against -(1 + 2^-29)
    # exactly; a fused multiply-add would keep the 2^-60
    kernel.compiled()
    e = 1.0 + 2.0 ** -30
    assert kernel._plane(e, e, -(1.0 + 2.0 ** -29), 0.0) == 0.0
    assert kernel.plane(e, e, -(1.0 + 2.0 ** -29), 0.0) == 0.0


@needs_numba
def test_the_kernels_clip_as_numpy_does():
    clip01 = kernel.compiled().clip01
    values = np.array([-0.0, 0.0, np.nan, -np.nan, -1e-300, 1e-300, -1.0, 0.5, 1.0, 1.0 + 1e-16, 2.0,
                       np.inf, -np.inf])
    for dtype in (np.float64, np.float32):
        v = values.astype(dtype)
        mine = np.array([clip01(x) for x in v], dtype=dtype)
        assert _same_bits(mine, np.clip(v, 0.0, 1.0).astype(dtype)), dtype


def test_without_numba_the_numpy_path_rasterizes(monkeypatch):
    monkeypatch.setitem(sys.modules, "numba", None)          # `import numba` raises ImportError
    monkeypatch.setattr(kernel, "_COMPILED", [])
    assert kernel.compiled() is None
    trace = rasterize(TriangleBatch.from_window(np.array([[[1.0, 1.0], [30.0, 2.0], [5.0, 20.0]]]), 32, 32),
                      32, 32)
    assert len(trace) == 273 and trace.z.dtype == np.float32


def test_empty_and_fully_dropped_batches_give_empty_traces():
    batch = TriangleBatch.from_window(np.array([[[1.0, 1.0], [2.0, 2.0], [3.0, 3.0]],       # degenerate
                                                [[-9.0, 1.0], [-5.0, 1.0], [-7.0, 5.0]]]),  # off-screen
                                      32, 32)
    for b in (batch, TriangleBatch.concat([])):
        trace = rasterize(b, 32, 32)
        assert len(trace) == 0 and trace.rgba.shape == (0, 4)
