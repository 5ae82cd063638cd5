"""Storage formats of the colour a scheme keeps per fragment, and their sizes.

A stored colour is rounded to the format before it is composited, so a scheme's
image carries exactly the quantisation its memory layout implies:

========= ====== ==============================================================
format    bytes  what is stored
========= ====== ==============================================================
rgba8     4      8-bit unsigned normalised channels, round to nearest (1/255)
rgba16f   8      IEEE half-precision channels (round to nearest even)
rgba32f   16     single-precision channels (the trace's own precision: exact)
========= ====== ==============================================================
"""

from __future__ import annotations

from typing import Callable, Literal

import numpy as np

ColourFormat = Literal["rgba8", "rgba16f", "rgba32f"]
COLOUR_BYTES: dict[str, int] = {"rgba8": 4, "rgba16f": 8, "rgba32f": 16}
DEPTH_BYTES = 4   # 32-bit depth (float or ordered integer key)
POINTER_BYTES = 4  # 32-bit node index / counter


def rounder(fmt: str) -> Callable[[np.ndarray], np.ndarray]:
    """Round float32 values to what a texel or render target of format ``fmt`` holds.

    8-bit unorm formats (rgba8, r8) clamp to [0, 1] and round to the nearest
    1/255; half formats round to nearest even and hold +inf past 65504, as
    hardware does; 32-bit float formats keep the value.
    """
    if fmt in ("rgba8", "r8"):
        return lambda v: (np.rint(np.clip(v, 0, 1) * np.float32(255.0)) / np.float32(255.0)).astype(np.float32)
    if fmt in ("rgba16f", "r16f"):
        def half(v):
            with np.errstate(over="ignore"):
                return np.asarray(v).astype(np.float16).astype(np.float32)
        return half
    if fmt in ("rgba32f", "r32f"):
        return lambda v: np.asarray(v, dtype=np.float32)
    raise ValueError(f"unknown render-target format {fmt!r}")


def store_colour(rgba: np.ndarray, fmt: str) -> np.ndarray:
    """The (N, 4) float32 colour a ``fmt`` texel gives back when read."""
    if fmt not in COLOUR_BYTES:
        raise ValueError(f"unknown colour format {fmt!r} (valid: {', '.join(COLOUR_BYTES)})")
    return rounder(fmt)(np.asarray(rgba, dtype=np.float32))


def effective_alpha(rgba: np.ndarray, opaque: np.ndarray) -> np.ndarray:
    """Alpha used in compositing: 1 for opaque fragments, the stored alpha otherwise."""
    return np.where(opaque, np.float32(1.0), rgba[:, 3]).astype(np.float32)
