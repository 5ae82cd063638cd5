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

import math
from dataclasses import dataclass
from typing import Literal

import numpy as np

from gpusim.metrics.composite import runs_by_length
from gpusim.schemes.common.arrays import put_rows, sort_within_runs
from gpusim.schemes.common.leading_zeros import colour_bits
from gpusim.schemes.common.storage import DEPTH_BYTES

Ties = Literal["arrival", "eq4"]


def unorm(values: np.ndarray, bits: int) -> np.ndarray:
    """Values in [0, 1] as ``bits``-bit unsigned normalised integers (round to nearest), int64."""
    return _unorm_steps(values, bits).astype(np.int64)


def _unorm_steps(values: np.ndarray, bits: int) -> np.ndarray:
    """:func:`unorm` as whole float64 numbers (exact: below 2**53)."""
    v = np.array(values, np.float64)          # a copy: the steps below work in place
    np.clip(v, 0.0, 1.0, out=v)
    v *= (1 << bits) - 1
    return np.rint(v, out=v)


def unorm_rounder(bits: int):
    """Round float32 values to what a ``bits``-bit unorm channel holds (float32 back)."""
    top = (1 << bits) - 1

    def rnd(v):
        steps = _unorm_steps(v, bits)
        steps /= top                          # the int64 unorm / top, without the int64
        return steps.astype(np.float32)
    return rnd


def check_fragment_bytes(fragment_bytes: int, bits: int) -> None:
    """ValueError unless a stored fragment has room for a 32-bit depth and four ``bits``-bit channels."""
    need = 8 * DEPTH_BYTES + 4 * bits
    if 8 * fragment_bytes < need:
        raise ValueError(f"fragment_bytes {fragment_bytes} cannot hold a 32-bit depth and four "
                         f"{bits}-bit channels ({math.ceil(need / 8)} bytes needed)")


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
        colour[:m] += w[:, None] * np.take(weighted, idx, axis=0)
        trans[:m] *= np.float32(1.0) - alpha[idx]
    put_rows(image, covered, colour + trans[:, None] * np.take(image, covered, axis=0))
    return image


@dataclass(frozen=True)
class StoredColours:
    """Integer colours of the stored fragments and what they cost in bits."""

    weighted: np.ndarray     # (N, 3) float32: a_i c_i as the read process sees it
    alpha: np.ndarray        # (N,) float32
    bits: np.ndarray         # (N,) int64: stored bits of each fragment


def stored_colours(rgba: np.ndarray, bits: int, fragment_bits: int, lze: str) -> StoredColours:
    """Quantise to ``bits`` per channel, compress (gpusim.schemes.common.leading_zeros), return the blended values."""
    top = np.float32((1 << bits) - 1)
    c = _unorm_steps(rgba[:, :3], bits)           # whole numbers: exact in float32 and int64 alike
    a = _unorm_steps(rgba[:, 3], bits)
    alpha = a.astype(np.float32) / top
    if lze == "off":
        weighted = c.astype(np.float32)
        weighted /= top
        weighted *= alpha[:, None]
        rgb_bits = np.full(len(c), 3 * bits, np.int64)
    else:
        pm = premultiply(c.astype(np.int64), a.astype(np.int64), bits)
        weighted = pm.astype(np.float32) / top
        rgb_bits = colour_bits(pm, bits, lze)
    return StoredColours(weighted, alpha, fragment_bits - 3 * bits + rgb_bits)


def weighted_image(trace, g, visible: np.ndarray, stored: np.ndarray, colours: StoredColours,
                   base: np.ndarray, ties: str) -> tuple[np.ndarray, np.ndarray]:
    """Eq. 2-4 image of the ``visible`` fragments over ``base``: ((H, W, 3) image, fragments in depth order).

    ``colours`` belong to the fragments ``stored`` (trace indices, a superset of the visible ones).
    """
    at = np.empty(len(trace), np.int64)            # each stored fragment's row in ``colours``
    at[stored] = np.arange(len(stored))
    # depth order: each pixel's visible fragments in arrival order, sorted in place (ties keep arrival)
    in_arrival = visible[g.by_arrival]
    arrived, pix = g.by_arrival[in_arrival], g.pix_by_arrival[in_arrival]
    key = g.key[arrived]
    nearest_first = sort_within_runs(pix, key)
    order = arrived[nearest_first]
    rows = at[order]
    image = composite_weighted(pix, key[nearest_first], np.take(colours.weighted, rows, axis=0),
                               colours.alpha[rows], base, ties)
    return image.reshape(trace.height, trace.width, 3), order
