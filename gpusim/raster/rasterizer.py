"""A vectorised triangle rasterizer following OpenGL/Direct3D rules.

Rules (all exact, integer arithmetic where coverage is decided):

* Window coordinates: OpenGL convention, origin at the bottom-left corner of the
  screen, y up; pixel (x, y) has its sample (centre) at (x + 0.5, y + 0.5).
* Vertices are snapped to 1/256 pixel (8 sub-pixel bits, round to nearest).
* Coverage: a sample is covered when all three edge functions are >= 0, with the
  Direct3D top-left tie rule for samples exactly on an edge, applied (as in
  hardware and in Mesa's llvmpipe) in the raster frame where rows are stored
  first-to-last, i.e. y growing downwards from row 0. In OpenGL window
  coordinates (y up) that makes a sample on an edge belong to the triangle when
  the edge is a *left* edge or a horizontal *bottom* edge (interior above it).
  Two triangles sharing an edge therefore never both cover, and never both
  miss, a sample on it. Verified against Mesa llvmpipe (tests/test_mesa_agreement.py).
* Depth is window z (``z_ndc * 0.5 + 0.5``), interpolated linearly in screen
  space as OpenGL does; colour and alpha are interpolated perspective-correctly
  (through 1/w). Depth and colours are clamped to [0, 1] against rounding.
* Orientation: counter-clockwise in window coordinates is front-facing
  (``glFrontFace(GL_CCW)``); culling is optional.
* Clipping: see :mod:`gpusim.raster.clip`; no fragment leaves [0, 1] depth.
* Emission order (submission order): primitive by primitive; inside one
  primitive row by row with increasing window y (bottom to top), and inside a
  row with increasing x. Pieces of a clipped primitive follow each other.
* Degenerate (zero snapped area), culled and off-screen triangles emit nothing
  and cost no per-pixel work.

The work is split into row spans (per triangle and pixel row, the exact first
and last covered pixel from the three edge equations) and then fragments are
emitted span by span in bounded chunks into arrays allocated once.
"""

from __future__ import annotations

from typing import Literal

import numpy as np

from gpusim.raster.batch import TriangleBatch
from gpusim.raster.clip import clip_triangles
from gpusim.trace import DTYPES, MAX_SCREEN_SIDE, FragmentTrace

SUBPIXEL_BITS = 8
_ONE = 1 << SUBPIXEL_BITS        # one pixel in fixed point
_HALF = _ONE // 2                # pixel-centre offset
_ROWS_PER_CHUNK = 1 << 21
_FRAGMENTS_PER_CHUNK = 1 << 21


