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

from gpusim.metrics.composite import run_starts
from gpusim.schemes.common.arrays import lex_order, put_rows, sort_short_runs
from gpusim.schemes.common.leading_zeros import colour_bits, significant_bits
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
                       base: np.ndarray, ties: str, rows: np.ndarray | None = None) -> np.ndarray:
    """Eq. 2-4 over grouped runs in depth order; returns (pixel_count, 3) float32.

    ``pix`` and ``key`` are grouped by pixel, nearest first (ties in arrival
    order); ``weighted`` is a_i c_i (N, 3); ``base`` (pixel_count, 3) is the
    colour behind every fragment (nearest opaque, or the background). With
    ``rows``, fragment i's ``weighted`` and ``alpha`` are at ``rows[i]``.

    The fragments are read once into rank-major order (every pixel's nearest, then every second nearest,
    ..., pixels longest run first), so step k adds one contiguous block to a prefix of the pixels.
    """
    image = np.array(base, dtype=np.float32, copy=True)
    if len(pix) == 0:
        return image
    start = run_starts(pix)
    length = np.diff(np.r_[start, len(pix)])
    by_length = lex_order(length.max() - length)            # longest first, equal lengths in pixel order
    start, length = start[by_length], length[by_length]
    active = np.searchsorted(-length, -(np.arange(length[0]) + 1), side="right").tolist()
    pos = np.concatenate([start[:m] + k for k, m in enumerate(active)])
    at = np.r_[0, np.cumsum(active)]
    src = pos if rows is None else rows[pos]
    weighted = np.take(np.asarray(weighted, np.float32), src, axis=0)
    alpha = np.take(np.asarray(alpha, np.float32), src)
    key = key[pos] if ties == "eq4" else None
    covered = pix[start]
    trans = np.ones(len(covered), np.float32)           # product over all fragments so far
    tie_w = np.ones(len(covered), np.float32)           # weight of the current tie group (eq4)
    colour = np.zeros((len(covered), 3), np.float32)
    for k, m in enumerate(active):
        lo = at[k]
        if ties == "eq4" and k > 0:
            new_group = key[lo:lo + m] != key[at[k - 1]:at[k - 1] + m]
            tie_w[:m] = np.where(new_group, trans[:m], tie_w[:m])
            w = tie_w[:m]
        else:
            tie_w[:m] = trans[:m]
            w = trans[:m]
        colour[:m] += w[:, None] * weighted[lo:lo + m]
        trans[:m] *= np.float32(1.0) - alpha[lo:lo + m]
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
    steps = _unorm_steps(rgba, bits)              # whole numbers: exact in float32 and int64 alike
    c, a = steps[:, :3], steps[:, 3]
    alpha = a.astype(np.float32) / top
    if lze == "off":
        weighted = c.astype(np.float32)
        weighted /= top
        weighted *= alpha[:, None]
        rgb_bits = np.full(len(c), 3 * bits, np.int64)
    elif bits <= 8 and lze in ("fixed", "variable"):
        # every (colour, alpha) pair's premultiplied value and its significant bits from tables of
        # (2**bits)**2 entries (the longest channel is the one with the most significant bits)
        every = np.arange(1 << bits, dtype=np.int64)
        table = ((every[:, None] * every + (1 << bits) // 2 - 1) // ((1 << bits) - 1)).ravel()   # premultiply
        level = steps.astype(np.intp)
        pair = level[:, :3] << bits
        pair |= level[:, 3:]
        weighted = (table.astype(np.float32) / top)[pair]
        sig = significant_bits(table).astype(np.uint8)[pair]
        if lze == "fixed":
            rgb_bits = 3 * np.maximum(np.maximum(sig[:, 0], sig[:, 1]), sig[:, 2]).astype(np.int64)
        else:
            rgb_bits = sig.sum(axis=1, dtype=np.int64)
    else:
        pm = premultiply(c.astype(np.int64), a.astype(np.int64), bits)
        weighted = pm.astype(np.float32) / top
        rgb_bits = colour_bits(pm, bits, lze)
    return StoredColours(weighted, alpha, fragment_bits - 3 * bits + rgb_bits)


def weighted_image(trace, g, visible: np.ndarray, stored: np.ndarray, colours: StoredColours,
                   base: np.ndarray, ties: str, visible_by_arrival: np.ndarray | None = None,
                   key_by_arrival: np.ndarray | None = None, row_by_arrival: np.ndarray | None = None,
                   with_pixels: bool = False):
    """Eq. 2-4 image of the ``visible`` fragments over ``base``: ((H, W, 3) image, fragments in depth order),
    with ``with_pixels`` their pixel ids too.

    ``colours`` belong to the fragments ``stored`` (trace indices, a superset of the visible ones).
    ``visible_by_arrival``, ``key_by_arrival`` and ``row_by_arrival``, when the caller has them, are
    ``visible``, the depth keys and each stored fragment's row in ``colours`` in the order ``g.by_arrival``.
    """
    # depth order: each pixel's visible fragments in arrival order, sorted in place (ties keep arrival)
    in_arrival = visible[g.by_arrival] if visible_by_arrival is None else visible_by_arrival
    arrived, pix = g.by_arrival[in_arrival], g.pix_by_arrival[in_arrival]
    key = g.key[arrived] if key_by_arrival is None else key_by_arrival[in_arrival]
    nearest_first = sort_short_runs(pix, key)
    order = arrived[nearest_first]
    if row_by_arrival is None:
        at = np.empty(len(trace), np.int64)            # each stored fragment's row in ``colours``
        at[stored] = np.arange(len(stored))
        rows = at[order]
    else:
        rows = row_by_arrival[in_arrival][nearest_first]
    image = composite_weighted(pix, key[nearest_first], colours.weighted, colours.alpha, base, ties, rows)
    image = image.reshape(trace.height, trace.width, 3)
    return (image, order, pix) if with_pixels else (image, order)   # the runs stay where they are: pix[order]
