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
emitted span by span into arrays allocated once. Two paths do it with the same
results bit for bit: compiled kernels (numba, :mod:`gpusim.raster.kernel`, one
triangle at a time) when numba imports, else numpy (all triangles at once, then
fragments in bounded chunks). Both evaluate the formulas of
:mod:`gpusim.raster.kernel`, written once.

Precision: set-up and interpolation are float64. Each fragment's value is
``a0 + dadx*dx + dady*dy`` of its triangle's plane (window z; 1/w; rgba/w,
divided by the interpolated 1/w); depth is clamped to [0, 1] and rounded to
float32, colour rounded to float32 and then clamped (a tiny negative stays -0.0). The
numpy path evaluates exactly these float64 operations, but per attribute over
chunks of about _FRAGMENTS_PER_CHUNK fragments that stay in cache, with each
span's plane values gathered once and repeated over its fragments; the kernels
evaluate them per fragment, vectorised over a triangle's fragments
(tests/test_raster_exact.py holds both to the plain formula bit for bit). Mesa's
llvmpipe keeps its plane coefficients and interpolates in float32; the two agree
on coverage (tests/test_mesa_agreement.py), not on the last bits of depth and
colour, and evaluating gpusim's planes in float32 instead would change about a
third of its depth and colour values.
"""

from __future__ import annotations

from typing import Literal

import numpy as np

from gpusim.raster.batch import TriangleBatch
from gpusim.raster import kernel
from gpusim.raster.clip import clip_triangles
from gpusim.raster.kernel import (HALF, ONE, SUBPIXEL_BITS, doubled_area, edge, gradients, pixel_range,
                                  plane, snap, window_depth)
from gpusim.trace import DTYPES, MAX_SCREEN_SIDE, FragmentTrace

_ROWS_PER_CHUNK = 1 << 16
_FRAGMENTS_PER_CHUNK = 1 << 14  # small enough for a chunk's float64 work to stay in cache
_FRAGMENTS_PER_CALL = 1 << 20   # compiled path: fragments per emission call (progress bar steps)
_GATHER_BELOW = 0.75             # set-up gathers the kept triangles when fewer are kept


class _Setup:
    """Per-triangle fixed-point edge equations, bounding boxes and attribute planes.

    Per-vertex, per-edge and per-attribute arrays are laid out (3, T) and (6, T),
    so that every step below is one contiguous numpy operation over all triangles.
    """

    def __init__(self, batch: TriangleBatch, width: int, height: int, cull: str):
        clip = np.ascontiguousarray(batch.clip.transpose(2, 1, 0))             # (4, 3, T)
        inv_w = 1.0 / clip[3]
        fx = snap(clip[0], inv_w, width / 2.0 * ONE).astype(np.int64)
        fy = snap(clip[1], inv_w, height / 2.0 * ONE).astype(np.int64)
        area2 = doubled_area(fx, fy)
        keep = area2 != 0
        if cull == "back":
            keep &= area2 > 0
        elif cull == "front":
            keep &= area2 < 0
        # pixel bounding box of the covered samples, clamped to the screen
        bx0, bx1 = pixel_range(fx.min(axis=0), fx.max(axis=0))
        by0, by1 = pixel_range(fy.min(axis=0), fy.max(axis=0))
        bx0, bx1 = np.maximum(bx0, 0), np.minimum(bx1, width - 1)
        by0, by1 = np.maximum(by0, 0), np.minimum(by1, height - 1)
        keep &= (bx0 <= bx1) & (by0 <= by1)
        sel = np.flatnonzero(keep)
        if len(sel) < _GATHER_BELOW * len(keep):       # set up the kept triangles only
            bx0, bx1, by0, by1, area2 = bx0[sel], bx1[sel], by0[sel], by1[sel], area2[sel]
            fx, fy, inv_w, z = fx[:, sel], fy[:, sel], inv_w[:, sel], clip[2][:, sel]
            rgba = batch.rgba[sel]
            self.prim, self.opaque = batch.prim[sel], batch.opaque[sel]
        else:     # set up every triangle (cheaper than gathering); dropped ones get no rows
            by1 = np.where(keep, by1, by0 - 1)
            area2 = np.where(area2 == 0, 1, area2)     # no division by zero for degenerate ones
            z, rgba, self.prim, self.opaque = clip[2], batch.rgba, batch.prim, batch.opaque
        self.count = len(bx0)
        self.x0, self.x1, self.y0, self.y1 = bx0, bx1, by0, by1
        # z, 1/w and rgba/w at each vertex, (6, 3, T)
        attrs = np.empty((6, 3, self.count))
        attrs[0] = window_depth(z, inv_w)
        attrs[1] = inv_w
        np.multiply(rgba.transpose(2, 1, 0), inv_w, out=attrs[2:])
        # make every kept triangle counter-clockwise by swapping vertices 1 and 2
        flip = area2 < 0
        if flip.any():
            for arr in (fx, fy, attrs):
                v1 = arr[..., 1, :].copy()
                np.copyto(arr[..., 1, :], arr[..., 2, :], where=flip)
                np.copyto(arr[..., 2, :], v1, where=flip)
        area2 = np.abs(area2)
        # edge k runs from vertex (k+1)%3 to (k+2)%3 and is opposite vertex k; per row Y the
        # value at pixel x is kk + ea*ONE*x, kk = ec + eb*Y (exact in int64)
        i, j = [1, 2, 0], [2, 0, 1]
        self.ea, self.eb, self.ec = edge(fx[i], fy[i], fx[j], fy[j])
        self.planes = self._attribute_planes(fx, fy, area2, attrs)

    @staticmethod
    def _attribute_planes(fx, fy, area2, attrs) -> tuple[np.ndarray, ...]:
        """Planes a0 + dadx*(x-x0) + dady*(y-y0) (pixel units) for z, 1/w and rgba/w: one (18, T)
        table of dadx, a0 and dady (6 rows each), and each triangle's vertex 0 (x0, y0), each (T,)."""
        px, py = fx / ONE, fy / ONE
        d1, d2 = attrs[:, 1] - attrs[:, 0], attrs[:, 2] - attrs[:, 0]
        x10, x20 = px[1] - px[0], px[2] - px[0]
        y10, y20 = py[1] - py[0], py[2] - py[0]
        area = area2 / (ONE * ONE)
        dadx, dady = gradients(d1, d2, x10, x20, y10, y20, area)
        return np.concatenate([dadx, attrs[:, 0], dady]), px[0], py[0]


