"""Fragment traces: what the rasterizer emits and every later stage replays.

A :class:`FragmentTrace` is a set of columnar numpy arrays, one entry per
fragment, in *submission order* (primitive by primitive, and inside a primitive
in the rasterizer's documented order):

======== ================ ==================================================
array    dtype            meaning
======== ================ ==================================================
x, y     uint16           pixel column and row in OpenGL window coordinates
                          (origin at the bottom-left pixel, y grows upwards)
z        float32          window-space depth in [0, 1] (0 = near plane)
rgba     float32, (N, 4)  straight (non-premultiplied) colour and alpha in [0, 1]
prim     uint32           index of the input primitive that made the fragment
opaque   bool             True for an opaque surface (occludes what lies behind)
======== ================ ==================================================

The arrays are never copied into Python lists; all checks are vectorised.
"""

from __future__ import annotations

import reprlib
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from gpusim.errors import TraceError

#: Largest supported screen side in pixels (x and y are uint16; the rasterizer's
#: fixed-point arithmetic is exact up to this size).
MAX_SCREEN_SIDE = 16384

DTYPES: dict[str, np.dtype] = {
    "x": np.dtype(np.uint16),
    "y": np.dtype(np.uint16),
    "z": np.dtype(np.float32),
    "rgba": np.dtype(np.float32),
    "prim": np.dtype(np.uint32),
    "opaque": np.dtype(np.bool_),
}


