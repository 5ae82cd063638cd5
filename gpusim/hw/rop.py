"""ROP units with a reorder buffer, and the programmable blender (seed 004 sections 3.1-3.2).

Fixed-function raster operations (``blend``, ``depth_test``, ``stencil``) and
programmable-blender invocations (``program_blend``, k-buffer proposal 2) go to
ROP unit ``(address // memory.interleave_bytes) % rop.units``. Operations on
one address (one pixel's value) commit in submission order (primitive order),
which keeps blending correct however the shader cores interleave fragments:
an operation that arrives before the previous one on its address waits in the
unit's reorder buffer (``rop.reorder_entries``); an operation that can commit
at once needs no entry. When the buffer is full, the warp issuing into it
stalls (the core stalls) until an entry frees.

A unit commits one operation at a time: ``commit = max(arrival, previous
commit on the address, unit free) + service``, with a service of
``1 / rop.ops_per_cycle`` cycles for fixed-function operations and
``blender.cycles_per_op + bytes / blender.bytes_per_cycle`` for a blender
program. A depth or stencil result reaches the core ``rop.latency`` +
interconnect cycles after commit.
"""

from __future__ import annotations

import operator

import numpy as np

from gpusim.hw.lower import ROP, Program
from gpusim.hw.units import FP, Signal, Unit, UnitStat, fp_cost
from gpusim.opplan import OPS

PROGRAM_BLEND = OPS.index("program_blend")


