"""The rasterizer's arithmetic, written once, and its compiled kernels.

The formulas here (:func:`snap`, :func:`window_depth`, :func:`doubled_area`,
:func:`pixel_range`, :func:`edge`, :func:`gradients`, :func:`plane`) are the rasterizer's
rules in numbers. The numpy path of :mod:`gpusim.raster.rasterizer` applies them to arrays of
all triangles or fragments; the kernels below, compiled with numba, apply the very same
functions to one triangle's or fragment's scalars. Either way each is the same IEEE float64
operations in the same order (numba without ``fastmath`` keeps them: LLVM contracts no
multiply-add into an FMA without fast-math flags), so the two paths give the same traces bit
for bit (tests/test_raster_kernel.py); the integer coverage arithmetic is exact in both.

:func:`compiled` returns the kernels, or None when numba cannot be imported (or
``NUMBA_DISABLE_JIT`` is set), and the rasterizer then takes its numpy path:

* ``setup`` takes every clipped triangle once: snapping, area, culling, bounding box,
  winding, edge equations and the six attribute planes, and counts its fragments row by row.
* ``emit`` walks a range of triangles and writes each fragment's x, y, z, rgba, primitive and
  opaque flag straight into the trace's arrays at the triangle's offset. It allocates nothing
  per fragment, so memory is the trace itself plus a few hundred bytes per triangle however
  many fragments the frame has; the rasterizer calls it on ranges of triangles of about a
  million fragments each, to update its progress bar.

Compiling takes a few seconds, once: the kernels are cached on disk next to this file, or in
numba's per-user cache directory when that is not writable (``NUMBA_CACHE_DIR`` chooses
another); with no writable place they are compiled in each process, without a warning. numba
invalidates a cached kernel when its own source file changes, not when a function it calls
from another file does: that is why the formulas and constants live in this file with the
kernels. numba is imported on the first rasterization, not with gpusim.
"""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager
from types import SimpleNamespace

import numpy as np

from gpusim.jit import njit, numba_usable


SUBPIXEL_BITS = 8
ONE = 1 << SUBPIXEL_BITS        # one pixel in fixed point
HALF = ONE // 2                 # pixel-centre offset


# ---------------------------------------------------------------- the formulas (arrays or scalars)

def snap(coord, inv_w, scale):
    """A clip-space coordinate in window fixed point, rounded (still a float): ``scale`` is
    half the screen side times ONE."""
    return np.rint((coord * inv_w + 1.0) * scale)


def window_depth(z, inv_w):
    """Window depth ``z_ndc * 0.5 + 0.5`` of clip-space z."""
    return (z * inv_w + 1.0) * 0.5


def doubled_area(fx, fy):
    """Twice the signed area of the triangle with fixed-point vertices ``fx[v]``, ``fy[v]``
    (exact; positive when counter-clockwise in window coordinates)."""
    return (fx[1] - fx[0]) * (fy[2] - fy[0]) - (fx[2] - fx[0]) * (fy[1] - fy[0])


def pixel_range(lo, hi):
    """First and last pixel whose centre lies in the fixed-point interval [lo, hi] (>> is
    floor division)."""
    return (lo - HALF + ONE - 1) >> SUBPIXEL_BITS, (hi - HALF) >> SUBPIXEL_BITS


def edge(xi, yi, xj, yj):
    """The edge from fixed-point vertex i to vertex j of a counter-clockwise triangle as
    (a, b, c): in pixel row py (sample y = py*ONE + HALF) the pixel px is inside it when
    ``c + b*(py*ONE + HALF) + a*ONE*px >= 0``. ``c`` carries the top-left rule: a sample
    exactly on the edge is inside for a left edge (a > 0) or a horizontal bottom one."""
    a, b = yi - yj, xj - xi
    bias = ((a > 0) | ((a == 0) & (b > 0))) - 1       # 0 (inside) or -1 (outside) on the edge
    return a, b, a * (HALF - xi) - b * yi + bias


def gradients(d1, d2, x10, x20, y10, y20, area):
    """A plane's (dadx, dady) from its values' differences at vertices 1 and 2 against vertex 0,
    the vertices' differences in pixels and the triangle's area in pixels."""
    return (d1 * y20 - d2 * y10) / area, (d2 * x10 - d1 * x20) / area


def plane(dadx, dx, a0, dady_dy):
    """A plane at a fragment: ``dadx*dx + a0 + dady*dy``, its row's ``dady*dy`` given."""
    return dadx * dx + a0 + dady_dy


# ---------------------------------------------------------------- the kernels (scalar code)

# per-triangle integer table: the three edges' a, b and c, then the pixel bounding box
EA, EB, EC, X0, X1, Y0, Y1 = 0, 3, 6, 9, 10, 11, 12
INTS = 13
# per-triangle float table: the six planes' dadx, a0 and dady, then vertex 0 (x0, y0) in pixels
DADX, A0, DADY, OX, OY = 0, 6, 12, 18, 19
FLOATS = 20
CULL = {"none": 0, "back": 1, "front": 2}

