"""The rasterizer's depth and colour are exactly the plain float64 plane formula.

The rasterizer reorganises its work for speed (set-up over (3, T) arrays, one
plane table per span, attributes one at a time over cached chunks, triangles kept
or gathered); none of that may change a bit of the trace. The reference here is
the formula written out plainly: planes from the snapped vertices, then
``a0 + dadx*dx + dady*dy`` per fragment in float64, colour divided by the
interpolated 1/w, clamped to [0, 1] and rounded to float32.
"""

from __future__ import annotations

import numpy as np
import pytest

import gpusim.raster.rasterizer as r
from gpusim.raster import TriangleBatch, rasterize
from gpusim.raster.clip import clip_triangles
from gpusim.scene.camera import look_at, perspective


def _batch(seed: int, count: int, width: int, height: int) -> TriangleBatch:
    """Random triangles seen in perspective, all inside the near/far planes and the guard
    band (so clipping changes nothing): large and small, both windings, some degenerate,
    some off the screen."""
    rng = np.random.default_rng(seed)
    centre = rng.uniform([-4, -3, -12], [4, 3, -2], (count, 1, 3))
    size = rng.choice([0.02, 0.3, 2.0], (count, 1, 1))
    world = centre + size * rng.normal(size=(count, 3, 3))
    world[::17, 2] = world[::17, 1]                  # a repeated vertex: zero area
    world[::23] += [40.0, 0.0, 0.0]                   # beside the screen
    world[..., 2] = np.clip(world[..., 2], -40.0, -1.0)  # between the near and far planes
    vp = perspective(50.0, width / height, 0.5, 50.0) @ look_at((0, 0, 0), (0, 0, -1), (0, 1, 0))
    clip = np.concatenate([world, np.ones((count, 3, 1))], axis=2) @ vp.T
    rgba = rng.uniform(0, 1, (count, 3, 4))
    rgba[::5, :, 3] = 1.0
    return TriangleBatch(clip, rgba, rng.random(count) < 0.3)


def _reference(batch: TriangleBatch, trace, width: int, height: int, dtype=np.float32):
    """(z, rgba) of each fragment of ``trace`` by the plain formula, float32 (or ``dtype``)."""
    clip = batch.clip
    inv_w = 1.0 / clip[..., 3]
    fx = np.rint((clip[..., 0] * inv_w + 1.0) * (width / 2.0 * 256)).astype(np.int64)
    fy = np.rint((clip[..., 1] * inv_w + 1.0) * (height / 2.0 * 256)).astype(np.int64)
    area2 = (fx[:, 1] - fx[:, 0]) * (fy[:, 2] - fy[:, 0]) - (fx[:, 2] - fx[:, 0]) * (fy[:, 1] - fy[:, 0])
    z = (clip[..., 2] * inv_w + 1.0) * 0.5
    attrs = np.concatenate([z[..., None], inv_w[..., None], batch.rgba * inv_w[..., None]], axis=2)
    ccw = np.where((area2 < 0)[:, None], [0, 2, 1], [0, 1, 2])    # clockwise: swap vertices 1, 2
    take = lambda a: np.take_along_axis(a, ccw.reshape(ccw.shape + (1,) * (a.ndim - 2)), axis=1)  # noqa: E731
    px, py, attrs = take(fx) / 256, take(fy) / 256, take(attrs)
    d1, d2 = attrs[:, 1] - attrs[:, 0], attrs[:, 2] - attrs[:, 0]
    x10, x20 = (px[:, 1] - px[:, 0])[:, None], (px[:, 2] - px[:, 0])[:, None]
    y10, y20 = (py[:, 1] - py[:, 0])[:, None], (py[:, 2] - py[:, 0])[:, None]
    with np.errstate(divide="ignore", invalid="ignore"):       # degenerate ones emit nothing
        area = (np.abs(area2) / 65536)[:, None]
        dadx = (d1 * y20 - d2 * y10) / area
        dady = (d2 * x10 - d1 * x20) / area
    t = trace.prim
    dx = (trace.x + 0.5) - px[t, 0]
    dy = (trace.y + 0.5) - py[t, 0]
    vals = attrs[t, 0] + dadx[t] * dx[:, None] + dady[t] * dy[:, None]
    return (np.clip(vals[:, 0], 0, 1).astype(dtype),
            np.clip(vals[:, 2:] / vals[:, 1:2], 0, 1).astype(dtype))


def _same_bits(a: np.ndarray, b: np.ndarray) -> bool:
    return a.dtype == b.dtype and a.shape == b.shape and np.array_equal(a.view(np.uint8), b.view(np.uint8))


@pytest.mark.parametrize("chunks", [None, (5, 37)])
def test_depth_and_colour_are_the_plain_float64_formula_bit_for_bit(monkeypatch, chunks):
    if chunks:   # rows and fragments split at every possible place, spans longer than a chunk
        monkeypatch.setattr(r, "_ROWS_PER_CHUNK", chunks[0])
        monkeypatch.setattr(r, "_FRAGMENTS_PER_CHUNK", chunks[1])
    w, h = 160, 96
    batch = _batch(11, 400, w, h)
    kept = clip_triangles(batch)                        # nothing clipped: prim indexes batch
    assert np.array_equal(kept.clip, batch.clip[kept.prim])
    trace = rasterize(batch, w, h)
    assert len(trace) > 10_000 and len(np.unique(trace.prim)) > 200
    z, rgba = _reference(batch, trace, w, h)
    assert _same_bits(trace.z, z)
    assert _same_bits(trace.rgba, rgba)


@pytest.mark.parametrize("cull", ["none", "back"])
def test_setting_up_every_triangle_or_only_the_kept_ones_gives_the_same_trace(monkeypatch, cull):
    w, h = 128, 80
    batch = _batch(5, 300, w, h)
    traces = []
    for gather_below in (0.0, 2.0):      # never gather / always gather the kept triangles
        monkeypatch.setattr(r, "_GATHER_BELOW", gather_below)
        traces.append(rasterize(batch, w, h, cull))
    assert len(traces[0]) > 1000
    for name in ("x", "y", "z", "rgba", "prim", "opaque"):
        assert _same_bits(getattr(traces[0], name), getattr(traces[1], name)), name
