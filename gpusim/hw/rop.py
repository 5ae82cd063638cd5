"""ROP units with a reorder buffer (seed 004 sections 3.1-3.2).

Fixed-function raster operations (``blend``, ``depth_test``, ``stencil``) and
programmable-blender invocations (``program_blend``, gpusim.hw.blender) go to
the ROP unit its ``memory.interleave_bytes`` block maps to (gpusim.hw.unit.interleave, over
``rop.units``). Operations on
one address (one pixel's value) commit in submission order (primitive order),
which keeps blending correct however the shader cores interleave fragments:
an operation that arrives before the previous one on its address waits in the
unit's reorder buffer (``rop.reorder_entries``); an operation that can commit
at once needs no entry. When the buffer is full, the warp issuing into it
stalls (the core stalls) until an entry frees.

A unit commits one operation at a time: ``commit = max(arrival, previous
commit on the address, unit free) + service``, with a service of
``1 / rop.ops_per_cycle`` cycles for fixed-function operations and the
blender's program time for ``program_blend``. A depth or stencil result
reaches the core ``rop.latency`` + interconnect cycles after commit.

Framebuffer traffic (``rop.memory_traffic``, on by default): when a warp
instruction's operations arrive, the sectors they touch are read and written
through the memory path after the coalescer (gpusim.hw.memory: the L2 slices
where the GPU has them, else the DRAM channels), coalesced as the SM's requests
are. The unit's queue hides the reads' latency, so a commit does not wait for
them; they hold the partitions' bandwidth, which the cores' requests share, and
the pass ends when the partitions have served them.
"""

from __future__ import annotations

import operator
from dataclasses import dataclass

import numpy as np

from gpusim.config import param
from gpusim.hw.unit import (BUSY, FP, REQUESTS, UTILISATION, Stat, Unit, fp_cost, interleave, occupancy,
                            register_unit, run_held)
from gpusim.opplan import OPS

PROGRAM_BLEND = OPS.index("program_blend")


@dataclass(frozen=True)
class RopConfig:
    """ROP units with a reorder buffer (fixed-function blend, depth test, stencil)."""

    units: int = param(32, unit="ROPs", doc="ROP units (pixels interleaved across them by address)", min=1,
                       max=4096)
    reorder_entries: int = param(64, unit="fragments", doc="reorder-buffer entries per ROP unit; a full "
                                 "buffer stalls the core", min=1)
    ops_per_cycle: float = param(0.5, unit="fragments/cycle", doc="operations committed per ROP unit per "
                                 "shader cycle", gt=0)
    latency: int = param(100, unit="cycles", doc="latency from commit to the framebuffer write landing", min=0)
    memory_traffic: bool = param(True, doc="whether operations read and write the framebuffer through the "
                                 "memory partitions (L2 and DRAM: a read and a write of each sector a warp "
                                 "instruction's operations touch); false: an ideal ROP cache that holds the "
                                 "whole framebuffer, so only the ROPs' own service counts")


def framebuffer_traffic(gpu) -> bool:
    """Whether ROP operations on ``gpu`` send their framebuffer reads and writes down the memory path."""
    return bool(gpu.rop.memory_traffic)


def framebuffer_operations(gpu) -> frozenset:
    """The ROP operations whose framebuffer reads and writes go down the memory path on ``gpu`` (none with
    ``rop.memory_traffic`` off)."""
    return RopUnit.issued if framebuffer_traffic(gpu) else frozenset()


