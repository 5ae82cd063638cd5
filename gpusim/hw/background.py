"""The rest of the GPU's work on a shared unit, in a sampled program (gpusim.hw.sample).

A replicate of the sampled level runs a share of the run's work on a share of its SMs. The shared units (the
memory partitions' DRAM channels and L2 slices, the atomic units, the ROPs) keep every instance, and must be as
busy as in the run: each request of the sample stands for itself and the other SMs' requests that come with
it, ``held - cost`` sub-cycles more of the instance's time (``Program.occupancy``: the run's load on the
instance in the pass over the sample's). Where that work queues:

* The L2 slices, the atomic units and the ROPs (their own code): it holds the instance right after the
  instruction's requests there, before the next instruction's. The other SMs work on the same triangles, in
  the front end's order, so their traffic on a unit of short latency comes when and where the sample's does
  (the run's hot L2 slice is hot while the front end is on its pixels).
* The DRAM channels (:class:`Background`): it goes into a pool, spread over every channel in the pass's mix
  of the run's other traffic (per pass and channel, the run's load less the sample's: ``Program.own_load``
  times ``Program.occupancy`` less one). A channel takes its share of what the pool gained since it last
  served, ahead of the sample's next request there: as a fluid that came in since then, a backlog only where
  it came faster than the channel serves; the rest when the pass ends. A DRAM request is in flight for
  hundreds of cycles, and in that time the other SMs' requests come from all over the screen and from warps
  at every point of their programs. Those requests arrive at random, so a request of the sample also finds
  the mean wait of an M/D/1 queue among them: ``rho x cost / (2 (1 - rho))``, where ``rho`` is the
  channel's load from the pool since it last served (its share over the time since; at most
  :data:`RHO_MAX`) and ``cost`` the request's own service, or the fluid's backlog where that is longer.
  Without it a sample ran a little fast on channels busy but not saturated (LucidRaster on nested spheres
  at 64x64, gtx280: 3.3% short of the full level; 2.5% with it).

Why the pool for the DRAM: a replicate's SMs have a few dozen warps. When each of their requests held its
channel for the other SMs' requests too, the warps queued on one channel while the others stood idle, where
the run's thirty SMs keep every channel busy: a closed queueing network of far fewer customers than the
run's, which cannot keep its queues busy together. On `foliage` at 384x384 on `gtx280` that put TFSS 15% over
the full level (7% pooled; the rest was how the sample's warps coalesce, which the run's coalesced
traffic sets instead: gpusim.hw.sample.coalesced_load). Why not everywhere: pooled at the L2
slices, the stencil-routed A-buffer's framebuffer traffic on `modern` spread evenly over the slices, and the
hot slice's queue, which decides its capture pass, was gone (the pass 20% short on `bunny` at 160x160, 4%
held behind), and LucidRaster's latency-bound passes there came out 3% further over.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np


#: the most load the pool puts on a channel in the M/D/1 wait (its mean grows without bound as the load nears
#: 1; a channel loaded past this serves the pool's backlog as a fluid instead)
RHO_MAX = 0.95


class Background:
    """A DRAM-like unit's pool of the rest of the GPU's work in a sampled program (see the module docstring):
    ``weights`` (passes, instances), the other SMs' load on each instance in each pass (any unit of load; only
    its share of the pass's total counts)."""

    def __init__(self, weights: np.ndarray):
        weights = np.asarray(weights, np.float64)
        total = weights.sum(axis=1, keepdims=True)
        self.shares = np.where(total > 0, weights / np.where(total > 0, total, 1.0), 0.0).tolist()
        self.instances = weights.shape[1]
        self.k = -1                       # the pass being served
        self.share: list[float] = []      # its shares
        self.pool = 0.0                   # sub-cycles of background the pass's requests have brought so far
        self.seen = [0.0] * self.instances   # the pool when each instance last took its share
        self.last = [0] * self.instances     # the sub-cycle each instance last took its share

    def start(self, k: int, p: int, free: int, at: int, extra: int, cost: int) -> int:
        """The sub-cycle instance ``p``, free from sub-cycle ``free``, starts a sample's request of ``cost``
        sub-cycles arriving at ``at`` in pass ``k``, which brings ``extra`` sub-cycles of the rest of the GPU's
        to the pool (:meth:`serve` of one cell; its free sub-cycle held alone, not a list of every instance's
        made for each request: the atomic units' and L2 misses' channel requests come through here)."""
        return self.serve(k, 0, 1, (p,), (cost,), (extra,), {p: free}, at, None) - cost

    def serve(self, k: int, lo: int, hi: int, part: Sequence[int], cost: Sequence[int], extra: Sequence[int],
              free: list[int] | dict[int, int], at: int, starts: list | None) -> int:
        """Serve an instruction's cells ``lo`` to ``hi - 1`` of a sample's requests arriving together at sub-cycle
        ``at`` in pass ``k``, in order: cell ``j`` on instance ``part[j]``, free from ``free[part[j]]``, takes
        ``cost[j]`` sub-cycles and brings ``extra[j]`` of the rest of the GPU's to the pool. Each starts after its
        instance's share of what the pool gained since the instance last served, as a fluid that came in since
        then (a backlog only where it came faster than the instance serves), or after the mean wait among those
        requests arriving at random (M/D/1), whichever is later, and not before ``at``. Moves each ``free`` past
        its cell and puts its start in ``starts`` where given; returns the sub-cycle the last one ends. (One
        call for all of an instruction's cells: a DRAM access's are the sampled level's most frequent event
        work.)"""
        if k != self.k:
            self.k, self.share, self.pool, self.seen = k, self.shares[k], 0.0, [0.0] * self.instances
            self.last = [at] * self.instances
        share, seen, last = self.share, self.seen, self.last
        pool, end = self.pool, 0
        for j in range(lo, hi):
            p = part[j]
            due = (pool - seen[p]) * share[p]
            span = at - last[p]
            f = free[p]
            e = f + int(due)
            seen[p] = pool
            last[p] = at
            pool += extra[j]
            c = cost[j]
            if span > 0 and due > 0:
                rho = due / span
                if rho > RHO_MAX:
                    rho = RHO_MAX
                wait = at + round(rho * c / (2.0 * (1.0 - rho)))
                if wait > e:
                    e = wait
            if e < at:
                e = at
            if starts is not None:
                starts[p] = e
            e += c
            free[p] = e
            if e > end:
                end = e
        self.pool = pool
        return end

    def settled(self, free: list[int]) -> list[int]:
        """Each instance's free sub-cycle ``free`` once it has served its share of what is left in the pool (the
        pass's end)."""
        if self.k < 0:
            return list(free)
        return [f + int((self.pool - s) * w) for f, s, w in zip(free, self.seen, self.share)]


def background(program, name: str) -> Background | None:
    """Shared unit ``name``'s pool in a sampled ``program`` (a key of ``Program.occupancy``), None in a whole run
    or where the sample bears the whole load."""
    if program is None or not program.occupancy or name not in program.occupancy or not program.own_load:
        return None
    return Background(program.own_load[name] * (program.occupancy[name] - 1.0))
