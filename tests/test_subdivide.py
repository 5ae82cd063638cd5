"""Geometry subdivision (seed 004 section 4.3; gpusim/scene/subdivide.py) and the tet-ventricle volume mesh
(gpusim/scene/tetmesh.py) behind the like-heart scene."""

from __future__ import annotations

import math
import subprocess
import sys

import numpy as np
import pytest

from gpusim.errors import ConfigError
from gpusim.scene import load_scene, trace_scene
from gpusim.scene.build import scene_triangles
from gpusim.scene.model import TetVentricle
from gpusim.scene.subdivide import MAX_ASPECT, areas, aspect_ratio, priority, split, subdivide
from gpusim.scene.tetmesh import faces_of, tet_ventricle, tetrahedra

SMALL_HEART = ["objects.0.divisions=[2,24,10]", "objects.1.divisions=[1,12,8]"]


def signed_normal(tri: np.ndarray) -> np.ndarray:
    return np.cross(tri[..., 1, :] - tri[..., 0, :], tri[..., 2, :] - tri[..., 0, :])


def test_one_split_follows_the_paper_construction():
    # edges: opposite corner 0 sqrt(65) (e_max), opposite corner 1 length 1 (e_min), opposite corner 2 length 8;
    # they share corner 2, so the new vertex is on 2 -> 1 at distance min(1, sqrt(65) / 2) = 1 from corner 2
    tri = np.array([[[0.0, 0.0, 0.0], [8.0, 0.0, 0.0], [0.0, 1.0, 0.0]]])
    colour = np.array([[[1.0, 0.0], [0.0, 1.0], [0.5, 0.5]]])
    first, first_a, second, second_a = split(tri, colour)
    new = np.array([8.0, -1.0, 0.0]) / math.sqrt(65.0) + [0.0, 1.0, 0.0]
    np.testing.assert_allclose(np.linalg.norm(new - tri[0, 2]), 1.0)
    np.testing.assert_allclose(first[0], [[0.0, 0.0, 0.0], new, [0.0, 1.0, 0.0]])      # corner 1 replaced
    np.testing.assert_allclose(second[0], [[0.0, 0.0, 0.0], [8.0, 0.0, 0.0], new])     # corner 2 replaced
    t = 1.0 / math.sqrt(65.0)
    np.testing.assert_allclose(first_a[0, 1], (1 - t) * colour[0, 2] + t * colour[0, 1])
    np.testing.assert_allclose(second_a[0, 2], first_a[0, 1])
    # the piece at the shared corner is isosceles (two sides of l_min); both keep the winding; area kept
    assert np.linalg.norm(first[0, 1] - first[0, 2]) == pytest.approx(1.0)
    assert np.linalg.norm(first[0, 0] - first[0, 2]) == pytest.approx(1.0)
    assert np.all(signed_normal(first)[:, 2] > 0) and np.all(signed_normal(second)[:, 2] > 0)
    assert areas(first)[0] + areas(second)[0] == pytest.approx(areas(tri)[0])


def test_a_fat_triangle_is_split_at_the_middle_of_its_longest_edge():
    # l_min = sqrt(1 + 2.56) > l_max / 2 = 1: the new vertex is the midpoint of e_max (corners 0 and 1)
    tri = np.array([[[0.0, 0.0, 0.0], [2.0, 0.0, 0.0], [1.0, 1.6, 0.0]]])
    first, _, second, _ = split(tri, np.zeros((1, 3, 1)))
    assert {tuple(first[0, 0]), tuple(second[0, 1])} == {(1.0, 0.0, 0.0)}
    assert aspect_ratio(np.array([[[0, 0, 0], [1, 0, 0], [0.5, math.sqrt(0.75), 0]]]))[0] == pytest.approx(1.0)


