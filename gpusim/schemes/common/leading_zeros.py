"""Leading-0s elimination of stored colour (seed 003 section 3.3, Figures 3-10 to 3-14).

The RGB channels are first multiplied by alpha (the thesis's right shift "based
on the fragment's alpha value"; here the exact unorm multiply, which equals the
shift when alpha is a power of two), then stripped of leading zero bits:

* ``fixed`` (the thesis): the smallest leading-zero count among R, G and B is
  removed from all three, so each keeps L = bits - min(lz) bits; the Length
  Table stores L (0..bits) per fragment.
* ``variable`` (the thesis's future work, section 5.2): each channel keeps its
  own length; the Length Table stores three lengths per fragment.
* ``off``: colours are stored straight (not premultiplied) at full width.

Alpha and depth are stored uncompressed. A zero channel has ``bits`` leading
zeros (it keeps 0 bits).
"""

from __future__ import annotations

from typing import Literal

import numpy as np

LzeMode = Literal["off", "fixed", "variable"]


def significant_bits(values: np.ndarray) -> np.ndarray:
    """Bits needed to write each non-negative integer (below 2**53) without leading zeros (0 for 0)."""
    v = np.maximum(np.asarray(values, np.int64), 0)
    if v.size and int(v.max()) < 1 << 16:          # small values (colour channels): look them up
        return _significant_bits_float(np.arange(int(v.max()) + 1))[v]
    return _significant_bits_float(v)


def _significant_bits_float(v: np.ndarray) -> np.ndarray:
    v = v.astype(np.float64)                      # exact below 2**53
    return np.frexp(v)[1].astype(np.int64)        # v = m * 2**e with m in [0.5, 1): e bits (0 -> 0)


def colour_bits(rgb: np.ndarray, bits: int, mode: str) -> np.ndarray:
    """Stored RGB bits per fragment for integer channels ``rgb`` (N, 3) of width ``bits``."""
    if mode == "off":
        return np.full(len(rgb), 3 * bits, np.int64)
    if mode == "fixed":         # the longest channel: the bits of the largest
        rgb = np.asarray(rgb)
        return 3 * significant_bits(np.maximum(np.maximum(rgb[:, 0], rgb[:, 1]), rgb[:, 2]))
    if mode == "variable":
        return significant_bits(rgb).sum(axis=1)
    raise ValueError(f"unknown leading-0s elimination mode {mode!r}")


def length_field_bits(bits: int, mode: str) -> int:
    """Bits of one fragment's Length Table field: one length (fixed) or three (variable)."""
    one = int(bits).bit_length()          # lengths 0..bits
    return {"off": 0, "fixed": one, "variable": 3 * one}[mode]
