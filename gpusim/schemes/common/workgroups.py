"""Work items dealt to the lanes of a workgroup, as a compute shader's loops over shared lists deal them.

A loop ``for (i = lane; i < n; i += size)`` over a list of ``n`` items (a bin's
triangles, a block-row's tri-block-rows) gives lane ``l`` the items ``l, l + size,
l + 2 size, ...``; the plan's threads are then the workgroups' lanes, so the timing
model sees each workgroup's parallelism (and the warps of one workgroup run side by
side on the SMs). :class:`Lanes` turns items placed on threads into an OpPlan
group (threads, their operation counts, the item of each operation), and
:func:`thread_totals` sums the ALU work of the items each thread takes.
"""

from __future__ import annotations

import numpy as np

from gpusim.schemes.common.arrays import lex_order


class Lanes:
    """Items each issued by a given thread, in program order: the form of an OpPlan group.

    ``thread[k]`` is the thread that issues item ``k``; ``order`` (optional keys, most significant first)
    says the order a thread issues its items in (default: item order). ``threads`` and ``counts`` are the
    distinct threads ascending and their items; ``item(i, s)`` is the item of operation ``s`` of thread
    ``threads[i]``, to index an item's address or bytes with.
    """

    def __init__(self, thread: np.ndarray, *order: np.ndarray):
        thread = np.asarray(thread, np.int64)
        self.order = lex_order(thread, *order) if len(thread) else np.zeros(0, np.int64)
        t = thread[self.order]
        new = np.ones(len(t), bool)
        new[1:] = t[1:] != t[:-1]
        self.first = np.flatnonzero(new)
        self.threads = t[self.first]
        self.counts = np.diff(np.append(self.first, len(t)))

    def item(self, i: np.ndarray, s: np.ndarray) -> np.ndarray:
        return self.order[self.first[i] + s]


def thread_totals(thread: np.ndarray, work: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The distinct threads of ``thread`` ascending and the sum of ``work`` over each one's entries (a thread's
    ALU instructions from the items it takes)."""
    thread = np.asarray(thread, np.int64)
    if len(thread) == 0:
        return np.zeros(0, np.int64), np.zeros(0, np.int64)
    threads, inverse = np.unique(thread, return_inverse=True)
    totals = np.bincount(inverse, weights=np.asarray(work, np.float64), minlength=len(threads))
    return threads, np.rint(totals).astype(np.int64)
