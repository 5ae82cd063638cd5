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

import numpy as np

from gpusim.hw.lower import ATOMIC, Program
from gpusim.hw.units import FP, Unit, UnitStat, address_ids, cycles, div, fp_costs, mod


class AtomicUnits(Unit):
    name = "atomic"

    def __init__(self, gpu, program: Program):
        super().__init__(gpu.memory.partitions)
        self.gpu = gpu
        P = self.instances
        c = gpu.atomic
        self.icn, self.sac, self.tail = gpu.memory.interconnect_latency, c.same_address_cycles, \
            c.latency + gpu.memory.interconnect_latency
        self.free = [0] * P                          # sub-cycles
        self.until = 0                               # cycles: the last address hold ends
        wis, counts, wi_row = program.storage(ATOMIC)
        addr = program.rows_of(ATOMIC).address
        part = mod(div(addr, gpu.memory.interleave_bytes), P)
        # operations per (instruction, partition) cell, dense; the unit's work is static
        cell = wi_row * P + part
        nops = np.bincount(cell, minlength=program.instructions * P) if len(cell) else np.zeros(0, np.int64)
        hit = np.flatnonzero(nops)
        cost = fp_costs(nops[hit], c.ops_per_cycle)
        k_wi, k_p = div(hit, P), mod(hit, P)
        self.busy_fp = np.bincount(k_p, weights=cost, minlength=P).astype(np.int64).tolist()
        self.requests = np.bincount(k_p, weights=nops[hit], minlength=P).astype(np.int64).tolist()
        # flat lists: instruction wi owns cells po[wi]:po[wi + 1]; cell j its lanes' addresses ids[cl[j]:cl[j + 1]],
        # grouped by cell (a stable sort: the lanes of one address, all in one partition, stay in lane order)
        self.kp, self.kc = k_p.tolist(), cost.tolist()
        self.po = np.searchsorted(k_wi, np.arange(program.instructions + 1)).tolist()
        self.cl = np.r_[0, np.cumsum(nops[hit])].tolist()
        if len(cell) > 1 and not (cell[1:] >= cell[:-1]).all():
            addr = addr[np.argsort(cell, kind="stable")]
        ids, self.addr_ops = address_ids(addr)           # operations per address: for the stats
        self.ids = ids.tolist()
        self.addr_free = [0] * (int(ids.max()) + 1 if len(ids) else 0)      # cycles

    def access(self, wi: int, t: int) -> int:
        arrive = (t + self.icn) * FP
        free, kp, kc, cl, ids, fa, sac = self.free, self.kp, self.kc, self.cl, self.ids, self.addr_free, self.sac
        last = 0
        for j in range(self.po[wi], self.po[wi + 1]):
            p = kp[j]
            start = free[p] if free[p] > arrive else arrive
            free[p] = start + kc[j]
            u = -(-start // FP)          # the cycle this partition's unit takes the instruction's lanes
            if u > last:
                last = u
            after = u + sac
            for a in ids[cl[j]:cl[j + 1]]:   # lanes of one address in lane order: each waits for the last
                st = fa[a]
                if st <= u:
                    fa[a] = after
                else:
                    fa[a] = st + sac
                    if st > last:
                        last = st
        if last + sac > self.until:
            self.until = last + sac
        return last + self.tail

    def idle_at(self) -> int:
        """The cycle every unit and address is free again."""
        return max(self.until, cycles(max(self.free)))

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