class RopUnits(Unit):
    name = "rop"
    COUNTERS = {"stalls": operator.add, "max_held": max}     # changed by a run; merged across processes

    def __init__(self, gpu, program: Program, fire):
        units = gpu.rop.units
        super().__init__(units)
        self.gpu, self.fire = gpu, fire      # fire(signal): wake the warps waiting on it
        self.icn, self.lat = gpu.memory.interconnect_latency, gpu.rop.latency
        self.C = gpu.rop.reorder_entries
        _, _, wi_row = program.storage(ROP)
        self.row_pass = program.wi_pass[wi_row]
        R = program.rows_of(ROP)
        n = len(R)
        addr = R.address
        unit = (addr // gpu.memory.interleave_bytes) % units
        # the previous operation on the same address, in submission order
        # submission order on one address: pass, fragment, then program order inside the thread
        order = np.lexsort((program.wi_k[wi_row], program.wi_group[wi_row], R.thread, program.wi_pass[wi_row],
                            addr))
        pred = np.full(n, -1, np.int64)
        same = np.r_[False, addr[order][1:] == addr[order][:-1]] if n else np.zeros(0, bool)
        pred[order[same]] = order[np.flatnonzero(same) - 1]
        fixed = fp_cost(1, gpu.rop.ops_per_cycle)
        b = gpu.blender
        prog_blend = R.op == PROGRAM_BLEND
        service = np.where(prog_blend, b.cycles_per_op * FP + np.ceil(R.nbytes * FP
                                                                        / b.bytes_per_cycle).astype(np.int64),
                           fixed)
        self.blender_ops = int(prog_blend.sum())
        self.busy_fp = np.bincount(unit, weights=service, minlength=units).astype(np.int64).tolist()
        self.requests = np.bincount(unit, minlength=units).tolist()
        self.unit, self.pred, self.service = unit.tolist(), pred.tolist(), service.tolist()
        self.commit = [-1] * n                   # cycle, once known
        self.arrive = [-1] * n
        self.free = [0] * units                  # sub-cycles
        self.held = [0] * units                  # reorder-buffer entries in use
        self.max_held = [0] * units
        self.stalls = 0
        self.waiting_on: dict[int, list[int]] = {}
        self.commit_events: dict[int, object] = {}
        self.space = [None] * units
        self.drain = 0
        self.lo, self.hi = program.row_bounds    # instruction -> its rows
        self.placed: dict[int, int] = {}          # instruction -> lanes placed so far

    def access(self, wi: int, t: int, now: int, produces: bool):
        """(cycle the warp may go on, cycle the result is back), or a Signal to wait on and retry at ``now``
        (``t``: the cycle the instruction issued)."""
        a, b = self.lo[wi], self.hi[wi]
        done = self.placed.get(wi, a)
        for i in range(done, b):
            p = self.pred[i]
            if p >= 0 and self.commit[p] < 0:             # must wait for the previous op on its address
                u = self.unit[i]
                if self.held[u] >= self.C:                # full: the warp stalls
                    self.placed[wi] = i
                    self.stalls += 1
                    if self.space[u] is None:
                        self.space[u] = Signal()
                    return self.space[u]
                self.held[u] += 1
                self.max_held[u] = max(self.max_held[u], self.held[u])
                self.arrive[i] = now + self.icn
                self.waiting_on.setdefault(p, []).append(i)
            else:
                self.arrive[i] = now + self.icn
                self._commit(i)
        self.placed[wi] = b
        go = max(t, now)          # a warp stalled by a full buffer goes on once it is placed
        if not produces:
            return go, go
        value = go
        for i in range(a, b):
            if self.commit[i] < 0:
                ev = self.commit_events.get(i)
                if ev is None:
                    ev = self.commit_events[i] = Signal()
                return ev
            value = max(value, self.commit[i] + self.lat + self.icn)
        return go, value

    def _commit(self, i: int) -> None:
        stack = [i]
        while stack:
            i = stack.pop()
            u, p = self.unit[i], self.pred[i]
            start = max(self.arrive[i] * FP, self.free[u], (self.commit[p] * FP) if p >= 0 else 0)
            end = start + self.service[i]
            self.free[u] = end
            self.commit[i] = c = -(-end // FP)
            if c + self.lat > self.drain:
                self.drain = c + self.lat
            ev = self.commit_events.pop(i, None)
            if ev is not None:
                self.fire(ev)
            for k in self.waiting_on.pop(i, ()):
                uk = self.unit[k]
                self.held[uk] -= 1
                if self.space[uk] is not None:
                    self.fire(self.space[uk])
                    self.space[uk] = None
                stack.append(k)

    def assume_committed(self, indices) -> None:
        """Only the passes ``indices`` run here: operations of the others count as committed long before
        (a pass starts after the previous one drained, so that is all an operation sees of them)."""
        self.commit = np.where(np.isin(self.row_pass, list(indices)), -1, 0).tolist()

    def idle_at(self) -> int:
        """The cycle the last committed operation's result is out (the buffers are empty at a pass end)."""
        return self.drain

    def blocked(self) -> list[str]:
        """What the units are stuck on (no-progress diagnosis)."""
        out = []
        for u in range(self.instances):
            if self.space[u] is not None or self.held[u]:
                out.append(f"rop[{u}] reorder buffer: {self.held[u]}/{self.C} entries hold operations waiting for "
                           f"an earlier operation on their pixel that has not arrived"
                           + ("; a warp waits for a free entry" if self.space[u] is not None else ""))
        if self.commit_events:
            out.append(f"rop: {len(self.commit_events)} warp(s) wait for a depth/stencil result")
        return out[:4] + ([f"... {len(out) - 4} more"] if len(out) > 4 else [])

    def stats(self, total_cycles):
        rows = super().stats(total_cycles)
        for u in range(self.instances):
            rows.append(UnitStat(self.name, "max_reorder_occupancy", self.max_held[u], "entries",
                                 "most operations waiting in the reorder buffer", u))
        rows.append(UnitStat(self.name, "stalls", self.stalls, "stalls", "warp instructions stalled by a full buffer"))
        return rows

    def summary(self, total_cycles):
        return super().summary(total_cycles) | {"reorder_entries": self.C, "stalls": self.stalls,
                                                "max_reorder_occupancy": int(max(self.max_held)),
                                                "blender_ops": self.blender_ops}