# What the kernels call: the formulas above, replaced by their compiled versions in compiled().
_snap, _window_depth, _doubled_area, _pixel_range, _edge, _gradients, _plane = (
    snap, window_depth, doubled_area, pixel_range, edge, gradients, plane)


def _clip01(v):
    """``np.clip(v, 0, 1)`` of one value: nan and -0.0 pass through, as numpy's do."""
    v = 0.0 if v < 0.0 else v
    return 1.0 if v > 1.0 else v


def _spans(ints, t, first, last, state):
    """First and last covered pixel of triangle ``t`` in each of its pixel rows into ``first``
    and ``last`` (last < first: none); returns the number of rows. ``state``: (5, 3) scratch.

    Edge k covers pixel x of row py when kk + a*ONE*x >= 0, kk = c + b*(py*ONE + HALF) (see
    :func:`edge`): from the left (a > 0) from x = -floor(kk / (a*ONE)) on, from the right
    (a < 0) up to x = floor(kk / (-a*ONE)), and a horizontal edge (a = 0) the whole row or
    none. The floor is divided once per edge, then carried from row to row exactly: kk grows
    by b*ONE a row, the quotient by that step's quotient, the remainder with a carry."""
    y0, rows = ints[t, Y0], ints[t, Y1] - ints[t, Y0] + 1
    q, r, d, dq, dr = state[0], state[1], state[2], state[3], state[4]
    for k in range(3):
        a, b = ints[t, EA + k], ints[t, EB + k]
        d[k] = abs(a) * ONE if a != 0 else 1
        kk = b * (y0 * ONE + HALF) + ints[t, EC + k]
        q[k] = kk // d[k]
        r[k] = kk - q[k] * d[k]
        dq[k] = (b * ONE) // d[k]
        dr[k] = b * ONE - dq[k] * d[k]
    for row in range(rows):
        lo, hi = ints[t, X0], ints[t, X1]
        for k in range(3):
            a = ints[t, EA + k]
            if a > 0:
                lo = max(lo, -q[k])
            elif a < 0:
                hi = min(hi, q[k])
            elif q[k] < 0:
                hi = lo - 1
            q[k] += dq[k]
            r[k] += dr[k]
            if r[k] >= d[k]:
                r[k] -= d[k]
                q[k] += 1
        first[row], last[row] = lo, hi
    return rows


def _setup(clip, rgba, width, height, cull, ints, floats, counts):
    """Set up every triangle of ``clip`` (T, 3, 4) and ``rgba`` (T, 3, 4) on a ``width`` x
    ``height`` screen into ``ints`` (T, INTS), ``floats`` (T, FLOATS) and ``counts`` (T,): its
    fragments, 0 for a culled, degenerate or off-screen one (``cull``: a value of CULL)."""
    sx, sy = width / 2.0 * ONE, height / 2.0 * ONE
    fx, fy, attrs = np.empty(3, np.int64), np.empty(3, np.int64), np.empty((6, 3))
    first, last, state = np.empty(height, np.int64), np.empty(height, np.int64), np.empty((5, 3), np.int64)
    for t in range(clip.shape[0]):
        counts[t] = 0
        for v in range(3):
            inv_w = 1.0 / clip[t, v, 3]
            fx[v] = np.int64(_snap(clip[t, v, 0], inv_w, sx))
            fy[v] = np.int64(_snap(clip[t, v, 1], inv_w, sy))
            attrs[0, v] = _window_depth(clip[t, v, 2], inv_w)
            attrs[1, v] = inv_w
            for c in range(4):
                attrs[2 + c, v] = rgba[t, v, c] * inv_w
        area2 = _doubled_area(fx, fy)
        if area2 == 0 or (cull == 1 and area2 < 0) or (cull == 2 and area2 > 0):
            continue
        x0, x1 = _pixel_range(min(fx[0], fx[1], fx[2]), max(fx[0], fx[1], fx[2]))
        y0, y1 = _pixel_range(min(fy[0], fy[1], fy[2]), max(fy[0], fy[1], fy[2]))
        x0, x1, y0, y1 = max(x0, 0), min(x1, width - 1), max(y0, 0), min(y1, height - 1)
        if x0 > x1 or y0 > y1:
            continue
        if area2 < 0:            # clockwise: swap vertices 1 and 2
            fx[1], fx[2] = fx[2], fx[1]
            fy[1], fy[2] = fy[2], fy[1]
            for a in range(6):
                attrs[a, 1], attrs[a, 2] = attrs[a, 2], attrs[a, 1]
            area2 = -area2
        ints[t, X0], ints[t, X1], ints[t, Y0], ints[t, Y1] = x0, x1, y0, y1
        for k in range(3):       # edge k runs from vertex (k+1)%3 to (k+2)%3, opposite vertex k
            i, j = (k + 1) % 3, (k + 2) % 3
            ints[t, EA + k], ints[t, EB + k], ints[t, EC + k] = _edge(fx[i], fy[i], fx[j], fy[j])
        px0, py0 = fx[0] / ONE, fy[0] / ONE
        x10, x20 = fx[1] / ONE - px0, fx[2] / ONE - px0
        y10, y20 = fy[1] / ONE - py0, fy[2] / ONE - py0
        area = area2 / (ONE * ONE)
        for a in range(6):
            d1, d2 = attrs[a, 1] - attrs[a, 0], attrs[a, 2] - attrs[a, 0]
            floats[t, DADX + a], floats[t, DADY + a] = _gradients(d1, d2, x10, x20, y10, y20, area)
            floats[t, A0 + a] = attrs[a, 0]
        floats[t, OX], floats[t, OY] = px0, py0
        n = 0
        for row in range(_spans(ints, t, first, last, state)):
            n += max(last[row] - first[row] + 1, 0)
        counts[t] = n