def _row_spans(setup: _Setup):
    """All non-empty (triangle, row, first x, length) spans, in emission order."""
    nrows = setup.y1 - setup.y0 + 1
    cum = np.cumsum(nrows)
    y_off = setup.y0 - (cum - nrows)          # py = y_off + global row index
    ea = setup.ea
    div = np.where(ea == 0, 1, np.abs(ea) * ONE)
    pos, neg = ea > 0, ea < 0
    out_tri, out_y, out_lo, out_len = [], [], [], []
    start = 0
    while start < setup.count:
        # take triangles until about _ROWS_PER_CHUNK rows are gathered
        base = cum[start - 1] if start else 0
        stop = max(int(np.searchsorted(cum, base + _ROWS_PER_CHUNK, side="right")), start + 1)
        counts = nrows[start:stop]
        each = lambda per_tri: np.repeat(per_tri[..., start:stop], counts, axis=-1)  # noqa: E731
        py = np.arange(base, cum[stop - 1]) + each(y_off)
        ys = py * ONE + HALF
        lo, hi = each(setup.x0), each(setup.x1)
        # edge k at pixel x of row ys: kk + ea*ONE*x >= 0, kk = ec + eb*ys
        kk = each(setup.eb)
        kk *= ys
        kk += each(setup.ec)
        kk //= each(div)                                  # floor(kk / (|ea| * ONE))
        left, right = each(pos), each(neg)
        empty = np.zeros(len(py), dtype=bool)
        for k in range(3):
            np.maximum(lo, np.negative(kk[k]), out=lo, where=left[k])
            np.minimum(hi, kk[k], out=hi, where=right[k])
            empty |= ~(left[k] | right[k]) & (kk[k] < 0)
        length = hi - lo + 1
        keep = ~empty & (length > 0)
        out_tri.append(np.repeat(np.arange(start, stop), counts)[keep])
        out_y.append(py[keep].astype(np.int32))
        out_lo.append(lo[keep].astype(np.int32))
        out_len.append(length[keep])
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
    from tqdm import tqdm

    bar = tqdm(unit="frag", unit_scale=True, disable=(None if progress is None else not progress),
               desc="rasterize", leave=False)
    compiled = kernel.compiled()
    clipped = clip_triangles(batch)
    with bar:
        if compiled is not None:
            out = _emit_compiled(compiled, clipped, width, height, cull, bar)
        else:
            out = _emit_numpy(_Setup(clipped, width, height, cull), bar)
    return FragmentTrace(**out, width=width, height=height, meta=dict(meta or {}))


