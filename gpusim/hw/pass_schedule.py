"""Which passes the ``analytic`` level times, and how it counts the others.

A pass's analytic time depends on its work only: its kind and front end (``Pass.kind``, ``threads``,
``software``, ``primitives``) and, in program order, its groups with each group's threads in it. Passes alike in
all of that but the number of threads each ``seq_pass`` group still has in them form a *family*: depth peeling's
peel passes, the R-buffer's recirculations, the multi-pass k-buffer's peels. A group that falls in one pass only
stands for its content (operation, structure, threads, counts, first addresses), so passes that make the same
work again as new groups (the multi-pass k-buffer's resolves of the same deep pixels) are one family too. Groups
that pick a subset of their threads in each pass (a ``pass_fn``) are alike when the subsets' sizes, operation
counts and first addresses' count, sum and sum of squares are (a summary, not the addresses themselves).

In a family:

* a pass whose every group has the same threads as the family's last timed pass, or at most
  :data:`REPEAT_TOLERANCE` fewer (a ``seq_pass`` group's threads only shrink), or -- when a throughput bound that
  grows with all of a pass's work (:data:`VOLUME_BOUNDS`) decided that pass -- at most REPEAT_TOLERANCE of its
  threads fewer in all, is that pass counted again (``repeat_of`` in its record);
* a family of at least :data:`INTERPOLATE_MIN_PASSES` passes whose groups' threads only shrink from pass to pass
  is timed instead at its first and last pass, then at the midpoint (by threads) of each span. A span is accepted
  when its midpoint's cycles lie within :data:`INTERPOLATE_TOLERANCE` of those the straight lines through its ends'
  bounds against their threads give (each bound on its line, the largest deciding, so a bend from one bound to
  another is followed); else when its quarter points' cycles lie within the tolerance of those the parabolas
  through its ends' and midpoint's bounds give (a bound that curves as the threads shrink); else it is split at
  its midpoint (the halves take the quarter points as theirs). Inside an accepted span a pass with the same
  threads as one end is that end counted again; every other gets each bound from its line or parabola, the
  largest deciding (``interpolated``: the timed passes, in its record).

So a stiff scene's thousands of passes cost bookkeeping per pass and a timed pass per family and bend, each timed
pass O(its threads), not O(passes x threads).
"""

from __future__ import annotations

import hashlib
from dataclasses import dataclass

import numpy as np

from gpusim.hw.placement import StillIssuing

REPEAT_TOLERANCE = 0.01    # a pass whose groups each differ from a timed pass's by at most this share of their threads
VOLUME_BOUNDS = ("issue", "raster", "dram", "atomic")   # bounds that grow with all of a pass's operations
INTERPOLATE_MIN_PASSES = 64   # passes a family needs before its spans are interpolated
INTERPOLATE_TOLERANCE = 5e-3  # largest |cycles off the line or parabola| / cycles at a checked pass of a span
TERMS = "terms"               # a timed record's bounds and the cycles added to the largest, for interpolation


def interpolated(records: list[dict], at: list[int], weights: list[float]) -> dict:
    """The record of a pass between timed passes ``at`` (their ``records``): each bound the sum of theirs times
    ``weights`` (the line through two, or the parabola through three, against their threads), the largest
    deciding, plus the round trip and driver cycles they share."""
    terms = {k: sum(w * r[TERMS][0][k] for w, r in zip(weights, records)) for k in records[0][TERMS][0]}
    limit = max(terms, key=terms.get)
    return {"name": records[0]["name"], "kind": records[0]["kind"],
            "cycles": int(np.ceil(terms[limit])) + records[0][TERMS][1],
            "warps": int(round(sum(w * r["warps"] for w, r in zip(weights, records)))), "bound": limit,
            "interpolated": list(at)}


def lagrange(nodes: np.ndarray, x: np.ndarray) -> np.ndarray:
    """``(len(x), len(nodes))`` weights of the polynomial through ``nodes`` (distinct) evaluated at ``x``."""
    nodes, x = np.asarray(nodes, np.float64), np.asarray(x, np.float64)
    out = np.ones((len(x), len(nodes)))
    for i, xi in enumerate(nodes):
        for j, xj in enumerate(nodes):
            if i != j:
                out[:, i] *= (x - xj) / (xi - xj)
    return out