def test_budget_count_area_order_and_attributes():
    rng = np.random.default_rng(3)
    tri = rng.random((200, 3, 3))
    tri[:, 1, 0] += rng.random(200) * 20              # long and skinny ones among them
    attr = rng.random((200, 3, 4))
    for budget in (1.0, 1.5, 4.0):
        out, out_attr, parent = subdivide(tri, attr, budget)
        assert len(out) == math.floor(budget * 200)
        np.testing.assert_allclose(np.bincount(parent, weights=areas(out), minlength=200), areas(tri), rtol=1e-9)
        assert np.all(np.diff(parent) >= 0)           # each triangle's pieces where it stood, in order
        # every new corner lies in its parent triangle's plane with the attribute its position implies
        for i in np.flatnonzero(np.bincount(parent) > 1)[:20]:
            a, b, c = tri[i]
            basis = np.stack([b - a, c - a], axis=1)
            for piece, piece_attr in zip(out[parent == i], out_attr[parent == i]):
                w, *_ = np.linalg.lstsq(basis, (piece - a).T, rcond=None)
                np.testing.assert_allclose(basis @ w + a[:, None], piece.T, atol=1e-9)
                expected = attr[i, 0] + w.T @ np.stack([attr[i, 1] - attr[i, 0], attr[i, 2] - attr[i, 0]])
                np.testing.assert_allclose(piece_attr, expected, atol=1e-9)
    same, same_attr, parent = subdivide(tri, attr, 1.0)
    assert np.array_equal(same, tri) and np.array_equal(same_attr, attr) and np.array_equal(parent, np.arange(200))


def test_the_highest_priority_goes_first_and_bad_shapes_lose_area():
    heart = tet_ventricle(TetVentricle(kind="tet-ventricle", divisions=(3, 40, 12)))
    tri = heart.vertices[heart.faces]
    bad_area, worst = [], []
    for budget in (1.0, 1.5, 3.0, 6.0):
        out, _, _ = subdivide(tri, np.zeros((len(tri), 3, 1)), budget)
        aspect = aspect_ratio(out)
        bad_area.append(areas(out)[aspect > 4].sum())
        worst.append(priority(out).max())
    # the paper's aim: less area in triangles of bad aspect ratio at every step; the key's maximum falls too
    assert all(a > b for a, b in zip(bad_area, bad_area[1:])), bad_area
    assert all(a > b for a, b in zip(worst, worst[1:])), worst
    # a one-at-a-time queue stops where the batched one does, within a round's step: none above the last key
    out, _, parent = subdivide(tri, np.zeros((len(tri), 3, 1)), 1.2)
    untouched = np.bincount(parent, minlength=len(tri)) == 1
    assert priority(tri)[untouched].max() <= priority(tri)[~untouched].min() * (1 + 1 / 16) ** 2


def test_lines_are_never_split_and_bad_input_fails():
    line = np.array([[[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [2.0, 0.0, 0.0]],
                     [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.5, 1.0 / MAX_ASPECT / 2, 0.0]]])
    assert priority(line).max() == -np.inf
    out, _, _ = subdivide(line, np.zeros((2, 3, 1)), 10.0)
    assert len(out) == 2
    with pytest.raises(ValueError, match="below 1"):
        subdivide(line, np.zeros((2, 3, 1)), 0.5)
    with pytest.raises(ValueError, match="not \\(T, 3, 3\\)"):
        subdivide(line[:, :, :2], np.zeros((2, 3, 1)), 2.0)


GRID = """
name = "grid"
[screen]
width = 48
height = 40
[camera]
eye = [0.3, 0.4, 4.0]
[[objects]]
kind = "quad-grid"
size = [3.0, 3.0]
divisions = [4, 4]
rotate_deg = [50.0, 20.0, 0.0]
alpha = 0.5
"""


def per_pixel(t):
    """Pixel ids, depths and colours of a trace's fragments, by pixel then depth."""
    order = np.lexsort((t.z, t.pixel_ids()))
    return t.pixel_ids()[order], t.z[order], t.rgba[order]


def test_subdivision_keeps_the_rasterized_surface(tmp_path):
    # square cells: every triangle is split once at its hypotenuse's midpoint, no T-junction: same fragments
    path = tmp_path / "grid.toml"
    path.write_text(GRID)
    scene, where = load_scene(str(path))
    plain = trace_scene(scene, where, progress=False)
    twice = trace_scene(load_scene(str(path), ["subdivide_budget=2.0"])[0], where, progress=False)
    assert twice.meta["primitives"] == 2 * plain.meta["primitives"] == 64
    (p0, z0, c0), (p1, z1, c1) = per_pixel(plain), per_pixel(twice)
    np.testing.assert_array_equal(p0, p1)
    # the new vertex snaps to 1/256 pixel, which tilts its triangles' depth planes by as much
    np.testing.assert_allclose(z1, z0, atol=1e-5)
    np.testing.assert_allclose(c1, c0, atol=1e-5)
    # the heart: coverage differs only where a split edge meets an unsplit one (a T-junction: the new vertex,
    # snapped, is off the neighbour's edge by rounding), a fragment moved to a neighbouring pixel and back
    heart, where = load_scene("like-heart", SMALL_HEART + ["screen.width=64", "screen.height=64"])
    before = trace_scene(heart, where, progress=False)
    after_scene = load_scene("like-heart", SMALL_HEART + ["screen.width=64", "screen.height=64",
                                                          "subdivide_budget=6.0"])[0]
    after = trace_scene(after_scene, where, progress=False)
    assert after.meta["primitives"] == math.floor(6.0 * before.meta["primitives"])
    dc0, dc1 = before.depth_complexity(), after.depth_complexity()
    assert np.count_nonzero(dc0 != dc1) <= 0.02 * np.count_nonzero(dc0)
    assert abs(len(after) - len(before)) <= 1e-3 * len(before)