class _Setup:
    """Per-triangle fixed-point edge equations, bounding boxes and attribute planes."""

    def __init__(self, batch: TriangleBatch, width: int, height: int, cull: str):
        clip = batch.clip
        inv_w = 1.0 / clip[..., 3]
        fx = np.rint((clip[..., 0] * inv_w + 1.0) * (width / 2.0 * _ONE)).astype(np.int64)
        fy = np.rint((clip[..., 1] * inv_w + 1.0) * (height / 2.0 * _ONE)).astype(np.int64)
        x0, x1, x2 = fx[:, 0], fx[:, 1], fx[:, 2]
        y0, y1, y2 = fy[:, 0], fy[:, 1], fy[:, 2]
        area2 = (x1 - x0) * (y2 - y0) - (x2 - x0) * (y1 - y0)
        keep = area2 != 0
        if cull == "back":
            keep &= area2 > 0
        elif cull == "front":
            keep &= area2 < 0
        # pixel bounding box of the covered samples, clamped to the screen
        bx0 = np.maximum((np.minimum(np.minimum(x0, x1), x2) - _HALF + _ONE - 1) // _ONE, 0)
        bx1 = np.minimum((np.maximum(np.maximum(x0, x1), x2) - _HALF) // _ONE, width - 1)
        by0 = np.maximum((np.minimum(np.minimum(y0, y1), y2) - _HALF + _ONE - 1) // _ONE, 0)
        by1 = np.minimum((np.maximum(np.maximum(y0, y1), y2) - _HALF) // _ONE, height - 1)
        keep &= (bx0 <= bx1) & (by0 <= by1)
        sel = np.flatnonzero(keep)
        self.count = len(sel)
        self.prim, self.opaque = batch.prim[sel], batch.opaque[sel]
        self.x0, self.x1, self.y0, self.y1 = bx0[sel], bx1[sel], by0[sel], by1[sel]
        fx, fy, inv_w = fx[sel], fy[sel], inv_w[sel]
        z = (clip[sel, :, 2] * inv_w + 1.0) * 0.5
        rgba = batch.rgba[sel]
        # make every kept triangle counter-clockwise by swapping vertices 1 and 2
        flip = np.flatnonzero(area2[sel] < 0)
        for arr in (fx, fy, z, inv_w, rgba):
            arr[flip, 1], arr[flip, 2] = arr[flip, 2], arr[flip, 1].copy()
        area2 = np.abs(area2[sel])
        # edge k runs from vertex (k+1)%3 to (k+2)%3 and is opposite vertex k
        i, j = np.array([1, 2, 0]), np.array([2, 0, 1])
        self.ea = fy[:, i] - fy[:, j]                     # A_k = -(Yj - Yi)
        self.eb = fx[:, j] - fx[:, i]                     # B_k = Xj - Xi
        top_left = (self.ea > 0) | ((self.ea == 0) & (self.eb > 0))
        self.ebias = np.where(top_left, 0, -1)
        self.ex, self.ey = fx[:, i], fy[:, i]
        self.planes = self._attribute_planes(fx, fy, area2, z, inv_w, rgba)

    @staticmethod
    def _attribute_planes(fx, fy, area2, z, inv_w, rgba) -> tuple[np.ndarray, np.ndarray]:
        """Planes a0 + dadx*(x-x0) + dady*(y-y0) (pixel units) for z, 1/w and rgba/w, (T, 6, 3),
        and each triangle's vertex-0 position (x0, y0), (T, 2)."""
        px, py = fx / _ONE, fy / _ONE
        attrs = np.concatenate([z[..., None], inv_w[..., None], rgba * inv_w[..., None]], axis=2)  # (T,3,6)
        d1, d2 = attrs[:, 1] - attrs[:, 0], attrs[:, 2] - attrs[:, 0]
        x10, x20 = (px[:, 1] - px[:, 0])[:, None], (px[:, 2] - px[:, 0])[:, None]
        y10, y20 = (py[:, 1] - py[:, 0])[:, None], (py[:, 2] - py[:, 0])[:, None]
        area = (area2 / (_ONE * _ONE))[:, None]
        dadx = (d1 * y20 - d2 * y10) / area
        dady = (d2 * x10 - d1 * x20) / area
        planes = np.stack([attrs[:, 0], dadx, dady], axis=2)       # (T, 6, 3)
        origin = np.stack([px[:, 0], py[:, 0]], axis=1)
        return planes, origin

    def spans(self, tri: np.ndarray, py: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """First covered pixel and span length of pixel row ``py`` of triangles ``tri``."""
        ys = py.astype(np.int64) * _ONE + _HALF
        lo = self.x0[tri].copy()
        hi = self.x1[tri].copy()
        empty = np.zeros(len(tri), dtype=bool)
        for k in range(3):
            a = self.ea[tri, k]
            kk = a * (_HALF - self.ex[tri, k]) + self.eb[tri, k] * (ys - self.ey[tri, k]) + self.ebias[tri, k]
            pos, neg = a > 0, a < 0
            step = a * _ONE
            safe = np.where(a == 0, 1, step)
            lo = np.where(pos, np.maximum(lo, -(kk // safe)), lo)
            hi = np.where(neg, np.minimum(hi, kk // -safe), hi)
            empty |= (a == 0) & (kk < 0)
        length = np.where(empty, 0, np.maximum(hi - lo + 1, 0))
        return lo, length


def _row_spans(setup: _Setup):
    """All non-empty (triangle, row, first x, length) spans, in emission order."""
    nrows = setup.y1 - setup.y0 + 1
    out_tri, out_y, out_lo, out_len = [], [], [], []
    start = 0
    cum = np.cumsum(nrows)
    while start < setup.count:
        # take triangles until about _ROWS_PER_CHUNK rows are gathered
        base = cum[start - 1] if start else 0
        stop = max(int(np.searchsorted(cum, base + _ROWS_PER_CHUNK, side="right")), start + 1)
        tris = np.arange(start, stop)
        counts = nrows[start:stop]
        tri = np.repeat(tris, counts)
        first = np.repeat(np.cumsum(counts) - counts, counts)
        py = setup.y0[tri] + (np.arange(len(tri)) - first)
        lo, length = setup.spans(tri, py)
        nz = length > 0
        out_tri.append(tri[nz])
        out_y.append(py[nz].astype(np.int32))
        out_lo.append(lo[nz].astype(np.int32))
        out_len.append(length[nz])
        start = stop
    cat = lambda parts, dt: np.concatenate(parts).astype(dt) if parts else np.zeros(0, dt)  # noqa: E731
    return cat(out_tri, np.int64), cat(out_y, np.int32), cat(out_lo, np.int32), cat(out_len, np.int64)


def rasterize(batch: TriangleBatch, width: int, height: int,
              cull: Literal["none", "back", "front"] = "none", meta: dict | None = None,
              progress: bool | None = False) -> FragmentTrace:
    """Rasterize ``batch`` onto a ``width`` x ``height`` screen; returns the fragment trace.

    ``progress``: True shows a progress bar, None shows one only on a terminal.
    """
    if not (1 <= width <= MAX_SCREEN_SIDE and 1 <= height <= MAX_SCREEN_SIDE):
        raise ValueError(f"screen size {width}x{height} outside 1..{MAX_SCREEN_SIDE}")
    if cull not in ("none", "back", "front"):
        raise ValueError(f"cull must be none, back or front, not {cull!r}")
    setup = _Setup(clip_triangles(batch), width, height, cull)
    tri, py, lo, length = _row_spans(setup)
    total = int(length.sum())
    out = {name: np.empty((total, 4) if name == "rgba" else total, dtype)
           for name, dtype in DTYPES.items()}
    planes, origin = setup.planes
    ends = np.cumsum(length)
    bounds = [0]
    while bounds[-1] < len(length):  # row chunks of about _FRAGMENTS_PER_CHUNK fragments
        done = ends[bounds[-1] - 1] if bounds[-1] else 0
        nxt = int(np.searchsorted(ends, done + _FRAGMENTS_PER_CHUNK, side="right"))
        bounds.append(max(nxt, bounds[-1] + 1))
    from tqdm import tqdm

    bar = tqdm(total=total, unit="frag", unit_scale=True, disable=(None if progress is None else not progress),
               desc="rasterize", leave=False)
    pos = 0
    for a, b in zip(bounds[:-1], bounds[1:]):
        lens = length[a:b]
        n = int(lens.sum())
        row = np.repeat(np.arange(a, b), lens)
        first = np.repeat(np.cumsum(lens) - lens, lens)
        x = lo[row] + (np.arange(n) - first)
        y = py[row]
        t = tri[row]
        sl = slice(pos, pos + n)
        out["x"][sl], out["y"][sl] = x, y
        dx = (x + 0.5) - origin[t, 0]
        dy = (y + 0.5) - origin[t, 1]
        p = planes[t]                                              # (n, 6, 3)
        vals = p[:, :, 0] + p[:, :, 1] * dx[:, None] + p[:, :, 2] * dy[:, None]
        np.clip(vals[:, 0], 0.0, 1.0, out=out["z"][sl], casting="same_kind")
        np.clip(vals[:, 2:6] / vals[:, 1:2], 0.0, 1.0, out=out["rgba"][sl], casting="same_kind")
        out["prim"][sl] = setup.prim[t]
        out["opaque"][sl] = setup.opaque[t]
        pos += n
        bar.update(n)
    bar.close()
    return FragmentTrace(**out, width=width, height=height, meta=dict(meta or {}))
