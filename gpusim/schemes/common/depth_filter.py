"""A per-pixel fixed-capacity priority queue that emits the nearest entry when full.

This is the k-buffer's sort-and-blend program (seed 004 section 4.3: keep k
fragments; when another arrives, the nearest of the k + 1 is blended and
leaves) and LucidRaster's depth filter (seed 002). Fed a k-nearly-sorted
sequence it emits it sorted; otherwise some fragments leave out of order.

Vectorised over pixels: one step per arrival rank (so a pixel with 4,000
fragments costs 4,000 small vector steps), each an argmin over k + 1 entries.
Equal depths leave in arrival order.
"""

from __future__ import annotations

import numpy as np

from gpusim.metrics.composite import runs_by_length

_NONE = np.iinfo(np.int64).max


def emit_order(pix: np.ndarray, key: np.ndarray, by_arrival: np.ndarray, capacity: int,
               return_steps: bool = False, return_keys: bool = False):
    """Fragment indices in the order the queue emits them, grouped by pixel (ascending).

    ``by_arrival`` lists fragment indices grouped by pixel in arrival order.
    After the last arrival the queue drains nearest first. With
    ``return_steps`` also returns, per emitted entry, the 0-based arrival rank
    whose arrival pushed it out (``count + k`` for the k-th entry drained); with
    ``return_keys`` then the pixel and the key of each emitted entry.
    """
    n = len(by_arrival)
    if n == 0:
        empty = np.zeros(0, np.int64)
        return (empty,) * (1 + return_steps + 2 * return_keys) if return_steps or return_keys else empty
    pix_sorted = pix[by_arrival]
    start_c, count_c, active = runs_by_length(pix_sorted)
    arrived_key = key[by_arrival]                      # in arrival order
    key_sorted = arrived_key.astype(np.int64)
    # queue entries: (key << 32 | position) so argmin = nearest, then earliest; _NONE = empty slot
    queue = np.full((len(start_c), capacity + 1), _NONE, np.int64)
    # a pixel emits one entry per arrival once full, then drains: its sequence (grouped like ``by_arrival``)
    # takes the entry pushed out by arrival j >= capacity at position j - capacity, the d-th drained at
    # max(count - capacity, 0) + d; each goes straight to its place (no sort by pixel and step)
    at = np.empty(n, np.int64)
    steps = np.empty(n, np.int64) if return_steps else None
    for j, m in enumerate(active):
        pos = start_c[:m] + j
        entry = (key_sorted[pos] << 32) | pos          # position in by_arrival breaks ties by arrival
        if j < capacity:
            queue[:m, j] = entry
            continue
        queue[:m, capacity] = entry
        slot = np.argmin(queue[:m], axis=1)
        rows = np.arange(m)
        dest = start_c[:m] + (j - capacity)
        at[dest] = queue[rows, slot] & 0xFFFFFFFF
        if return_steps:
            steps[dest] = j
        queue[rows, slot] = queue[:m, capacity]
    # drain: remaining entries nearest first
    rest = np.sort(queue[:, :capacity], axis=1)
    valid = rest != _NONE
    first = start_c + np.maximum(count_c - capacity, 0)
    dest = (first[:, None] + np.arange(capacity))[valid]
    at[dest] = rest[valid] & 0xFFFFFFFF
    if return_steps:
        steps[dest] = (count_c[:, None] + np.arange(capacity))[valid]
    emitted_pix = pix_sorted
    out = (by_arrival[at],) + ((steps,) if return_steps else ()) + \
        ((emitted_pix, arrived_key[at]) if return_keys else ())
    return out if len(out) > 1 else out[0]