@dataclass
class Family:
    """Passes alike but for their ``seq_pass`` groups' threads: ``sizes[i, j]`` is the threads of the family's
    ``j``-th such group in its pass ``passes[i]`` (-1: all of the group's, the same in every pass);
    ``threads[i]`` the pass's threads over all its groups."""

    passes: np.ndarray
    sizes: np.ndarray
    threads: np.ndarray

    def shrinking(self) -> bool:
        """Whether every group's threads only shrink (or stay) from pass to pass."""
        return len(self.passes) < 2 or bool((np.diff(self.sizes, axis=0) <= 0).all())


def _digest(g, lanes: np.ndarray, thread: np.ndarray, counts: np.ndarray, base: int, seen: dict,
            whole: bool) -> bytes:
    """What decides a group's timing in its one pass: threads, counts and first addresses (and sizes). ``seen``
    keeps each thread array's digest (a pass's groups over one set of threads share it); ``whole``: ``lanes`` are
    all of the group's."""
    zero = np.zeros(len(lanes), np.int64)
    h = hashlib.blake2b(digest_size=16)
    key = (id(thread), -1) if whole else (id(thread), id(lanes))
    if key not in seen:
        seen[key] = (thread, lanes, hashlib.blake2b(np.ascontiguousarray(thread[lanes], np.int64).tobytes(),
                                                    digest_size=16).digest())
    h.update(seen[key][2])
    if len(counts) and counts.strides[0] == 0:         # one count for every thread
        h.update(np.float64(counts[0]).tobytes())
    else:
        h.update(np.ascontiguousarray(counts, np.float64).tobytes())
    if not g.is_compute:
        h.update(np.ascontiguousarray(base + np.asarray(g.offset(lanes, zero), np.int64), np.int64).tobytes())
        if callable(g.bytes):
            h.update(np.ascontiguousarray(g.bytes(lanes, zero), np.float64).tobytes())
    return h.digest()


def _subset_stats(g, li: np.ndarray, cnt: np.ndarray, where: dict, base: int) -> dict:
    """Per pass of a group that picks explicit lanes in each: (lanes, operations, sum and sum of squares of
    their first addresses), all passes at once."""
    passes = list(where)
    sels = [where[p] for p in passes]
    lens = np.array([len(s) for s in sels], np.int64)
    order = np.concatenate(sels) if sels else np.zeros(0, np.int64)
    lanes = li[order]
    counts = (np.asarray(g.instructions)[lanes] if g.is_compute else cnt[order]).astype(np.float64)
    if g.is_compute:
        addr = np.zeros(len(lanes))
    else:
        addr = base + np.asarray(g.offset(lanes, np.broadcast_to(np.zeros(1, np.int64), lanes.shape)), np.float64)
    pass_of = np.repeat(np.arange(len(passes)), lens)
    sums = [np.bincount(pass_of, weights=w, minlength=len(passes)) for w in (counts, addr, addr * addr)]
    return {p: (int(n), float(a), float(b), float(c)) for p, n, a, b, c in zip(passes, lens.tolist(), *sums)}


