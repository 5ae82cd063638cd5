"""Work items spread over the threads of a workgroup, as a compute shader's loop over a shared list does.

A persistent workgroup of ``size`` threads working on an item list of ``n``
entries (a bin's triangles, its tri-block-rows) gives thread ``l`` the entries
``l, l + size, l + 2 size, ...``: ``ceil((n - l) / size)`` of them. A group of
``count[i]`` operations by one thread ``i`` becomes, spread, a group of
operations by threads ``i * size + l``: the plan's threads are then the
workgroup's lanes, so the timing model sees the workgroup's parallelism (and
the warps of one workgroup run side by side on the SMs).
"""

from __future__ import annotations

import numpy as np


class Spread:
    """``count[i]`` items of owner ``i`` (``owner`` ids) dealt round robin to ``size`` lanes per owner.

    ``threads`` and ``counts`` are the lanes holding at least one item; ``item(i, s)`` maps operation ``s`` of
    spread thread index ``i`` back to (owner index, item number) of the unspread group.
    """

    def __init__(self, owner: np.ndarray, count: np.ndarray, size: int, lane_base: int | None = None):
        owner = np.asarray(owner, np.int64)
        count = np.asarray(count, np.int64)
        if size < 1:
            raise ValueError("size: must be >= 1 threads")
        lanes = np.minimum(count, size)                      # lanes with work, per owner
        self.owner_index = np.repeat(np.arange(len(owner)), lanes)
        self.lane = np.arange(int(lanes.sum())) - np.repeat(np.cumsum(lanes) - lanes, lanes)
        base = size if lane_base is None else lane_base
        self.threads = owner[self.owner_index] * base + self.lane
        self.counts = (count[self.owner_index] - self.lane + size - 1) // size
        self.size = size

    def item(self, i: np.ndarray, s: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(owner index, item number) of operation ``s`` of spread thread ``i``."""
        return self.owner_index[i], s * self.size + self.lane[i]
