"""Weight-factor compositing (Amor et al. 2006, seed 003 section 2.5.2, Eq. 2-4) and n-bit colours.

Eq. 2-4: c = sum_i w_i a_i c_i + w_o c_o, with w_i = prod over the fragments j
in front of i (Z_j < Z_i) of (1 - a_j), and w_o (the weight of the nearest
opaque fragment, or the background) the product over every visible fragment.
The weights do not depend on the order the fragments were stored in, so the
storage can keep arrival order.

Equal depths: Eq. 4 as printed (``ties = "eq4"``) lets no fragment of a tie
attenuate another, so two coincident layers both count at full weight (a
brightening the exact reference does not have). ``ties = "arrival"`` breaks
ties by arrival (the earlier fragment in front), which is the reference's
order: a hardware comparator that also compares the storage index.

Arithmetic is float32 (a shader). A pixel with thousands of fragments costs
thousands of vector steps over the pixels that deep, never a Python loop per
fragment.
"""

from __future__ import annotations

import numpy as np

from gpusim.metrics.composite import runs_by_length


def unorm(values: np.ndarray, bits: int) -> np.ndarray:
    """Values in [0, 1] as ``bits``-bit unsigned normalised integers (round to nearest), int64."""
    top = (1 << bits) - 1
    return np.rint(np.clip(np.asarray(values, np.float64), 0.0, 1.0) * top).astype(np.int64)


def premultiply(colour: np.ndarray, alpha: np.ndarray, bits: int) -> np.ndarray:
    """``bits``-bit colour times ``bits``-bit alpha, rounded, as a GPU's unorm multiply does (int64)."""
    top = (1 << bits) - 1
    return (colour * alpha[..., None] + top // 2) // top


def composite_weighted(pix: np.ndarray, key: np.ndarray, weighted: np.ndarray, alpha: np.ndarray,
                       base: np.ndarray, ties: str) -> np.ndarray:
    """Eq. 2-4 over grouped runs in depth order; returns (pixel_count, 3) float32.

    ``pix`` and ``key`` are grouped by pixel, nearest first (ties in arrival
    order); ``weighted`` is a_i c_i (N, 3); ``base`` (pixel_count, 3) is the
    colour behind every fragment (nearest opaque, or the background).
    """
    image = np.array(base, dtype=np.float32, copy=True)
    if len(pix) == 0:
        return image
    weighted = np.asarray(weighted, np.float32)
    alpha = np.asarray(alpha, np.float32)
    start, _, active = runs_by_length(pix)
    covered = pix[start]
    trans = np.ones(len(covered), np.float32)           # product over all fragments so far
    tie_w = np.ones(len(covered), np.float32)           # weight of the current tie group (eq4)
    colour = np.zeros((len(covered), 3), np.float32)
    for k, m in enumerate(active):
        idx = start[:m] + k
        if ties == "eq4" and k > 0:
            new_group = key[idx] != key[idx - 1]
            tie_w[:m] = np.where(new_group, trans[:m], tie_w[:m])
            w = tie_w[:m]
        else:
            tie_w[:m] = trans[:m]
            w = trans[:m]
        colour[:m] += w[:, None] * weighted[idx]
        trans[:m] *= np.float32(1.0) - alpha[idx]
    image[covered] = colour + trans[:, None] * image[covered]
    return image