def pass_families(plan, placement: list, groups_of_pass: list, bases: dict, ids: list) -> tuple[np.ndarray, list]:
    """Each pass's family (-1 for a flush, which no family holds) and the families, in order of their first pass.
    ``placement[gi]``: (lanes, counts, {pass: selection}) as gpusim.hw.placement.group_passes gives; ``ids[gi]``
    the group's thread ids. Passes with the same groups are taken together (a ``seq_pass`` group's threads in
    each are one gather), so the bookkeeping is a few dictionary operations a pass."""
    same_groups: dict = {}
    for p, pk in enumerate(plan.passes):
        if pk.kind != "flush":
            same_groups.setdefault((pk.kind, pk.threads, pk.software, pk.primitives, tuple(groups_of_pass[p])),
                                   []).append(p)
    parts: dict = {}                      # family key -> [(passes, sizes, threads)]
    subsets: dict = {}
    for (kind, threads_kind, software, primitives, groups), passes in same_groups.items():
        at = np.array(passes, np.int64)
        cid, cols, singles = [], [], []
        threads = np.zeros(len(at), np.int64)
        explicit = []
        for gi in groups:
            li, cnt, where = placement[gi]
            g = plan.groups[gi]
            first = where[passes[0]]
            if len(where) == 1:            # a group of this pass alone: its content, told apart by a digest below
                n = len(li) if first is None else first.size() if isinstance(first, StillIssuing) else len(first)
                cid.append((g.op, g.structure, g.dep, g.bytes if not callable(g.bytes) else None, n))
                singles.append(gi)
                threads += n
            elif first is None:            # all of the group's threads in each of its passes
                cid.append(gi)
                cols.append(np.full(len(at), -1, np.int64))
                threads += len(li)
            elif isinstance(first, StillIssuing):
                size = first.sizes[np.searchsorted(g.seq_pass, at)]
                cid.append(gi)
                cols.append(size)
                threads += size
            else:                          # explicit lanes in each pass: alike when their stats are
                if gi not in subsets:
                    subsets[gi] = _subset_stats(g, li, cnt, where, bases.get(g.structure, 0))
                cid.append(gi)
                explicit.append(subsets[gi])
                threads += np.array([subsets[gi][p][0] for p in passes], np.int64)
        sizes = np.stack(cols, axis=1) if cols else np.zeros((len(at), 0), np.int64)
        base = (kind, threads_kind, software, primitives, tuple(cid))
        if explicit:
            by: dict = {}
            for i, p in enumerate(passes):
                by.setdefault(tuple(e[p] for e in explicit), []).append(i)
            pieces = [((base, k), np.array(v, np.int64)) for k, v in by.items()]
        else:
            pieces = [((base, None), slice(None))]
        for key, sel in pieces:
            parts.setdefault(key, []).append((at[sel], sizes[sel], threads[sel], singles))
    out: list = []
    for members in parts.values():
        if len(members) > 1 and members[0][3]:      # alike but for their own groups' content: tell them apart
            split: dict = {}
            seen: dict = {}
            for m in members:                        # (one pass each: its own groups are of no other pass)
                d = tuple(_single_digest(plan, placement, ids, bases, gi, int(m[0][0]), seen) for gi in m[3])
                split.setdefault(d, []).append(m)
            groups_of = list(split.values())
        else:
            groups_of = [members]
        for ms in groups_of:
            at = np.concatenate([m[0] for m in ms])
            order = np.argsort(at, kind="stable")
            out.append(Family(at[order], np.concatenate([m[1] for m in ms])[order],
                              np.concatenate([m[2] for m in ms])[order]))
    out.sort(key=lambda f: int(f.passes[0]))
    fam_of = np.full(len(plan.passes), -1, np.int64)
    for i, f in enumerate(out):
        fam_of[f.passes] = i
    return fam_of, out


def _single_digest(plan, placement, ids, bases, gi: int, p: int, seen: dict) -> bytes:
    g = plan.groups[gi]
    li, cnt, where = placement[gi]
    sel = where[p]
    if sel is None:
        lanes, counts = li, cnt
    elif isinstance(sel, StillIssuing):
        lanes = sel()
        counts = cnt[:len(lanes)]
    else:
        lanes, counts = li[sel], cnt[sel]
    if g.is_compute:
        counts = np.asarray(g.instructions)[lanes]
    return _digest(g, lanes, ids[gi], counts, bases.get(g.structure, 0), seen, sel is None)


