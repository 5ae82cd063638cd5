"""Atomic units, one per memory partition (seed 000 section 4: FreePipe's atomicMin/atomicInc).

An atomic instruction's lanes go to the partition of their address. The unit
accepts ``atomic.ops_per_cycle`` operations per cycle, and operations on one
address serialize: each holds its address for ``atomic.same_address_cycles``
(read, modify and write at the partition), so ``n`` operations on one word take
at least ``n * same_address_cycles``. Lanes of one instruction on one address
go in lane order; instructions in the order they reach the unit. This is where
FreePipe's hot pixels pay: a pixel of depth complexity N sees O(N^2)
dependent atomicMin operations in the multi-depth test scheme.

A lane completes ``atomic.latency`` cycles after its operation starts, plus
the interconnect back to the core.
"""

from __future__ import annotations

from itertools import repeat

import numpy as np

from gpusim.hw.lower import ATOMIC, Program
from gpusim.hw.units import FP, Unit, UnitStat, fp_costs


class AtomicUnits(Unit):
    name = "atomic"

    def __init__(self, gpu, program: Program):
        super().__init__(gpu.memory.partitions)
        self.gpu = gpu
        self.icn = gpu.memory.interconnect_latency
        self.free = [0] * self.instances              # sub-cycles
        wis, counts, rows = program.class_rows(ATOMIC)
        addr = program.address[rows]
        uniq, ids = np.unique(addr, return_inverse=True)
        part = (addr // gpu.memory.interleave_bytes) % self.instances
        wi_of = np.repeat(wis, counts)
        ids_s, wi_s, part_s = ids, wi_of, part          # lanes in lane order inside each instruction
        # operations per (instruction, partition), dense; the unit's work is static
        P = self.instances
        cell = wi_s * P + part_s
        nops = np.bincount(cell, minlength=program.instructions * P) if len(cell) else np.zeros(0, np.int64)
        hit = np.flatnonzero(nops)
        cost = fp_costs(nops[hit], gpu.atomic.ops_per_cycle)
        k_wi, k_p = hit // P, hit % P
        self.busy_fp = np.bincount(k_p, weights=cost, minlength=P).astype(np.int64).tolist()
        self.requests = np.bincount(k_p, weights=nops[hit], minlength=P).astype(np.int64).tolist()
        # flat lists; instruction wi owns lanes lo[wi]:lo[wi+1] and partitions po[wi]:po[wi+1]
        self.kp, self.kc = k_p.tolist(), cost.tolist()
        self.po = np.searchsorted(k_wi, np.arange(program.instructions + 1)).tolist()
        self.lo = np.searchsorted(wi_s, np.arange(program.instructions + 1)).tolist()
        self.ids, self.part = ids_s.tolist(), part_s.tolist()
        self.addr_free = [0] * len(uniq)                      # cycles
        self.addr_ops = np.bincount(ids, minlength=len(uniq))

    def access(self, wi: int, t: int) -> int:
        c = self.gpu.atomic
        arrive = (t + self.icn) * FP
        free = self.free
        pa, pb = self.po[wi], self.po[wi + 1]
        la, lb = self.lo[wi], self.lo[wi + 1]
        ids = self.ids[la:lb]
        if pb - pa == 1:
            p = self.kp[pa]
            start = free[p] if free[p] > arrive else arrive
            free[p] = start + self.kc[pa]
            lane_unit = -(-start // FP)
        else:
            unit_start = {}
            for j in range(pa, pb):
                p = self.kp[j]
                start = free[p] if free[p] > arrive else arrive
                free[p] = start + self.kc[j]
                unit_start[p] = -(-start // FP)
            lane_unit = [unit_start[p] for p in self.part[la:lb]]
        free_a, sac = self.addr_free, c.same_address_cycles
        last = 0
        if type(lane_unit) is int:
            lane_unit = repeat(lane_unit)
        for a, lu in zip(ids, lane_unit):   # lanes of one address in lane order: each waits for the last
            st = free_a[a]
            if st < lu:
                st = lu
            free_a[a] = st + sac
            if st > last:
                last = st
        return last + c.latency + self.icn

    def stats(self, total_cycles):
        rows = super().stats(total_cycles)
        rows.append(UnitStat(self.name, "max_ops_one_address", int(self.addr_ops.max()) if len(self.addr_ops) else 0,
                             "operations", "most operations on a single address (the hottest word)"))
        rows.append(UnitStat(self.name, "addresses", len(self.addr_ops), "addresses", "distinct addresses"))
        return rows

    def summary(self, total_cycles):
        return super().summary(total_cycles) | {
            "addresses": int(len(self.addr_ops)),
            "max_ops_one_address": int(self.addr_ops.max()) if len(self.addr_ops) else 0}