def _emit_compiled(compiled, batch: TriangleBatch, width: int, height: int, cull: str, bar) -> dict:
    """Set-up, spans and fragments by the compiled kernels, straight into the trace's arrays,
    over ranges of triangles of about _FRAGMENTS_PER_CALL fragments."""
    count = len(batch)
    ints = np.empty((count, kernel.INTS), np.int64)
    floats = np.empty((count, kernel.FLOATS))
    offsets = np.zeros(count + 1, np.int64)
    compiled.setup(batch.clip, batch.rgba, width, height, kernel.CULL[cull], ints, floats, offsets[1:])
    np.cumsum(offsets, out=offsets)
    total = int(offsets[-1])
    bar.reset(total)
    out = {name: np.empty((total, 4) if name == "rgba" else total, dtype) for name, dtype in DTYPES.items()}
    first = 0
    while first < count:
        last = int(np.searchsorted(offsets, offsets[first] + _FRAGMENTS_PER_CALL, side="right")) - 1
        last = min(max(last, first + 1), count)
        compiled.emit(first, last, height, ints, floats, offsets, batch.prim, batch.opaque,
                      out["x"], out["y"], out["z"], out["rgba"].reshape(-1), out["prim"], out["opaque"])
        bar.update(int(offsets[last] - offsets[first]))
        first = last
    return out


def _emit_numpy(setup: _Setup, bar) -> dict:
    """Fragments by numpy: span constants repeated over chunks of about _FRAGMENTS_PER_CHUNK
    fragments."""
    tri, py, lo, length = _row_spans(setup)
    total = int(length.sum())
    bar.reset(total)
    # per-span constants spread over the span's fragments directly into the outputs
    out = {"y": np.repeat(py.astype(np.uint16), length),
           "prim": np.repeat(setup.prim[tri], length),
           "opaque": np.repeat(setup.opaque[tri], length)}
    for name in ("x", "z", "rgba"):
        out[name] = np.empty((total, 4) if name == "rgba" else total, DTYPES[name])
    table, ox, oy = setup.planes
    ends = np.cumsum(length)
    bounds = [0]
    while bounds[-1] < len(length):  # row chunks of about _FRAGMENTS_PER_CHUNK fragments
        done = ends[bounds[-1] - 1] if bounds[-1] else 0
        nxt = int(np.searchsorted(ends, done + _FRAGMENTS_PER_CHUNK, side="right"))
        bounds.append(max(nxt, bounds[-1] + 1))
    steps = np.arange(max(_FRAGMENTS_PER_CHUNK, int(length.max(initial=0))))   # j, then j + 0.5
    half_steps = steps + 0.5
    pos = 0
    for a, b in zip(bounds[:-1], bounds[1:]):
        # per span (row): the 6 planes' dadx, a0 and dady*dy, and dx of the span's pixel 0
        lens, t = length[a:b], tri[a:b]
        n = int(ends[b - 1]) - pos
        x_base = lo[a:b] - (ends[a:b] - lens - pos)      # x = x_base + j, j = fragment index in chunk
        per_row = np.empty((19, b - a))
        np.take(table, t, axis=1, out=per_row[0:18])
        per_row[12:18] *= (py[a:b] + 0.5) - oy[t]
        np.subtract(x_base, ox[t], out=per_row[18])
        sl = slice(pos, pos + n)
        np.add(np.repeat(x_base, lens), steps[:n], out=out["x"][sl], casting="unsafe")
        dx = np.repeat(per_row[18], lens)
        dx += half_steps[:n]                             # (x + 0.5) - x0, exact
        rgba = out["rgba"][sl]
        for k in (1, 0, 2, 3, 4, 5):
            # the same float64 operations, in the same order, as a0 + dadx*dx + dady*dy per fragment
            dadx, a0, dady_dy = np.repeat(per_row[k:18:6], lens, axis=1)
            val = plane(dadx, dx, a0, dady_dy)
            if k == 1:
                inv_w = val
            elif k == 0:
                np.clip(val, 0.0, 1.0, out=out["z"][sl], casting="same_kind")
            else:
                np.divide(val, inv_w, out=rgba[:, k - 2], casting="same_kind")
        np.clip(rgba, 0.0, 1.0, out=rgba)    # after rounding to float32: a tiny negative stays -0.0
        pos += n
        bar.update(n)
    return out