def _emit(begin, end, height, ints, floats, offsets, prim, opaque, x, y, z, rgba, prim_out, opaque_out):
    """Write the fragments of triangles ``begin`` to ``end - 1`` into the trace's arrays, from
    each triangle's ``offsets`` entry on: row by row upwards, each row left to right. ``rgba``
    is the trace's (N, 4) array flattened; ``height``: the screen's. Depth and colour are
    rounded to the precision of ``z`` and ``rgba`` (float32 in a trace; float64 arrays give
    the unrounded values, which tests/test_raster_kernel.py checks bit for bit)."""
    first, last, state = np.empty(height, np.int64), np.empty(height, np.int64), np.empty((5, 3), np.int64)
    for t in range(begin, end):
        start, stop = offsets[t], offsets[t + 1]
        if start == stop:
            continue
        pos, y0 = start, ints[t, Y0]
        for row in range(_spans(ints, t, first, last, state)):     # x and y of each fragment
            lo, n = first[row], last[row] - first[row] + 1
            if n > 0:
                xs, ys = x[pos:pos + n], y[pos:pos + n]
                for j in range(n):
                    xs[j] = lo + j
                    ys[j] = y0 + row
                pos += n
        prim_out[start:stop] = prim[t]
        opaque_out[start:stop] = opaque[t]
        # depth and colour: one loop over the triangle's fragments, which the compiler
        # vectorises, with the planes in locals so that they stay in registers
        ox, oy = floats[t, OX], floats[t, OY]
        dz, dw, dr, dg, db, da = floats[t, DADX:DADX + 6]
        az, aw, ar, ag, ab, aa = floats[t, A0:A0 + 6]
        gz, gw, gr, gg, gb, ga = floats[t, DADY:DADY + 6]
        xs, ys, zs, cs = x[start:stop], y[start:stop], z[start:stop], rgba[4 * start:4 * stop]
        for j in range(stop - start):
            dx, dy = (xs[j] + 0.5) - ox, (ys[j] + 0.5) - oy
            inv_w = _plane(dw, dx, aw, gw * dy)
            zs[j] = _clip01(_plane(dz, dx, az, gz * dy))      # clipped, then stored (rounded)
            # colour: stored (rounded), then clipped, as the numpy path does
            cs[4 * j] = _plane(dr, dx, ar, gr * dy) / inv_w
            cs[4 * j + 1] = _plane(dg, dx, ag, gg * dy) / inv_w
            cs[4 * j + 2] = _plane(db, dx, ab, gb * dy) / inv_w
            cs[4 * j + 3] = _plane(da, dx, aa, ga * dy) / inv_w
            for c in range(4):
                cs[4 * j + c] = _clip01(cs[4 * j + c])

_COMPILED: list = []      # [the kernels or None], decided on first use


def compiled() -> SimpleNamespace | None:
    """The compiled kernels (``setup``, ``emit``, ``clip01``), built on the first call; None
    when numba cannot be imported or NUMBA_DISABLE_JIT is set."""
    if not _COMPILED:
        _COMPILED.append(_compile())
    return _COMPILED[0]


@contextmanager
def numpy_path() -> Iterator[None]:
    """Within the block the rasterizer takes its numpy path (to compare the two)."""
    saved = _COMPILED[:]
    _COMPILED[:] = [None]
    try:
        yield
    finally:
        _COMPILED[:] = saved


def _compile() -> SimpleNamespace | None:
    if not numba_usable():
        return None
    jit = njit

    global _snap, _window_depth, _doubled_area, _pixel_range, _edge, _gradients, _plane, _clip01, _spans
    _snap, _window_depth, _doubled_area, _pixel_range, _edge, _gradients, _plane = (
        jit(f) for f in (snap, window_depth, doubled_area, pixel_range, edge, gradients, plane))
    _clip01, _spans = jit(_clip01), jit(_spans)
    return SimpleNamespace(setup=jit(_setup), emit=jit(_emit), clip01=_clip01)