@dataclass(eq=False)
class FragmentTrace:
    """Columnar fragments of one frame (see the module docstring for the arrays).

    ``meta`` is free metadata (JSON-serialisable): scene name, generator,
    gpusim version, background colour (``background``: RGB in [0, 1]).
    Construction validates shapes, dtypes and ranges (and the background) and raises
    :class:`~gpusim.errors.TraceError` naming the first offending fragment.
    """

    x: np.ndarray
    y: np.ndarray
    z: np.ndarray
    rgba: np.ndarray
    prim: np.ndarray
    opaque: np.ndarray
    width: int
    height: int
    meta: dict[str, Any] = field(default_factory=dict)
    source: str = field(default="<memory>", repr=False)

    def __post_init__(self) -> None:
        self.validate()

    # ------------------------------------------------------------------ checks
    def _fail(self, what: str, fix: str = "", fragment: int | None = None) -> None:
        problem = what + (f"; {fix}" if fix else "")
        raise TraceError(f"{self.source}: {problem}", fragment=fragment, problem=problem)

    def validate(self) -> None:
        """Check shapes, dtypes and value ranges; raise TraceError on the first problem."""
        for side, value in (("width", self.width), ("height", self.height)):
            if not isinstance(value, (int, np.integer)) or not 1 <= int(value) <= MAX_SCREEN_SIDE:
                self._fail(f"screen {side} {value!r} is outside 1..{MAX_SCREEN_SIDE}",
                           "give a screen size such as --size 512x512")
        self.width, self.height = int(self.width), int(self.height)
        n = None
        for name, dtype in DTYPES.items():
            arr = getattr(self, name)
            if not isinstance(arr, np.ndarray):
                self._fail(f"array '{name}' is a {type(arr).__name__}, not a numpy array")
            if arr.dtype != dtype:
                self._fail(f"array '{name}' has dtype {arr.dtype}, expected {dtype}",
                           "convert it before building the trace")
            want_ndim = 2 if name == "rgba" else 1
            if arr.ndim != want_ndim or (name == "rgba" and arr.shape[1] != 4):
                self._fail(f"array '{name}' has shape {arr.shape}, expected "
                           + ("(N, 4)" if name == "rgba" else "(N,)"))
            if n is None:
                n = arr.shape[0]
            elif arr.shape[0] != n:
                self._fail(f"array '{name}' has {arr.shape[0]} entries but 'x' has {n}",
                           "all arrays must have one entry per fragment")
        self._check_background()
        if n == 0:
            return
        self._check_below(self.x, self.width, "x", "pixel column")
        self._check_below(self.y, self.height, "y", "pixel row")
        self._check_unit_interval(self.z, "depth")
        self._check_unit_interval(self.rgba, "colour/alpha")

    def _check_background(self) -> None:
        if "background" not in self.meta:
            return
        value = self.meta["background"]
        try:
            rgb = np.asarray(value, dtype=np.float64)
        except (TypeError, ValueError):
            rgb = None
        if rgb is None or rgb.shape != (3,) or not np.all((rgb >= 0.0) & (rgb <= 1.0)):  # NaN fails too
            self._fail(f"metadata background {reprlib.repr(value)} is not an RGB colour in [0, 1]",
                       "set it to three numbers such as [1.0, 1.0, 1.0], or re-create the trace")

    def _check_below(self, arr: np.ndarray, limit: int, name: str, what: str) -> None:
        if int(arr.max()) >= limit:
            bad = int(np.flatnonzero(arr >= limit)[0])
            self._fail(f"fragment {bad} has {name}={int(arr[bad])}, outside the screen "
                       f"({what} must be < {limit})",
                       "fix the fragment or give a larger screen size", bad)

    def _check_unit_interval(self, arr: np.ndarray, what: str) -> None:
        lo, hi = float(arr.min()), float(arr.max())  # min/max propagate NaN
        if np.isnan(lo) or np.isnan(hi):
            bad = int(np.flatnonzero(np.isnan(arr).reshape(len(arr), -1).any(axis=1))[0])
            self._fail(f"fragment {bad} has NaN {what}", "every value must be a number in [0, 1]", bad)
        if np.isinf(lo) or np.isinf(hi):
            bad = int(np.flatnonzero(np.isinf(arr).reshape(len(arr), -1).any(axis=1))[0])
            self._fail(f"fragment {bad} has infinite {what}", "every value must be in [0, 1]", bad)
        if lo < 0.0 or hi > 1.0:
            outside = (arr < 0) | (arr > 1)
            bad = int(np.flatnonzero(outside.reshape(len(arr), -1).any(axis=1))[0])
            value = np.round(arr[bad], 6).tolist()
            self._fail(f"fragment {bad} has {what} {value} outside [0, 1]",
                       "clamp or rescale the values into [0, 1]", bad)

    # ------------------------------------------------------------------ views
    def __len__(self) -> int:
        return int(self.x.shape[0])

    @property
    def pixel_count(self) -> int:
        """Number of pixels on the screen (width x height)."""
        return self.width * self.height

    def pixel_ids(self) -> np.ndarray:
        """Linear pixel index ``y * width + x`` of every fragment (int64)."""
        return self.y.astype(np.int64) * self.width + self.x

    def depth_complexity(self) -> np.ndarray:
        """Fragments per pixel as an (height, width) int64 image (row 0 = bottom)."""
        counts = np.bincount(self.pixel_ids(), minlength=self.pixel_count)
        return counts.reshape(self.height, self.width)

    @property
    def background(self) -> np.ndarray:
        """Background RGB (float64) the frame is composited over; black if unset."""
        bg = np.asarray(self.meta.get("background", (0.0, 0.0, 0.0)), dtype=np.float64)
        return bg if bg.shape == (3,) else np.zeros(3)

    def subset(self, mask: np.ndarray) -> "FragmentTrace":
        """A new trace with the fragments where ``mask`` (booleans) is true, order kept, or those ``mask`` (indices)
        names, in its order (a permutation reorders the trace)."""
        mask = np.asarray(mask)
        rows = np.compress(mask, self.rgba, axis=0) if mask.dtype == bool else np.take(self.rgba, mask, axis=0)
        return FragmentTrace(self.x[mask], self.y[mask], self.z[mask], rows,   # rows: faster than rgba[mask]
                             self.prim[mask], self.opaque[mask], self.width, self.height,
                             dict(self.meta), self.source)

    @classmethod
    def empty(cls, width: int, height: int, meta: dict | None = None) -> "FragmentTrace":
        """A trace with no fragments on a ``width`` x ``height`` screen."""
        return cls(*(np.zeros((0, 4) if k == "rgba" else 0, dtype=d) for k, d in DTYPES.items()),
                   width=width, height=height, meta=dict(meta or {}))
