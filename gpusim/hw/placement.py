"""Where each OpPlan group's operations fall, pass by pass, for the ``analytic`` level.

:func:`group_passes` gives, for one group, its lanes (indices into ``g.thread``), their operation counts and a
selection of lanes per pass: ``None`` (all of them), an index array, or a :class:`StillIssuing` for a ``seq_pass``
group whose threads issue different numbers of operations (op ``s`` of every thread that has more than ``s``).
Nothing here grows with threads x passes: a ``seq_pass`` group's per-pass thread sets are made when a pass is
reached.
"""

from __future__ import annotations

import numpy as np

from gpusim.hw.lower import split_by
from gpusim.metrics.composite import run_starts
from gpusim.opplan import ThreadRange

def thread_ids_of(plan, arange=np.arange) -> list[np.ndarray]:
    """Each group's thread ids, made once: the groups over ``0..n-1`` share one ``arange`` (depth peeling's
    groups over every fragment would make one per group and pass)."""
    ranges: dict[int, np.ndarray] = {}
    out = []
    for g in plan.groups:
        if isinstance(g.thread, ThreadRange):
            n = len(g.thread)
            out.append(ranges[n] if n in ranges else ranges.setdefault(n, arange(n)))
        else:
            out.append(g.thread_ids())
    return out



def expand_pass(g, n):
    """(pass, lane index into g.thread, ops) per (pass, thread) of a group spanning passes."""
    i, seq = g.expand_ops()
    p = np.asarray(g.pass_of(i, seq), np.int64)
    if len(i) == n > 1 and seq.strides[0] == 0 and 0 <= int(p.min()) and int(p.max()) < 2**15:
        # an op per thread (i = 0..n-1): the keys are distinct, the lanes those of each pass in thread order
        order = np.argsort(p.astype(np.int16), kind="stable")
        return p[order], order, np.broadcast_to(np.ones(1, np.int64), (n,))
    key = p * n + i
    if len(key) > 1 and not (key[1:] >= key[:-1]).all():
        # i ascends (thread order), so ordering by pass, ties kept, sorts the keys: a radix sort when the passes
        # fit 16 bits
        small = len(p) and 0 <= int(p.min()) and int(p.max()) < 2**15
        key = key[np.argsort(p.astype(np.int16) if small else p, kind="stable")]
    new = run_starts(key)
    return key[new] // n, key[new] % n, np.diff(np.append(new, len(key)))


class StillIssuing:
    """The threads of a ``seq_pass`` group that issue its op ``s``: those with more than ``s`` ops. Made when
    the pass is reached (memory grows with the threads, not threads x passes); the sets are nested (fewer as
    ``s`` grows), so two of one group with the same size are the same set."""

    def __init__(self, count: np.ndarray, sizes: np.ndarray, s: int):
        self.count, self.sizes, self.s = count, sizes, s     # sizes[s]: threads with more than s ops

    def size(self) -> int:
        return int(self.sizes[self.s])

    def __call__(self, nested: dict | None = None, recent: list = ()) -> np.ndarray:
        """The threads; ``nested`` holds each count array's last set (``count_key``: its ``s``, the set, the set
        it was picked from, the mask picking it), which holds this one when it was made for a smaller ``s``
        (the next pass picks from the last pass's threads, not from all of them). ``recent``: other sorted sets
        of threads made lately; the smallest holding as many of these threads as there are is picked from
        instead (a pick of that many from it is these threads), and when it holds nothing else it is the set
        (the R-buffer's writes back in one pass are the threads reading in the next)."""
        key = count_key(self.count)
        last = nested.get(key) if nested is not None else None
        want = self.size()
        sources = sorted((x for x in recent if len(x) >= want and int(x[-1]) < len(self.count)), key=len)[:1]
        if last is not None and last[0] < self.s:
            sources.append(last[1])
        got = src = mask = None
        for cand in sources:
            m = self.count[cand] > self.s
            k = int(np.count_nonzero(m))
            if k == want:
                src, mask, got = cand, m, cand if k == len(cand) else cand[m]
                break
        if got is None:
            got = np.flatnonzero(self.count > self.s)
        if nested is not None:
            nested[key] = (self.s, got, src, mask)
        return got


def count_key(count: np.ndarray) -> tuple:
    """One count array (a view of it alike) as a dict key."""
    return count.__array_interface__["data"][0], count.shape, count.strides


class Aranges:
    """``arange(n)`` for any ``n`` as a view of one array (the groups' lane indices would otherwise hold an
    ``arange`` each: a multi-pass k-buffer's groups of every pass, gigabytes at tens of millions of fragments)."""

    def __init__(self, n: int):
        self.whole = np.arange(n, dtype=np.int64)

    def __call__(self, n: int) -> np.ndarray:
        return self.whole[:n] if n <= len(self.whole) else np.arange(n, dtype=np.int64)


def group_passes(g, arange=np.arange, counted: dict | None = None):
    """Where group ``g``'s operations fall: (lane index into ``g.thread``, ops, {pass: selection}) with the
    selection of each pass's lanes into the first two (None: all of them; a :class:`StillIssuing` for a
    ``seq_pass`` group whose threads issue different numbers of ops). ``counted`` keeps each count array's
    (least, most, threads with more than s ops): the groups of one thread set across passes share theirs."""
    n = len(g.thread)
    if g.seq_pass is not None:          # op s of every thread in pass seq_pass[s]
        count = g.count
        key = count_key(count)
        got = counted.get(key) if counted is not None else None
        if got is None:
            least, top = int(count.min()), int(count.max())
            sizes = None if least == top else \
                len(count) - np.cumsum(np.bincount(count, minlength=top + 1))[:top]   # no sort
            got = (least, top, sizes)
            if counted is not None:
                counted[key] = got
        least, top, sizes = got
        if sizes is None:
            where = {int(g.seq_pass[s]): None for s in range(top)}
        else:
            where = {int(g.seq_pass[s]): StillIssuing(count, sizes, s) for s in range(top)}
        return arange(n), np.broadcast_to(np.ones(1, np.int64), (n,)), where
    if g.pass_fn is not None:
        gp, li, cnt = expand_pass(g, n)
        return li, cnt, dict(split_by(gp))
    if np.isscalar(g.pass_index):
        return arange(n), g.count, {int(g.pass_index): None}
    return arange(n), g.count, dict(split_by(np.asarray(g.pass_index, np.int64)))