def test_scene_key_bounds_fail_in_one_line(tmp_path):
    with pytest.raises(ConfigError, match="subdivide_budget: must be >= 1.0"):
        load_scene("like-heart", ["subdivide_budget=0.5"])
    with pytest.raises(ConfigError, match="subdivide_budget: must be <= 64.0"):
        load_scene("like-heart", ["subdivide_budget=100"])
    run = subprocess.run([sys.executable, "-m", "gpusim", "trace", "like-heart", "--set", "subdivide_budget=0",
                          "-o", str(tmp_path / "t.npz")], capture_output=True, text=True)
    assert run.returncode != 0 and "Traceback" not in run.stderr
    assert len(run.stderr.strip().splitlines()) == 1 and "subdivide_budget" in run.stderr


def test_tetrahedra_conform_and_each_face_is_drawn_once():
    for ring, tip in ((True, True), (False, False), (True, False)):
        grid, tets = tetrahedra((2, 3, 5), ring, tip)
        assert len(np.unique(np.sort(tets, axis=1), axis=0)) == len(tets)
        assert np.all(np.sort(tets, axis=1)[:, 1:] != np.sort(tets, axis=1)[:, :-1])
        faces = faces_of(tets)
        keys = np.sort(tets[:, [[1, 2, 3], [0, 3, 2], [0, 1, 3], [0, 2, 1]]].reshape(-1, 3), axis=1)
        _, uses = np.unique(keys, axis=0, return_counts=True)
        assert uses.max() == 2 and len(faces) == len(uses)          # a face is shared by at most 2 tetrahedra
        # the faces used once close a surface: each of their edges is shared by an even number of them
        outer = np.unique(keys, axis=0, return_counts=True)
        boundary = outer[0][outer[1] == 1]
        edges = np.sort(np.concatenate([boundary[:, [0, 1]], boundary[:, [1, 2]], boundary[:, [0, 2]]]), axis=1)
        assert np.all(np.unique(edges, axis=0, return_counts=True)[1] % 2 == 0)
    _, full = tetrahedra((2, 3, 5), True, False)
    assert len(full) == 6 * 2 * 3 * 5
    _, collapsed = tetrahedra((2, 3, 5), True, True)
    assert len(collapsed) < len(full)                           # the tip's flattened tetrahedra are gone


def test_tet_ventricle_has_long_skinny_faces_and_full_size_like_the_paper():
    spec = TetVentricle(kind="tet-ventricle", divisions=(3, 40, 12), lambda_range=(0.37, 0.68))
    mesh = tet_ventricle(spec)
    aspect = aspect_ratio(mesh.vertices[mesh.faces])
    assert np.all(np.isfinite(aspect)) and np.mean(aspect > 5) > 0.1
    lam = np.arccosh(np.clip(np.linalg.norm(mesh.vertices - [1, 0, 0], axis=1) / 2
                             + np.linalg.norm(mesh.vertices + [1, 0, 0], axis=1) / 2, 1, None))
    assert lam.min() >= 0.37 - 1e-9 and lam.max() <= 0.68 + 1e-9           # jitter never leaves the wall
    np.testing.assert_allclose(mesh.rgba[:, 3], spec.alpha)
    scene, where = load_scene("like-heart")
    assert len(scene_triangles(scene, where)) == 359_582                   # the paper's heart: 359,310
    with pytest.raises(ConfigError, match="lambda_range: \\[0.9, 0.5\\] must satisfy 0 < inner < outer"):
        load_scene("like-heart", ["objects.0.lambda_range=[0.9, 0.5]"])
    with pytest.raises(ConfigError, match="jitter: must be <= 0.45"):
        load_scene("like-heart", ["objects.0.jitter=0.5"])
