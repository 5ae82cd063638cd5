"""The coalescer: a warp instruction's lanes become memory requests.

Lanes touching one ``coalescer.segment_bytes`` segment make one request, of
the bytes they touch rounded up to 32-byte sectors (at most the segment); an
access wider than a segment touches several. Requests go to the partition
of their ``memory.interleave_bytes`` block (gpusim.hw.unit.interleave) and on to the
next level after ``memory.interconnect_latency``; the result is back at the
core that long after the last request is served.

``rmw_read`` / ``rmw_write`` instructions get the sub-cycle each partition
started serving them (the moment a read samples memory and a write lands), for
the RMW-hazard analysis (gpusim.hw.hazards).
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np

from gpusim.config import param
from gpusim.hw.memory.level import MEMORY_OPS, SECTOR, MemoryLevel, Requests
from gpusim.hw.unit import FP, Stat, cycles, div, interleave, mod, register_unit
from gpusim.metrics.composite import run_starts
from gpusim.opplan import OPS

WRITE_OPS = ("store", "rmw_write")
RMW_OPS = ("rmw_read", "rmw_write")


def touched_segments(addr: np.ndarray, nbytes, segment: int) -> tuple[np.ndarray | None, np.ndarray]:
    """The ``segment``-byte segments accesses of ``nbytes`` (at least 1) at ``addr`` touch: (per access its
    number of segments, or None where each touches one; the segment of each piece, an access's ascending)."""
    seg = div(addr, segment)
    if not (mod(addr, segment) + nbytes > segment).any():
        return None, seg
    span = div(addr + nbytes - 1, segment) - seg + 1
    k = np.arange(span.sum()) - np.repeat(np.cumsum(span) - span, span)
    return span, np.repeat(seg, span) + k


def instruction_writes(program, framebuffer: bool) -> np.ndarray:
    """Per instruction of ``program``: whether its requests write (dirty their lines): stores and RMW writes, and
    where the ROPs' ``framebuffer`` traffic takes the memory path their operations (a read of each sector, then
    its write)."""
    write = np.isin(program.wi_op, [OPS.index(o) for o in WRITE_OPS])
    if framebuffer and "rop" in program.units:
        write[program.wi_unit == program.units.index("rop")] = True
    return write


def unit_requests(program, unit: str, wis: np.ndarray, counts: np.ndarray, memory, segment: int) -> list[Requests]:
    """Coalesced requests of ``unit``'s rows in ``program`` (its instructions ``wis`` in row-storage order, with
    ``counts`` rows each; ``memory``: the GPU's memory config, ``segment``: the coalescing segment in bytes): part
    by part (arrays the allocator reuses), or all rows at once when there are many small parts (a k-buffer batch
    run: thousands), where numpy's per-call cost would dominate."""
    R = program.rows_of(unit)
    los = program.row_lo[wis]
    parts = (zip(R.parts, R.offsets()) if len(R.parts) <= 64
             else [((None, R.address, R.nbytes, None), 0)])
    return [q for part, off in parts for q in _requests(part, off, los, counts, wis, memory, segment)]


def _requests(part, off: int, los: np.ndarray, counts: np.ndarray, wis: np.ndarray, memory, S: int,
              chunk: int = 1 << 20) -> list[Requests]:
    """Coalesced requests of one part of the rows, a chunk of whole instructions at a time (arrays small
    enough for the allocator to reuse)."""
    _, address, nbytes, _ = part
    a, b = np.searchsorted(los, [off, off + len(address)])
    ends = np.cumsum(counts[a:b])
    out = []
    lo = 0
    while lo < b - a:
        hi = max(lo + 1, int(np.searchsorted(ends, (ends[lo - 1] if lo else 0) + chunk, side="right")))
        r0, r1 = (ends[lo - 1] if lo else 0), ends[hi - 1]
        addr = address[r0:r1]
        nb = max(int(nbytes), 1) if np.isscalar(nbytes) else np.maximum(nbytes[r0:r1], 1)
        rank = np.repeat(np.arange(a + lo, a + hi), counts[a + lo:a + hi])
        span, seg = touched_segments(addr, nb, S)
        if span is not None:                     # an access wider than a segment touches several
            nb = np.broadcast_to(nb, addr.shape)
            rank, addr, nb = np.repeat(rank, span), np.repeat(addr, span), np.repeat(nb, span)
            nb = np.minimum(addr + nb, (seg + 1) * S) - np.maximum(addr, seg * S)
        # one request per (instruction, segment); lanes in address order (the common case) need no sort
        key = (rank << 36) | seg
        if len(key) > 1 and not (key[1:] >= key[:-1]).all():
            order = np.argsort(key, kind="stable")
            key = key[order]
            if not np.isscalar(nb):
                nb = nb[order]
        starts = run_starts(key)
        touched = (np.add.reduceat(nb, starts) if not np.isscalar(nb)
                   else np.diff(np.append(starts, len(key))) * nb)
        req_bytes = np.minimum(div(touched + SECTOR - 1, SECTOR) * SECTOR, max(S, SECTOR))
        key = key[starts]
        seg_addr = (key & ((1 << 36) - 1)) * S
        out.append(Requests(key >> 36, wis, interleave(seg_addr, memory.interleave_bytes, memory.partitions),
                            seg_addr, req_bytes))
        lo = hi
    return out


def memory_bytes(program, gpu) -> np.ndarray:
    """The bytes each pass of ``program`` brings to each memory partition, (passes, partitions): the coalesced
    requests of the core's memory instructions; where they take the memory path, the ROPs' framebuffer reads
    and writes (each sector twice); where ``atomic.dram_rmw`` is set, the atomic units' sector read and write
    per operation. A sampled program's "memory" occupancy is the whole run's over its own
    (gpusim.hw.sample)."""
    from gpusim.hw.atomic import DRAM_RMW_BYTES
    from gpusim.hw.rop import framebuffer_traffic
    mem = gpu.memory
    P, n = mem.partitions, len(program.passes)
    out = np.zeros(n * P)
    for unit, times in (("coalescer", 1), ("rop", 2 if framebuffer_traffic(gpu) else 0)):
        wis, counts, _ = program.storage(unit)
        if not times or not len(wis):
            continue
        for q in unit_requests(program, unit, wis, counts, mem, gpu.coalescer.segment_bytes):
            out += times * np.bincount(program.wi_pass[q.wi] * P + q.partition, weights=q.nbytes, minlength=n * P)
    if gpu.atomic.dram_rmw:
        rows = program.rows_of("atomic")
        if len(rows):
            _, _, wi = program.storage("atomic")
            part = interleave(rows.address, mem.interleave_bytes, P)
            out += DRAM_RMW_BYTES * np.bincount(program.wi_pass[wi] * P + part, minlength=n * P)
    return out.reshape(n, P)


@dataclass(frozen=True)
class CoalescerConfig:
    """Coalescing of a warp's accesses into requests."""

    segment_bytes: int = param(64, unit="bytes", doc="coalescing segment: a warp's accesses to one segment "
                               "become one request", min=1)


@register_unit
class Coalescer(MemoryLevel):
    name = "coalescer"
    Config = CoalescerConfig
    issued = MEMORY_OPS
    STATS = (Stat("requests", "requests", "coalesced requests sent to the partition"),
             Stat("bytes", "bytes", "bytes requested from the partition (whole sectors)"))
    COUNTERS: dict = {}
    TOTALS = ("requests", "bytes")

    def __init__(self, config: CoalescerConfig, machine):
        super().__init__(machine)
        self._access = self.next.access
        self.segment = config.segment_bytes
        mem = machine.gpu.memory
        self.icn, self.interleave = mem.interconnect_latency, mem.interleave_bytes
        prog = self.program = machine.program
        # rmw instructions: the sub-cycle each partition started serving them (None without unsynchronised RMW)
        self.rmw_starts: dict[int, list] | None = None
        self.rmw_merged: list = []          # (instructions, starts) served in other processes (gpusim.hw.parallel)
        self.bytes = [0] * self.instances
        wis, counts, _ = prog.storage(self.name)
        from gpusim.hw.rop import framebuffer_traffic
        write = instruction_writes(prog, framebuffer_traffic(machine.gpu))
        self._rmw = np.isin(prog.wi_op, [OPS.index(o) for o in RMW_OPS]).tolist()
        if any(self._rmw):
            self.rmw_starts = {}
        chunks = unit_requests(prog, self.name, wis, counts, mem, self.segment) if len(wis) else []
        P = self.instances
        if chunks:
            self.requests = sum(np.bincount(q.partition, minlength=P) for q in chunks).tolist()
            self.bytes = sum(np.bincount(q.partition, weights=q.nbytes, minlength=P) for q in chunks
                             ).astype(np.int64).tolist()
        # the ROPs' framebuffer traffic (gpusim.hw.rop) takes the same path from the next level on
        rop_wis, rop_counts, _ = prog.storage("rop") if framebuffer_traffic(machine.gpu) else ((), (), ())
        if len(rop_wis):
            order = np.concatenate([wis, rop_wis])
            chunks = [dataclasses.replace(q, order=order) for q in chunks]
            for q in unit_requests(prog, "rop", rop_wis, rop_counts, mem, self.segment):
                # a read of each sector, then its write (the blend, test or program's result)
                chunks.append(Requests(np.repeat(q.rank + len(wis), 2), order, np.repeat(q.partition, 2),
                                       np.repeat(q.address, 2), np.repeat(q.nbytes, 2)))
        if chunks:
            self.next.prepare(chunks, write)

    def framebuffer(self, wi: int, arrive_fp: int) -> int:
        """A ROP instruction's framebuffer requests (reads and writes of the sectors its operations touch),
        arriving at the next level at sub-cycle ``arrive_fp``: the cycle the last is served."""
        return self._access(wi, arrive_fp, None)

    def serve(self, wi: int, now: int) -> int:
        """Instruction ``wi`` issued at cycle ``now``: the cycle its last request is back at the core."""
        icn = self.icn
        if self._rmw[wi]:
            starts = [-1] * self.instances
            done = self._access(wi, (now + icn) * FP, starts)
            self.rmw_starts[wi] = starts
            return done + icn
        return self._access(wi, (now + icn) * FP, None) + icn

    def values(self, total_cycles: int) -> dict:
        return {"requests": list(self.requests), "bytes": list(self.bytes)}

    def summary(self, total_cycles: int) -> dict:
        return {"instances": self.instances, "requests": int(sum(self.requests)), "bytes": int(sum(self.bytes))}

    def idle_at(self) -> int:
        return 0

    def line_trace(self) -> str:
        return "coalescer: -"            # no state of its own: it times nothing

    def rmw_service_cycles(self) -> np.ndarray | None:
        """Per row of the memory instructions: the cycle an ``rmw_read`` sampled memory or an ``rmw_write``
        landed (its partition started serving it), -1 for other rows; None without RMW instructions."""
        if self.rmw_starts is None:
            return None
        prog = self.program
        R = prog.rows_of(self.name)
        out = np.full(len(R), -1, np.int64)
        wis, starts = self.rmw_start_arrays()
        if len(wis):
            lo, counts = prog.row_lo[wis], prog.row_hi[wis] - prog.row_lo[wis]
            k = np.repeat(np.arange(len(wis)), counts)
            rows = np.arange(len(k)) - np.repeat(np.cumsum(counts) - counts, counts) + lo[k]
            part = interleave(R.address[rows], self.interleave, self.instances)
            out[rows] = cycles(starts[k, part])
        return out

    def rmw_start_arrays(self) -> tuple[np.ndarray, np.ndarray]:
        """The RMW instructions served so far and, per partition, the sub-cycle each started serving them."""
        P = self.instances
        got = [(np.fromiter(self.rmw_starts, np.int64, len(self.rmw_starts)),
                np.array(list(self.rmw_starts.values()), np.int64).reshape(-1, P))] + self.rmw_merged
        return np.concatenate([w for w, _ in got]), np.concatenate([a for _, a in got])
