"""Procedural tetrahedral volume meshes, drawn as the triangles of their tetrahedra.

:func:`tet_ventricle` builds the ``tet-ventricle`` object kind (see
:class:`gpusim.scene.model.TetVentricle`): a block of prolate spheroidal
coordinates, cut into cells, each cell split into the 6 tetrahedra of the
Kuhn split (the path from a cell's corner (0,0,0) to (1,1,1) along the three
axes in each of the 6 orders), which is conforming: neighbouring cells share
whole faces. Every distinct face is one triangle.
"""

from __future__ import annotations

import itertools

import numpy as np

from gpusim.scene import model as m

#: the 6 Kuhn tetrahedra of a unit cell, as (lambda, mu, theta) corner offsets
KUHN = np.array([[(0, 0, 0), tuple(np.eye(3, dtype=int)[p[0]]),
                  tuple(np.eye(3, dtype=int)[p[0]] + np.eye(3, dtype=int)[p[1]]), (1, 1, 1)]
                 for p in itertools.permutations(range(3))], dtype=np.int64)


def tetrahedra(divisions: tuple[int, int, int], ring: bool, tip: bool) -> tuple[np.ndarray, np.ndarray]:
    """The tetrahedra of a grid of ``divisions`` cells: (grid corner (V, 3) of each vertex, tetrahedra (N, 4)).

    ``ring``: the third axis wraps around (its last corner is its first); ``tip``: every corner with second
    coordinate 0 and the same first coordinate is one vertex (a ring collapsed onto the axis). Tetrahedra
    that the collapse flattens (a vertex twice) are left out."""
    ni, nj, nk = divisions
    ck = nk if ring else nk + 1                                   # distinct corners along the third axis
    i, j, k = np.meshgrid(np.arange(ni), np.arange(nj), np.arange(nk), indexing="ij")
    cell = np.stack([i.ravel(), j.ravel(), k.ravel()], axis=1)
    corner = cell[:, None, None, :] + KUHN[None]                  # (cells, 6, 4, 3)
    corner = corner.reshape(-1, 4, 3)
    corner[..., 2] %= ck
    if tip:
        corner[..., 2] = np.where(corner[..., 1] == 0, 0, corner[..., 2])
    ids = (corner[..., 0] * (nj + 1) + corner[..., 1]) * ck + corner[..., 2]
    flat = np.sort(ids, axis=1)
    keep = np.all(flat[:, 1:] != flat[:, :-1], axis=1)
    ids = ids[keep]
    used, tets = np.unique(ids, return_inverse=True)
    tets = tets.reshape(-1, 4)
    grid = np.stack([used // ((nj + 1) * ck), used // ck % (nj + 1), used % ck], axis=1)
    return grid, tets


def faces_of(tets: np.ndarray) -> np.ndarray:
    """The distinct triangles (F, 3) of tetrahedra (N, 4), each once, in order of first appearance."""
    tri = tets[:, [[1, 2, 3], [0, 3, 2], [0, 1, 3], [0, 2, 1]]].reshape(-1, 3)   # the 4 faces
    key = np.sort(tri, axis=1)
    n = int(tets.max()) + 1 if len(tets) else 1
    words = (key[:, 0] * n + key[:, 1]) * n + key[:, 2]
    _, first = np.unique(words, return_index=True)
    return tri[np.sort(first)]


def tet_ventricle(spec: m.TetVentricle):
    """Vertices, faces (every distinct face of the tetrahedra), radial normals and per-vertex RGBA."""
    from gpusim.scene.geometry import MeshData, _unit

    ring = spec.theta_range_deg[1] - spec.theta_range_deg[0] == 360.0
    tip = spec.mu_range_deg[0] == 0.0
    grid, tets = tetrahedra(spec.divisions, ring, tip)
    ni, nj, nk = spec.divisions
    frac = grid.astype(np.float64) / [ni, nj, nk]
    rng = np.random.default_rng(spec.seed)
    move = (rng.random(frac.shape) * 2.0 - 1.0) * spec.jitter / [ni, nj, nk]
    inside = np.stack([(grid[:, 0] > 0) & (grid[:, 0] < ni),            # the surface stays where it is
                       (grid[:, 1] > 0) & (grid[:, 1] < nj),
                       ((grid[:, 2] > 0) & (grid[:, 2] < nk)) | ring], axis=1)
    frac = frac + np.where(inside, move, 0.0)
    (l0, l1), (u0, u1), (t0, t1) = spec.lambda_range, spec.mu_range_deg, spec.theta_range_deg
    lam = l0 + frac[:, 0] * (l1 - l0)
    mu = np.radians(u0 + frac[:, 1] * (u1 - u0))
    theta = np.radians(t0 + frac[:, 2] * (t1 - t0))
    d = spec.focal
    verts = np.stack([d * np.cosh(lam) * np.cos(mu), d * np.sinh(lam) * np.sin(mu) * np.cos(theta),
                      d * np.sinh(lam) * np.sin(mu) * np.sin(theta)], axis=1)
    normals = _unit(verts * [0.0, 1.0, 1.0] + [1e-9, 0.0, 0.0])        # away from the long axis
    shade = ((lam - l0) / (l1 - l0))[:, None]
    colour = np.asarray(spec.inner_color) * (1.0 - shade) + np.asarray(spec.color) * shade
    rgba = np.concatenate([colour, np.full((len(verts), 1), spec.alpha)], axis=1)
    return MeshData(verts, faces_of(tets).astype(np.int64), normals, rgba)
