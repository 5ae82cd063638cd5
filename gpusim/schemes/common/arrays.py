"""Helpers for schemes that keep a fixed array of entries per pixel."""

from __future__ import annotations

from typing import Literal

import numpy as np

from gpusim.metrics.composite import run_starts

Layout = Literal["pixel-major", "layer-major"]


def entry_index(pixel: np.ndarray, slot: np.ndarray, layers: int, pixel_count: int,
                layout: str) -> np.ndarray:
    """Linear entry index of (pixel, slot) in a pixels x layers array.

    ``pixel-major``: a pixel's entries are contiguous (FreePipe's DepthArray[x][y][i]);
    ``layer-major``: slot i of every pixel is one contiguous screen-sized plane.
    """
    pixel = np.asarray(pixel, dtype=np.int64)
    slot = np.asarray(slot, dtype=np.int64)
    if layout == "pixel-major":
        return pixel * layers + slot
    return slot * pixel_count + pixel


def pixel_key(pix: np.ndarray, value: np.ndarray) -> np.ndarray:
    """uint64 ``pix << 32 | value``: sorting it groups by pixel and orders by the 32-bit value."""
    return (np.asarray(pix).astype(np.uint64) << np.uint64(32)) | np.asarray(value).astype(np.uint64)


def rank_in_runs(pix_sorted: np.ndarray) -> np.ndarray:
    """0-based position of each element inside its run of a grouped array."""
    start = run_starts(pix_sorted)
    return np.arange(len(pix_sorted)) - np.repeat(start, np.diff(np.r_[start, len(pix_sorted)]))


def smallest_per_pixel(pix: np.ndarray, value: np.ndarray, limit: int,
                       candidates: np.ndarray | None = None) -> np.ndarray:
    """Indices of the ``limit`` smallest ``value`` s of each pixel, grouped by pixel, ascending.

    Equal values keep submission (index) order. ``candidates`` restricts the
    choice to those indices (others never enter the array).
    """
    idx = np.arange(len(pix)) if candidates is None else np.asarray(candidates, dtype=np.int64)
    order = idx[np.argsort(pixel_key(pix[idx], value[idx]), kind="stable")]
    return order[rank_in_runs(pix[order]) < limit]


def count_before_in_pixel(pix: np.ndarray, by_arrival: np.ndarray, flag: np.ndarray) -> np.ndarray:
    """For each fragment: how many *earlier* fragments of its pixel have ``flag`` set."""
    f = flag[by_arrival].astype(np.int64)
    csum = np.cumsum(f) - f
    start = run_starts(pix[by_arrival])
    base = np.repeat(csum[start], np.diff(np.r_[start, len(by_arrival)]))
    out = np.empty(len(pix), np.int64)
    out[by_arrival] = csum - base
    return out
