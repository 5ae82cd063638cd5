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

Where the partition has no cache on the global-memory path (``atomic.dram_rmw``:
GT200, whose L2 holds textures only), an atomic is a read-modify-write of its
word's 32-byte sector in the partition's DRAM channel: each operation holds the
channel for the sector's read and its write (2 x 32 bytes at
``dram.bytes_per_cycle``), in the same queue as the cores' loads and stores, and
starts no earlier than the channel is free (in a sampled program, than it has served its
share of the rest of the GPU's requests: gpusim.hw.background). Fermi and later GPUs perform
atomics in their L2 slices (NVIDIA's Fermi compute architecture whitepaper,
2009: atomics 5-20x faster than GT200's), which ``dram_rmw = false`` models.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from gpusim.config import param
from gpusim.hw.memory.level import SECTOR
from gpusim.hw.unit import (BUSY, FP, REQUESTS, UTILISATION, Stat, Unit, address_ids, cycles, div, fp_costs,
                            interleave, mod, occupancy, register_unit, run_held)
from gpusim.metrics.composite import run_starts


@dataclass(frozen=True)
class AtomicConfig:
    """Atomic unit in each partition."""

    latency: int = param(500, unit="cycles", doc="latency of one atomic (read, modify, write at the partition)",
                         min=0)
    ops_per_cycle: float = param(1.0, unit="ops/cycle", doc="atomic throughput per partition", gt=0)
    same_address_cycles: int = param(60, unit="cycles", doc="occupancy of one address by one atomic: "
                                     "operations on the same address serialize at this interval", min=1)
    dram_rmw: bool = param(False, doc="each operation reads and writes its 32-byte sector in the partition's "
                           "DRAM channel, holding it for both in the queue of the cores' requests (a GPU with no "
                           "cache on the global-memory path, as GT200); false: atomics are served in the partition "
                           "(an L2 slice's atomic unit, Fermi and later) and take no DRAM time")


#: DRAM bytes one atomic moves where ``atomic.dram_rmw`` is set: its sector read, then written back
DRAM_RMW_BYTES = 2 * SECTOR


def dram_atomics(program, gpu) -> bool:
    """Whether ``program``'s atomics on ``gpu`` read and write DRAM (``atomic.dram_rmw``, and it issues any)."""
    return bool(gpu.atomic.dram_rmw and AtomicUnit.issued & program.operation_names())


@register_unit
class AtomicUnit(Unit):
    name = "atomic"
    Config = AtomicConfig
    issued = frozenset({"atomic_min", "atomic_max", "atomic_inc", "atomic_exch"})
    STATS = (BUSY, REQUESTS, UTILISATION,
             Stat("hottest_address_ops", "operations", "most operations on a single address (the hottest word)",
                  per_instance=False),
             Stat("addresses", "addresses", "distinct addresses", per_instance=False))

    def __init__(self, config: AtomicConfig, machine):
        mem = machine.gpu.memory
        super().__init__(mem.partitions)
        P = self.instances
        prog = machine.program
        self.icn, self.hold = mem.interconnect_latency, config.same_address_cycles
        self.tail = config.latency + mem.interconnect_latency
        self.free = [0] * P                          # sub-cycle each partition's unit is free
        self.until = 0                               # cycle the last address hold ends
        wis, counts, wi_row = prog.storage(self.name)
        addr = prog.rows_of(self.name).address
        part = interleave(addr, mem.interleave_bytes, P)
        # operations per (instruction, partition) cell, dense; the unit's work is static
        cell = wi_row * P + part
        nops = np.bincount(cell, minlength=prog.instructions * P) if len(cell) else np.zeros(0, np.int64)
        hit = np.flatnonzero(nops)
        cost = fp_costs(nops[hit], config.ops_per_cycle)
        cell_wi, cell_part = div(hit, P), mod(hit, P)
        self.busy_fp = np.bincount(cell_part, weights=cost, minlength=P).astype(np.int64).tolist()
        if prog.occupancy is not None:         # a sampled program: as long as the run's operations there
            cost = occupancy(cost, prog.wi_pass[cell_wi], cell_part, prog, "atomic")
            self.run_busy_fp = np.bincount(cell_part, weights=run_held(cost, prog.wi_pass[cell_wi], prog, "atomic"),
                                           minlength=P).tolist()
        self.requests = np.bincount(cell_part, weights=nops[hit], minlength=P).astype(np.int64).tolist()
        # the DRAM channel each cell's read-modify-writes hold (atomic.dram_rmw), or None
        self.dram = machine.units.get("dram") if config.dram_rmw else None
        self.dram_free = self.dram_cost = self.dram_extra = None
        if self.dram is not None:           # a read and a write of each operation's sector
            dram_cost = fp_costs(nops[hit] * DRAM_RMW_BYTES, self.dram.rate)
            held = np.asarray(self.dram.serve_for(dram_cost, cell_wi, cell_part, 2 * nops[hit]), np.int64)
            self.dram_free, self.dram_cost = self.dram.free, dram_cost.tolist()
            if self.dram.pool is not None:  # a sampled program: the rest of the GPU's, pooled (gpusim.hw.background)
                self.dram_extra = (held - dram_cost).tolist()
        # flat lists: instruction wi owns cells cells_of[wi]:cells_of[wi + 1]; cell j its lanes' address ids
        # lanes_of[j]:lanes_of[j + 1], grouped by cell (a stable sort: the lanes of one address, all in one
        # partition, stay in lane order)
        self.cell_part, self.cell_cost = cell_part.tolist(), cost.tolist()
        self.cells_of = np.searchsorted(cell_wi, np.arange(prog.instructions + 1)).tolist()
        self.lanes_of = np.r_[0, np.cumsum(nops[hit])].tolist()
        scale = prog.hold_scale
        if len(cell) > 1 and not (cell[1:] >= cell[:-1]).all():
            order = np.argsort(cell, kind="stable")
            addr = addr[order]
            scale = scale[order] if scale is not None else None
        self.addresses = addr                  # each lane's (the program's rows; kept for detached)
        ids, self.ops_per_address = address_ids(addr)
        self.lane_address = ids.tolist()
        self.address_free = [0] * (int(ids.max()) + 1 if len(ids) else 0)      # cycle each address is free
        if scale is not None:
            # a sample (gpusim.hw.sample) keeps a share of the operations on a shared word: each holds it as long
            # as the run's operations on it over the sample's, so the word's chain lasts as long as the run's
            self.lane_hold = np.maximum(1, np.rint(config.same_address_cycles * scale)).astype(np.int64).tolist()
            self.serve = self._serve_sampled

    def serve(self, wi: int, now: int) -> int:
        arrive = (now + self.icn) * FP
        free, hold, address_free, lane_address = self.free, self.hold, self.address_free, self.lane_address
        cell_part, cell_cost, lanes_of = self.cell_part, self.cell_cost, self.lanes_of
        dram_free, dram_cost, dram_extra = self.dram_free, self.dram_cost, self.dram_extra
        last = 0
        for j in range(self.cells_of[wi], self.cells_of[wi + 1]):
            p = cell_part[j]
            start = free[p] if free[p] > arrive else arrive
            if dram_extra is not None:                # a sample: its channel's share of the pool first
                start = self.dram.take(p, start, dram_cost[j], dram_extra[j], wi)
            elif dram_free is not None:               # its sectors' reads and writes wait for the DRAM channel
                if dram_free[p] > start:
                    start = dram_free[p]
                dram_free[p] = start + dram_cost[j]
            free[p] = start + cell_cost[j]
            taken = -(-start // FP)          # the cycle this partition's unit takes the instruction's lanes
            if taken > last:
                last = taken
            after = taken + hold
            for a in lane_address[lanes_of[j]:lanes_of[j + 1]]:   # lanes of one address in lane order
                held = address_free[a]
                if held <= taken:
                    address_free[a] = after
                else:                        # the address is held: this lane waits for the last
                    address_free[a] = held + hold
                    if held > last:
                        last = held
        if last + hold > self.until:
            self.until = last + hold
        return last + self.tail

    def _serve_sampled(self, wi: int, now: int) -> int:
        """:meth:`serve` with a hold of its own per lane (``lane_hold``)."""
        arrive = (now + self.icn) * FP
        free, address_free, lane_address, lane_hold = self.free, self.address_free, self.lane_address, self.lane_hold
        cell_part, cell_cost, lanes_of = self.cell_part, self.cell_cost, self.lanes_of
        dram_free, dram_cost, dram_extra = self.dram_free, self.dram_cost, self.dram_extra
        last, until = 0, self.until
        for j in range(self.cells_of[wi], self.cells_of[wi + 1]):
            p = cell_part[j]
            start = free[p] if free[p] > arrive else arrive
            if dram_extra is not None:
                start = self.dram.take(p, start, dram_cost[j], dram_extra[j], wi)
            elif dram_free is not None:
                if dram_free[p] > start:
                    start = dram_free[p]
                dram_free[p] = start + dram_cost[j]
            free[p] = start + cell_cost[j]
            taken = -(-start // FP)
            if taken > last:
                last = taken
            for i in range(lanes_of[j], lanes_of[j + 1]):
                a = lane_address[i]
                held = address_free[a]
                if held > taken:             # the address is held: this lane waits for the last
                    if held > last:
                        last = held
                else:
                    held = taken
                address_free[a] = end = held + lane_hold[i]
                if end > until:
                    until = end
        self.until = until
        return last + self.tail

    def idle_at(self) -> int:
        """The cycle every unit and address is free again."""
        return max(self.until, cycles(max(self.free)))

    def detached(self) -> "AtomicUnit":
        """With the operations per distinct address (what ``absorb`` adds up by address)."""
        out = super().detached()
        out.addresses, out.ops_per_address = _per_address(self.addresses, np.ones(len(self.addresses), np.int64))
        return out

    def absorb(self, other: "AtomicUnit") -> None:
        """Operations per address added up by address (``self`` and ``other`` detached)."""
        super().absorb(other)
        self.addresses, self.ops_per_address = _per_address(np.concatenate([self.addresses, other.addresses]),
                                                            np.concatenate([self.ops_per_address,
                                                                            other.ops_per_address]))

    def values(self, total_cycles: int) -> dict:
        ops = self.ops_per_address
        return super().values(total_cycles) | {"hottest_address_ops": int(ops.max()) if len(ops) else 0,
                                               "addresses": len(ops)}

    def summary(self, total_cycles: int) -> dict:
        ops = self.ops_per_address
        return super().summary(total_cycles) | {"addresses": int(len(ops)),
                                                "hottest_address_ops": int(ops.max()) if len(ops) else 0}


def _per_address(addresses: np.ndarray, ops: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The distinct ``addresses`` (ascending) and the ``ops`` of each added up (a sort: numpy's hashing
    ``unique`` is far slower on millions of addresses)."""
    order = np.argsort(addresses, kind="stable")
    addresses = addresses[order]
    if not len(addresses):
        return addresses, ops[:0]
    starts = run_starts(addresses)
    return addresses[starts], np.add.reduceat(ops[order], starts)
