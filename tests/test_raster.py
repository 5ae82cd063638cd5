"""Rasterizer rules: fill rule, snapping, clipping, culling, interpolation, emission order."""

from __future__ import annotations

import numpy as np
import pytest

from gpusim.raster import TriangleBatch, rasterize
from gpusim.scene.camera import look_at, perspective


def raster_window(tris, width=64, height=64, cull="none", **kw):
    return rasterize(TriangleBatch.from_window(np.asarray(tris, float), width, height, **kw),
                     width, height, cull)


def grid_tris(xs, ys):
    tris = []
    for i in range(len(xs) - 1):
        for j in range(len(ys) - 1):
            a, b, c, d = (xs[i], ys[j]), (xs[i + 1], ys[j]), (xs[i + 1], ys[j + 1]), (xs[i], ys[j + 1])
            tris += [(a, b, c), (a, c, d)]
    return tris


@pytest.mark.parametrize("xs, ys", [
    (np.arange(0, 65, 8) + 0.5, np.arange(0, 65, 8) + 0.5),          # every edge through pixel centres
    (np.linspace(-3.5, 68.25, 13), np.linspace(-2.5, 67.5, 9)),     # mixed, past the screen
    (np.arange(0, 65, 4.0), np.arange(0, 65, 4.0)),                  # edges on pixel borders
])
def test_shared_edges_cover_each_sample_exactly_once(xs, ys):
    dc = raster_window(grid_tris(xs, ys)).depth_complexity()
    lo_x, hi_x = max(xs[0], 0), min(xs[-1], 64)
    lo_y, hi_y = max(ys[0], 0), min(ys[-1], 64)
    centres = np.arange(64) + 0.5
    inside = ((centres[None, :] >= lo_x) & (centres[None, :] < hi_x)
              & (centres[:, None] >= lo_y) & (centres[:, None] < hi_y))
    assert dc[inside].min() == 1 and dc.max() == 1
    assert (dc[~inside] == 0).all() or xs[0] < 0


def test_fan_around_a_pixel_centre_covers_it_once():
    c = np.array([20.5, 20.5])
    ang = np.linspace(0, 2 * np.pi, 33)
    tris = [(c, c + 9 * np.array([np.cos(a), np.sin(a)]), c + 9 * np.array([np.cos(b), np.sin(b)]))
            for a, b in zip(ang[:-1], ang[1:])]
    dc = raster_window(tris).depth_complexity()
    assert dc.max() == 1 and dc[20, 20] == 1


def test_tie_rule_includes_left_and_bottom_edges_in_window_coordinates():
    # right triangle with its legs exactly on pixel centres
    t = raster_window([((10.5, 10.5), (14.5, 10.5), (10.5, 14.5))])
    pts = set(zip(t.x.tolist(), t.y.tolist()))
    assert (10, 10) in pts and (13, 10) in pts and (10, 13) in pts   # left and bottom edges
    assert (14, 10) not in pts and (10, 14) not in pts               # far corners: on right/top edge
    assert (12, 12) not in pts                                        # on the hypotenuse (a right edge)


def test_vertices_snap_to_1_256_pixel():
    # an edge 1/1024 px left of a pixel centre snaps onto it and follows the tie rule
    a = raster_window([((10.5 - 1 / 1024, 5.0), (20.0, 5.0), (10.5 - 1 / 1024, 9.0))])
    b = raster_window([((10.5, 5.0), (20.0, 5.0), (10.5, 9.0))])
    np.testing.assert_array_equal(a.x, b.x)


def test_degenerate_and_offscreen_triangles_emit_nothing():
    assert len(raster_window([((5, 5), (10, 10), (15, 15))])) == 0       # collinear
    assert len(raster_window([((5, 5), (5, 5), (9, 7))])) == 0           # repeated vertex
    assert len(raster_window([((-30, 5), (-10, 5), (-20, 30))])) == 0    # left of the screen
    assert len(raster_window([((10.2, 10.2), (10.4, 10.2), (10.3, 10.4))])) == 0  # misses every centre


def test_culling_follows_ccw_front_faces():
    ccw = [((2, 2), (30, 2), (2, 30))]
    cw = [((2, 2), (2, 30), (30, 2))]
    assert len(raster_window(ccw, cull="back")) > 0
    assert len(raster_window(cw, cull="back")) == 0
    assert len(raster_window(ccw, cull="front")) == 0
    assert len(raster_window(cw, cull="none")) == len(raster_window(ccw))