class Schedule:
    """Decides, family by family, which passes ``time(p)`` (a record with ``cycles`` and ``bound``) is called on and
    how every other pass is counted: :attr:`how` maps each pass to ``("timed",)``, ``("repeat", q)`` or
    ``("interpolated", at, weights)`` (each bound the timed passes ``at``'s times ``weights``)."""

    def __init__(self, families: list, time, interpolate: bool = True):
        self.time, self.how, self.records = time, {}, {}
        for f in families:
            if interpolate and len(f.passes) >= INTERPOLATE_MIN_PASSES and f.shrinking():
                self._spans(f)
            else:
                self._one_by_one(f, 0, len(f.passes), None)

    def _timed(self, f: Family, i: int) -> dict:
        p = int(f.passes[i])
        if p not in self.records:
            self.records[p] = self.time(p)
            self.how[p] = ("timed",)
        return self.records[p]

    def _within(self, f: Family, lo: int, hi: int, a: int) -> np.ndarray:
        """Whether each of the family's passes ``lo..hi-1`` counts as its pass ``a`` again."""
        rows, ref = f.sizes[lo:hi], f.sizes[a]
        more = np.abs(rows - ref)
        same = ((rows < 0) == (ref < 0)).all(axis=1)
        near = (more <= REPEAT_TOLERANCE * np.abs(ref)).all(axis=1)
        if self.records[int(f.passes[a])]["bound"] in VOLUME_BOUNDS:
            near |= more.sum(axis=1) <= REPEAT_TOLERANCE * f.threads[a]
        return same & near

    def _one_by_one(self, f: Family, lo: int, hi: int, anchor: int | None) -> None:
        """Passes ``lo..hi-1`` in order: each counted as the last timed one again, or timed."""
        if anchor is None:
            self._timed(f, lo)
            anchor, lo = lo, lo + 1
        i, chunk = lo, 64
        while i < hi:
            end = min(i + chunk, hi)
            ok = self._within(f, i, end, anchor)
            bad = int(np.argmin(ok)) if not ok.all() else len(ok)
            for j in range(i, i + bad):
                self.how[int(f.passes[j])] = ("repeat", int(f.passes[anchor]))
            if bad == len(ok):
                i, chunk = end, chunk * 2
                continue
            anchor = i + bad
            self._timed(f, anchor)
            i, chunk = anchor + 1, 64

    def _spans(self, f: Family) -> None:
        last = len(f.passes) - 1
        self._timed(f, 0)
        self._timed(f, last)
        todo = [(0, last)]
        while todo:
            a, b = todo.pop()
            if b - a < 2:                     # nothing between
                continue
            m = self._midpoint(f, a, b)
            self._timed(f, m)
            if self._fits(f, (a, b), (m,)):
                self._fill(f, a, b, (a, b))
                continue
            if m - a >= 2 and b - m >= 2:    # a curved span: the parabola through its ends and midpoint, checked
                q1, q3 = self._midpoint(f, a, m), self._midpoint(f, m, b)   # at its quarters (which the halves
                self._timed(f, q1)                                          # take as midpoints if it fails)
                self._timed(f, q3)
                if self._fits(f, (a, m, b), (q1, q3)):
                    self._fill(f, a, b, (a, m, b))
                    continue
            todo += [(m, b), (a, m)]

    @staticmethod
    def _midpoint(f: Family, a: int, b: int) -> int:
        t = f.threads
        if t[a] == t[b]:
            return (a + b) // 2
        inner = t[a + 1:b]                    # non-increasing
        i = int(np.searchsorted(-inner, -(t[a] + t[b]) / 2))
        return a + 1 + min(max(i, 0), len(inner) - 1)

    def _fits(self, f: Family, nodes: tuple, checks: tuple) -> bool:
        """Whether the passes ``checks`` have the cycles, within the tolerance, that the line (two ``nodes``) or
        parabola (three) through the nodes' bounds against their threads gives them (the largest deciding; which
        of two bounds within a few cycles of each other is named matters not)."""
        recs = [self.records[int(f.passes[i])] for i in (*nodes, *checks)]
        if any(TERMS not in r for r in recs):      # passes with nothing to time: no bounds to draw lines through,
            return False                           # so the span splits until each is timed or counted again
        if len({r[TERMS][1] for r in recs}) != 1 or any(r[TERMS][0].keys() != recs[0][TERMS][0].keys() for r in recs):
            return False
        t = f.threads[list(nodes)]
        if len(set(t.tolist())) < len(nodes):      # ends of one thread count: the same passes or none
            return len(nodes) == 2 and len({r["cycles"] for r in recs}) == 1
        at = [int(f.passes[i]) for i in nodes]
        for row, rc in zip(lagrange(t, f.threads[list(checks)]), recs[len(nodes):]):
            got = interpolated(recs[:len(nodes)], at, row.tolist())
            if abs(got["cycles"] - rc["cycles"]) > INTERPOLATE_TOLERANCE * rc["cycles"]:
                return False
        return True

    def _fill(self, f: Family, a: int, b: int, nodes: tuple) -> None:
        """The passes inside an accepted span: an end again where their threads are that end's, else on the line or
        parabola through ``nodes``."""
        inner = np.arange(a + 1, b)
        same_a = (f.sizes[a + 1:b] == f.sizes[a]).all(axis=1)
        same_b = (f.sizes[a + 1:b] == f.sizes[b]).all(axis=1)
        t = f.threads[list(nodes)]
        w = lagrange(t, f.threads[inner]) if len(set(t.tolist())) == len(nodes) else \
            np.tile(np.eye(len(nodes))[0], (len(inner), 1))
        at = [int(f.passes[i]) for i in nodes]
        pa, pb = int(f.passes[a]), int(f.passes[b])
        for j, sa, sb, wj in zip(inner.tolist(), same_a.tolist(), same_b.tolist(), w.tolist()):
            p = int(f.passes[j])
            if p in self.records:
                continue
            self.how[p] = ("repeat", pa) if sa else ("repeat", pb) if sb else ("interpolated", at, wj)
