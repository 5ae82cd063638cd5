"""Depth values as ordered 32-bit integers, and FreePipe's depth + colour packing.

CUDA's ``atomicMin`` compares integers, so FreePipe casts each float depth to an
integer "while maintaining consistent results" (seed 000 section 4.1.1). For a
non-negative IEEE-754 binary32 value the bit pattern read as an unsigned
integer is monotone in the value, so on [0, 1] the cast is exact and order
preserving: 0.0 -> 0x00000000, 1.0 -> 0x3F800000. :func:`depth_key`
implements it (with -0.0 first made +0.0, so both zeros get the same key) and
rejects NaN, whose bits would otherwise sort above 1.0. Keys never reach
:data:`EMPTY` (0xFFFFFFFF), the value MDTS initialises its array to.

Equal depths get equal keys: a scheme sees a tie exactly where the trace has one.

Packing (section 4.1.2) maps depth to [0.5, 1) so sign and exponent are the same
for every fragment, shifts the 23 mantissa bits to the top and clears the low 12
bits: 20 bits of depth remain and 12 bits are free for half of a 24-bit colour.
"""

from __future__ import annotations

import numpy as np

#: Value of an empty MDTS entry (FreePipe initialises the array to the maximum integer).
EMPTY = np.uint32(0xFFFFFFFF)
#: Largest binary32 value below 1.0; packing clamps 0.5 + 0.5 z to it (z = 1 would
#: otherwise change the exponent and wrap to the key of z = 0).
_BELOW_ONE = np.nextafter(np.float32(1.0), np.float32(0.0))


def depth_key(z: np.ndarray) -> np.ndarray:
    """Ordered uint32 key of each non-negative float32 depth (exact, monotone; rejects NaN)."""
    z = np.asarray(z, dtype=np.float32)
    if np.isnan(z).any():
        raise ValueError("depth is NaN; NaN has no place in a depth order (fix the trace)")
    if (z < 0).any():
        raise ValueError("depth is negative; window-space depth must lie in [0, 1]")
    return (z + np.float32(0.0)).view(np.uint32)   # -0.0 + 0.0 == +0.0


def key_depth(key: np.ndarray) -> np.ndarray:
    """The float32 depth a key came from (the exact inverse of :func:`depth_key`)."""
    return np.asarray(key, dtype=np.uint32).view(np.float32)


def packed_depth(z: np.ndarray) -> np.ndarray:
    """FreePipe's 20-bit depth in the top bits of a uint32 (low 12 bits zero)."""
    z = np.asarray(z, dtype=np.float32)
    mapped = np.minimum(np.float32(0.5) + np.float32(0.5) * z, _BELOW_ONE)   # float32 arithmetic
    bits = mapped.view(np.uint32)
    return (bits << np.uint32(9)) & np.uint32(0xFFFFF000)


def colour24(rgb: np.ndarray) -> np.ndarray:
    """RGB in [0, 1] -> 24-bit 0xRRGGBB with round-to-nearest 8-bit channels (uint32)."""
    c8 = np.rint(np.asarray(rgb, dtype=np.float32) * np.float32(255.0)).astype(np.uint32)
    return (c8[:, 0] << np.uint32(16)) | (c8[:, 1] << np.uint32(8)) | c8[:, 2]


def colour24_rgb(c24: np.ndarray) -> np.ndarray:
    """0xRRGGBB -> (N, 3) float RGB in [0, 1]."""
    c24 = np.asarray(c24, dtype=np.uint32)
    rgb = np.empty((len(c24), 3))
    for k, shift in enumerate((16, 8, 0)):
        rgb[:, k] = (c24 >> np.uint32(shift)) & np.uint32(0xFF)
    rgb /= 255.0
    return rgb