def test_emission_order_is_primitive_then_row_then_column():
    rng = np.random.default_rng(3)
    t = raster_window(rng.uniform(-4, 68, (200, 3, 2)))
    key = t.prim.astype(np.int64) * 2**32 + t.y.astype(np.int64) * 2**16 + t.x
    assert (np.diff(key) > 0).all()


def _camera_batch(tri_world, width, height, near=1.0, far=10.0, rgba=None):
    vp = perspective(60.0, width / height, near, far) @ look_at((0, 0, 0), (0, 0, -1), (0, 1, 0))
    homo = np.concatenate([np.asarray(tri_world, float), np.ones((len(tri_world), 3, 1))], axis=2)
    clip = homo @ vp.T
    if rgba is None:
        rgba = np.full((len(tri_world), 3, 4), 0.5)
    return TriangleBatch(clip, rgba, np.zeros(len(tri_world), bool))


def test_near_far_clipping_never_leaves_unit_depth():
    # triangles crossing the near plane, the far plane, and passing behind the eye
    tris = [[(-3, -3, -0.2), (3, -3, -0.2), (0, 3, -20.0)],
            [(-1, -1, -0.5), (1, -1, -12.0), (0, 1, -15.0)],
            [(-2, -2, 3.0), (2, -2, 3.0), (0, 2, -5.0)]]
    t = rasterize(_camera_batch(tris, 64, 48), 64, 48)
    assert len(t) > 0 and t.z.min() >= 0.0 and t.z.max() <= 1.0
    assert set(np.unique(t.prim)) == {0, 1, 2}


def test_triangle_wholly_behind_near_or_past_far_is_dropped():
    tris = [[(-1, -1, -0.5), (1, -1, -0.5), (0, 1, -0.5)], [(-9, -9, -50), (9, -9, -50), (0, 9, -50)]]
    assert len(rasterize(_camera_batch(tris, 32, 32), 32, 32)) == 0


def test_huge_triangle_past_the_guard_band_covers_the_screen_once():
    tris = [[(-1e4, -1e4, -2), (1e4, -1e4, -2), (0, 1e4, -2)]]
    dc = rasterize(_camera_batch(tris, 40, 30), 40, 30).depth_complexity()
    assert (dc == 1).all()


def test_depth_is_linear_in_screen_space_and_colour_perspective_correct():
    # a quad receding in depth: window z is affine in x, y; colour is affine in world space
    quad = np.array([(-1, -1, -2), (1, -1, -6), (1, 1, -6), (-1, 1, -2)], float)
    tris = [quad[[0, 1, 2]], quad[[0, 2, 3]]]
    red = lambda p: [(1 - (-p[2] - 2) / 4), 0.0, 0.0, 1.0]  # noqa: E731 - red falls with eye depth
    rgba = np.array([[red(p) for p in tri] for tri in tris])
    w, h = 128, 128
    batch = _camera_batch(tris, w, h, rgba=rgba)
    t = rasterize(batch, w, h)
    # recover eye depth from window z and check the colour followed it
    near, far = 1.0, 10.0
    z_ndc = t.z.astype(np.float64) * 2 - 1
    eye_depth = 2 * far * near / (far + near - z_ndc * (far - near))
    expected_red = 1 - (eye_depth - 2) / 4
    np.testing.assert_allclose(t.rgba[:, 0], np.clip(expected_red, 0, 1), atol=2e-3)
    # screen-space affinity of depth inside one triangle
    sel = t.prim == 0
    A = np.stack([t.x[sel] + 0.5, t.y[sel] + 0.5, np.ones(sel.sum())], axis=1)
    coef, *_ = np.linalg.lstsq(A, t.z[sel].astype(np.float64), rcond=None)
    assert np.abs(A @ coef - t.z[sel]).max() < 1e-6


def test_many_rows_and_chunks_give_the_same_trace(monkeypatch):
    import gpusim.raster.rasterizer as r
    rng = np.random.default_rng(5)
    tris = rng.uniform(-10, 138, (300, 3, 2))
    full = raster_window(tris, 128, 128)
    monkeypatch.setattr(r, "_ROWS_PER_CHUNK", 7)
    monkeypatch.setattr(r, "_FRAGMENTS_PER_CHUNK", 50)
    small = raster_window(tris, 128, 128)
    for name in ("x", "y", "z", "rgba", "prim"):
        np.testing.assert_array_equal(getattr(full, name), getattr(small, name))
