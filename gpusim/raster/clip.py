"""Homogeneous clipping: near/far planes and an x/y guard band.

A triangle that lies wholly outside one screen or depth plane is dropped
(trivial rejection, vectorised). A triangle that crosses the near or far plane,
or reaches past the guard band (|x|, |y| > GUARD_BAND * w), is clipped with
Sutherland-Hodgman in clip space and re-triangulated as a fan that keeps the
primitive index; attributes are interpolated linearly in clip space, which is
exact for perspective-correct attributes. Guard-band clipping never changes
which pixels are covered; it keeps window coordinates small enough for the
rasterizer's exact 64-bit fixed-point arithmetic. Only the (rare) crossing
triangles go through the per-triangle loop.
"""

from __future__ import annotations

import numpy as np

from gpusim.raster.batch import TriangleBatch

#: |x_clip| and |y_clip| are kept within GUARD_BAND * w (the screen is 1 * w).
GUARD_BAND = 64.0

# inside <=> plane . (x, y, z, w) >= 0
_CLIP_PLANES = np.array([
    [0, 0, 1, 1],             # near: z >= -w
    [0, 0, -1, 1],            # far: z <= w
    [1, 0, 0, GUARD_BAND], [-1, 0, 0, GUARD_BAND],
    [0, 1, 0, GUARD_BAND], [0, -1, 0, GUARD_BAND],
], dtype=np.float64)
_SCREEN_PLANES = np.array([[1, 0, 0, 1], [-1, 0, 0, 1], [0, 1, 0, 1], [0, -1, 0, 1]], dtype=np.float64)
_ALL_PLANES = np.concatenate([_CLIP_PLANES, _SCREEN_PLANES])
assert all(np.count_nonzero(p[:3]) == 1 and np.abs(p[:3]).sum() == 1 and p[3] > 0
           and np.log2(p[3]) % 1 == 0 for p in _ALL_PLANES)   # the form _outside relies on
_CLIP = np.arange(len(_CLIP_PLANES))                    # planes that force clipping
_REJECT = np.array([0, 1, *range(len(_CLIP_PLANES), len(_ALL_PLANES))])  # near, far, screen


def _clip_polygon(verts: np.ndarray, attrs: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Sutherland-Hodgman against every clip plane; returns polygon vertices and attributes."""
    for plane in _CLIP_PLANES:
        if len(verts) == 0:
            break
        d = verts @ plane
        out_v, out_a = [], []
        n = len(verts)
        for i in range(n):
            j = (i + 1) % n
            if d[i] >= 0:
                out_v.append(verts[i])
                out_a.append(attrs[i])
            if (d[i] >= 0) != (d[j] >= 0):
                t = d[i] / (d[i] - d[j])
                out_v.append(verts[i] + t * (verts[j] - verts[i]))
                out_a.append(attrs[i] + t * (attrs[j] - attrs[i]))
        verts = np.array(out_v).reshape(-1, 4)
        attrs = np.array(out_a).reshape(-1, attrs.shape[1])
    return verts, attrs


def _outside(clip: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Per plane of _ALL_PLANES and triangle, whether all three vertices and whether any vertex
    lies outside it (plane . v < 0): two (planes, T) bool arrays.

    Every plane is s * coordinate + m * w with s = +-1 and m a power of two, so
    plane . v < 0 holds exactly when coordinate < -m*w (s = 1) or > m*w (s = -1):
    a comparison, with no rounded sum and no matrix product (whose threads cost more
    than the work).
    """
    v = np.ascontiguousarray(clip.transpose(2, 1, 0))          # (4, 3, T)
    bound = {m: v[3] * m for m in set(_ALL_PLANES[:, 3].tolist())}
    all_out = np.empty((len(_ALL_PLANES), len(clip)), dtype=bool)
    any_out = np.empty_like(all_out)
    for k, plane in enumerate(_ALL_PLANES):
        axis = int(np.flatnonzero(plane[:3])[0])
        m = float(plane[3])
        if plane[axis] > 0:
            out = np.less(v[axis], np.negative(bound[m]))
        else:
            out = np.greater(v[axis], bound[m])
        np.logical_and(out[0], out[1], out=all_out[k])
        all_out[k] &= out[2]
        np.logical_or(out[0], out[1], out=any_out[k])
        any_out[k] |= out[2]
    return all_out, any_out


def clip_triangles(batch: TriangleBatch) -> TriangleBatch:
    """Drop invisible triangles and clip crossing ones; submission order is kept."""
    if len(batch) == 0:
        return batch
    all_out, any_out = _outside(batch.clip)
    visible = ~all_out[_REJECT].any(axis=0)
    crossing = visible & any_out[_CLIP].any(axis=0)
    if not crossing.any():
        if visible.all():
            return batch
        return TriangleBatch(batch.clip[visible], batch.rgba[visible], batch.opaque[visible],
                             batch.prim[visible])
    keep_idx = np.flatnonzero(visible)
    pieces_clip, pieces_rgba, pieces_src = [], [], []
    for t in np.flatnonzero(crossing):
        verts, attrs = _clip_polygon(batch.clip[t], batch.rgba[t])
        if len(verts) < 3:
            continue
        fan = np.stack([np.zeros(len(verts) - 2, int), np.arange(1, len(verts) - 1),
                        np.arange(2, len(verts))], axis=1)
        pieces_clip.append(verts[fan])
        pieces_rgba.append(attrs[fan])
        pieces_src.append(np.full(len(fan), t))
    # merge untouched triangles and fan pieces, ordered by source triangle
    plain = keep_idx[~crossing[keep_idx]]
    src = np.concatenate([plain, *pieces_src]) if pieces_src else plain
    clip = np.concatenate([batch.clip[plain], *pieces_clip]) if pieces_clip else batch.clip[plain]
    rgba = np.concatenate([batch.rgba[plain], *pieces_rgba]) if pieces_rgba else batch.rgba[plain]
    order = np.argsort(src, kind="stable")
    src = src[order]
    return TriangleBatch(clip[order], rgba[order], batch.opaque[src], batch.prim[src])