@register_unit
class RopUnit(Unit):
    name = "rop"
    Config = RopConfig
    issued = frozenset({"blend", "depth_test", "stencil", "program_blend"})
    STATS = (BUSY, REQUESTS, UTILISATION,
             Stat("max_reorder_occupancy", "entries", "most operations waiting in the reorder buffer"),
             Stat("stalls", "stalls", "warp instructions stalled by a full buffer", per_instance=False),
             Stat("overflows", "entries", "entries granted past a full buffer to end a stall that nothing else "
                  "could end (the in-order launch real hardware has, which the model does not)",
                  per_instance=False))
    COUNTERS = {"stalls": operator.add, "max_held": max, "overflows": operator.add}   # merged across processes
    KEPT = ("instances", "entries")

    def __init__(self, config: RopConfig, machine):
        super().__init__(config.units)
        self.env = machine.env
        mem = machine.gpu.memory
        # the framebuffer reads and writes go down the memory path when they arrive (the reorder buffer and the
        # ROP's queue hide their latency; they take the partitions' bandwidth from the shader cores' requests)
        coalescer = machine.units.get("coalescer") if framebuffer_traffic(machine.gpu) else None
        self.framebuffer = None if coalescer is None else coalescer.framebuffer
        self.icn, self.latency, self.entries = mem.interconnect_latency, config.latency, config.reorder_entries
        prog = machine.program
        _, _, wi_row = prog.storage(self.name)
        self.row_pass = prog.wi_pass[wi_row]
        R = prog.rows_of(self.name)
        n = len(R)
        addr = R.address
        unit = interleave(addr, mem.interleave_bytes, config.units)
        # submission order: pass, fragment, then program order; the previous operation on the same address in it
        age = np.lexsort((prog.wi_k[wi_row], prog.wi_group[wi_row], R.thread, prog.wi_pass[wi_row]))
        self.age = np.empty(n, np.int64)
        self.age[age] = np.arange(n)
        order = np.lexsort((prog.wi_k[wi_row], prog.wi_group[wi_row], R.thread, prog.wi_pass[wi_row], addr))
        pred = np.full(n, -1, np.int64)
        same = np.r_[False, addr[order][1:] == addr[order][:-1]] if n else np.zeros(0, bool)
        pred[order[same]] = order[np.flatnonzero(same) - 1]
        service = np.full(n, fp_cost(1, config.ops_per_cycle), np.int64)
        programs = R.op == PROGRAM_BLEND
        if programs.any():
            service[programs] = machine.units["blender"].service_fp(R.nbytes[programs], addr[programs])
        self.busy_fp = np.bincount(unit, weights=service, minlength=config.units).astype(np.int64).tolist()
        self.requests = np.bincount(unit, minlength=config.units).tolist()
        self.unit, self.pred, self.service = unit.tolist(), pred.tolist(), service.tolist()
        # a sampled program (gpusim.hw.unit.occupancy): the rest of the GPU's operations that come with an
        # instruction's hold its unit after them, before the next instruction's (gpusim.hw.background)
        held = occupancy(service, self.row_pass, unit, prog, "rop")
        self.others = None if held is service else (held - service).tolist()
        if self.others is not None:
            self.run_busy_fp = np.bincount(unit, weights=run_held(held, self.row_pass, prog, "rop"),
                                           minlength=config.units).tolist()
        self.row_wi = wi_row.tolist() if self.others is not None else None
        self.after, self.last = [0] * config.units, [-1] * config.units
        self.produces = prog.wi_produces.tolist()
        self.commit = [-1] * n                   # cycle, once known
        self.arrive = [-1] * n
        self.free = [0] * config.units           # sub-cycles
        self.held = [0] * config.units           # reorder-buffer entries in use
        self.max_held = [0] * config.units
        self.stalls = 0
        self.overflows = 0
        self.extra = [0] * config.units                # entries granted past the buffer's size, in use
        self.stalled = [None] * config.units           # the oldest operation stalled on each full buffer
        self.waiting_on: dict[int, list[int]] = {}     # operation -> operations waiting for its commit
        self.commit_events: dict[int, object] = {}     # operation -> event a warp waits on for its result
        self.space = [None] * config.units             # event a warp waits on for a free entry
        self.drain = 0
        self.lo, self.hi = prog.row_bounds        # instruction -> its rows
        self.placed: dict[int, int] = {}          # instruction -> lanes placed so far

    def serve(self, wi: int, now: int):
        """The cycle the result is back (a depth or stencil test), or ``now`` when the warp need not wait; or
        an event to wait for (a free reorder-buffer entry, the result's commit) before issuing again."""
        a, b = self.lo[wi], self.hi[wi]
        placed = self.placed
        if self.framebuffer is not None and wi not in placed:
            self.framebuffer(wi, (now + self.icn) * FP)
        pred, commit, arrive, commit_op = self.pred, self.commit, self.arrive, self._commit
        at = now + self.icn
        for i in range(placed.get(wi, a), b):
            p = pred[i]
            if p >= 0 and commit[p] < 0:             # must wait for the previous op on its address
                u = self.unit[i]
                held = self.held
                if held[u] >= self.entries + self.extra[u]:     # full: the warp stalls
                    placed[wi] = i
                    self.stalls += 1
                    if self.space[u] is None:
                        self.space[u] = self.env.event()
                    if self.stalled[u] is None or self.age[i] < self.age[self.stalled[u]]:
                        self.stalled[u] = i
                    return self.space[u]
                held[u] += 1
                if held[u] > self.max_held[u]:
                    self.max_held[u] = held[u]
                arrive[i] = at
                self.waiting_on.setdefault(p, []).append(i)
            else:
                arrive[i] = at
                commit_op(i)
        placed[wi] = b
        if not self.produces[wi]:
            return now
        value, tail = now, self.latency + self.icn
        for i in range(a, b):
            c = commit[i]
            if c < 0:
                ev = self.commit_events.get(i)
                if ev is None:
                    ev = self.commit_events[i] = self.env.event()
                return ev
            if c + tail > value:
                value = c + tail
        return value

    def _commit(self, i: int) -> None:
        """Commit operation ``i`` and every operation waiting in a buffer that can follow it (the last one
        to be released first)."""
        unit, pred, arrive, free, service, commit = self.unit, self.pred, self.arrive, self.free, self.service, \
            self.commit
        others, latency, waiting_on, commit_events = self.others, self.latency, self.waiting_on, self.commit_events
        stack = None
        while True:
            u, p = unit[i], pred[i]
            if others is not None and self.last[u] != self.row_wi[i]:   # a sample: the other operations that
                free[u] += self.after[u]                               # came with the instruction before
                self.after[u], self.last[u] = 0, self.row_wi[i]
            start = arrive[i] * FP
            if free[u] > start:
                start = free[u]
            if p >= 0 and commit[p] * FP > start:
                start = commit[p] * FP
            end = start + service[i]
            free[u] = end
            if others is not None:
                self.after[u] += others[i]
            commit[i] = c = -(-end // FP)
            if c + latency > self.drain:
                self.drain = c + latency
            if commit_events:
                ev = commit_events.pop(i, None)
                if ev is not None:
                    ev.succeed()
            if waiting_on:
                for k in waiting_on.pop(i, ()):
                    uk = unit[k]
                    self.held[uk] -= 1
                    if self.extra[uk] and self.held[uk] < self.entries + self.extra[uk]:
                        self.extra[uk] -= 1              # an entry past the buffer's size is given back first
                    if self.space[uk] is not None:
                        self._wake(uk)
                    if stack is None:
                        stack = []
                    stack.append(k)
            if not stack:
                return
            i = stack.pop()

    def _wake(self, u: int) -> None:
        """Let the warps waiting for an entry of unit ``u`` try again."""
        self.space[u].succeed()
        self.space[u], self.stalled[u] = None, None

    def relieve(self) -> bool:
        """Every warp waits and nothing is left to happen: grant one entry past the size of the buffer whose
        stalled operation is oldest (real hardware launches fragments in order and reserves their entries, so
        the oldest always has one; the model launches per SM and may fill a buffer with younger operations).
        Whether there was a stall to end."""
        full = [u for u in range(self.instances) if self.space[u] is not None]
        if not full:
            return False
        u = min(full, key=lambda u: self.age[self.stalled[u]])
        self.extra[u] += 1
        self.overflows += 1
        self._wake(u)
        return True

    def only_passes(self, indices) -> None:
        """Only the passes ``indices`` run here (gpusim.hw.parallel): operations of the others count as
        committed long before (a pass starts after the previous one drained, so that is all an operation
        sees of them)."""
        self.commit = np.where(np.isin(self.row_pass, list(indices)), -1, 0).tolist()

    def idle_at(self) -> int:
        """The cycle the last committed operation's result is out (the buffers are empty at a pass end), and in a
        sampled program the rest of the GPU's operations are done."""
        if self.others is None:
            return self.drain
        return max(self.drain, -(-max(f + a for f, a in zip(self.free, self.after)) // FP))

    def blocked(self) -> list[str]:
        out = []
        for u in range(self.instances):
            if self.space[u] is not None or self.held[u]:
                out.append(f"rop[{u}] reorder buffer: {self.held[u]}/{self.entries} entries hold operations "
                           f"waiting for an earlier operation on their pixel that has not arrived"
                           + ("; a warp waits for a free entry" if self.space[u] is not None else ""))
        if self.commit_events:
            out.append(f"rop: {len(self.commit_events)} warp(s) wait for a depth/stencil result")
        return out[:4] + ([f"... {len(out) - 4} more"] if len(out) > 4 else [])

    def line_trace(self) -> str:
        return "rop: held " + " ".join(f"[{u}]{h}/{self.entries}" for u, h in enumerate(self.held[:8])) \
            + f" stalls={self.stalls}"

    def values(self, total_cycles: int) -> dict:
        return super().values(total_cycles) | {"max_reorder_occupancy": list(self.max_held), "stalls": self.stalls,
                                               "overflows": self.overflows}

    def summary(self, total_cycles: int) -> dict:
        return super().summary(total_cycles) | {"reorder_entries": self.entries, "stalls": self.stalls,
                                                "overflows": self.overflows,
                                                "max_reorder_occupancy": int(max(self.max_held))}
