"""Memory partitions: address interleaving, an L2 slice and a DRAM channel each.

A warp instruction's accesses are coalesced: lanes touching one
``memory.segment_bytes`` segment make one request, of the bytes they touch
rounded up to 32-byte sectors (at most the segment). Requests go to partition
``(address // interleave_bytes) % partitions``. In each partition the requests
of one instruction are served back to back:

* without an L2 (``l2.size_bytes = 0``), by the DRAM channel at
  ``dram.bytes_per_cycle`` after ``interconnect_latency``, completing
  ``dram.latency`` later (and ``interconnect_latency`` back to the core);
* with an L2 slice (set-associative, LRU, write-back, write-allocate), hits are
  served at ``l2.bytes_per_cycle`` with ``l2.latency``; misses and dirty
  evictions also occupy the DRAM channel.

``rmw_read`` / ``rmw_write`` rows get the cycle their partition started serving
them (the moment a read samples memory and a write lands), for the RMW-hazard
analysis (gpusim.hw.hazards).
"""

from __future__ import annotations

import numpy as np

from gpusim.hw.lower import MEM, RMW_READ, RMW_WRITE, Program
from gpusim.schemes.opstream import OPS
from gpusim.hw.units import FP, Unit, cycles, div, fp_cost, fp_costs, mod

SECTOR = 32     # bytes


class DramChannels(Unit):
    name = "dram"


class L2Slices(Unit):
    """Tag store of all slices: ``sets`` sets of ``ways`` lines per slice."""

    name = "l2"

    def __init__(self, gpu):
        super().__init__(gpu.memory.partitions)
        c = gpu.l2
        self.line = c.line_bytes
        self.sets = c.size_bytes // (c.line_bytes * c.ways)
        self.tags = np.full((self.instances * self.sets, c.ways), -1, np.int64)
        self.stamp = np.zeros((self.instances * self.sets, c.ways), np.int64)
        self.dirty = np.zeros((self.instances * self.sets, c.ways), bool)
        self.clock = 0
        self.hits = [0] * self.instances
        self.misses = [0] * self.instances

    def lookup(self, part: np.ndarray, line: np.ndarray, write: bool) -> tuple[np.ndarray, np.ndarray]:
        """Hit flags and dirty-eviction flags of requests (one instruction's lines, distinct)."""
        s = part * self.sets + line % self.sets
        tag = line // self.sets
        match = self.tags[s] == tag[:, None]
        hit = match.any(axis=1)
        way = np.where(hit, match.argmax(axis=1), self.stamp[s].argmin(axis=1))
        evict_dirty = ~hit & self.dirty[s, way] & (self.tags[s, way] >= 0)
        self.clock += 1
        self.tags[s, way] = tag
        self.stamp[s, way] = self.clock
        self.dirty[s, way] = np.where(hit, self.dirty[s, way] | write, write)
        for p, h in zip(part.tolist(), hit.tolist()):
            if h:
                self.hits[p] += 1
            else:
                self.misses[p] += 1
        return hit, evict_dirty

    def stats(self, total_cycles):
        from gpusim.hw.units import UnitStat
        rows = super().stats(total_cycles)
        for i in range(self.instances):
            rows += [UnitStat(self.name, "hits", self.hits[i], "requests", "requests that hit", i),
                     UnitStat(self.name, "misses", self.misses[i], "requests", "requests that missed", i)]
        return rows

    def summary(self, total_cycles):
        out = super().summary(total_cycles)
        h, m = sum(self.hits), sum(self.misses)
        return out | {"hits": h, "misses": m, "hit_rate": h / (h + m) if h + m else 0.0}


class Partitions:
    """The memory partitions serving load/store/rmw instructions."""

    def __init__(self, gpu, program: Program):
        self.gpu = gpu
        m = gpu.memory
        self.icn = m.interconnect_latency
        self.dram = DramChannels(m.partitions)
        self.l2 = L2Slices(gpu) if gpu.l2.size_bytes else None
        self.dram_free = [0] * m.partitions        # sub-cycles
        self.l2_free = [0] * m.partitions
        self.bytes_read = self.bytes_written = 0
        self.dram_lat = gpu.dram.latency
        self.sample = np.full(len(program.rows_of(MEM)), -1, np.int64)   # rmw rows: cycle served
        self._build(program)

    def _build(self, prog: Program) -> None:
        m, gpu = self.gpu.memory, self.gpu
        P = m.partitions
        self.table: list = [None] * prog.instructions
        wis, counts, _ = prog.storage(MEM)
        if not len(wis):
            return
        R = prog.rows_of(MEM)
        wi_of = np.repeat(np.arange(len(wis)), counts)        # rank in storage order (monotone)
        S = m.segment_bytes
        addr, nbytes = R.address, np.maximum(R.nbytes, 1)
        seg = div(addr, S)
        if (mod(addr, S) + nbytes > S).any():    # an access wider than a segment touches several
            span = div(addr + nbytes - 1, S) - seg + 1
            k = np.arange(span.sum()) - np.repeat(np.cumsum(span) - span, span)
            wi_of, addr, nbytes = np.repeat(wi_of, span), np.repeat(addr, span), np.repeat(nbytes, span)
            seg = np.repeat(seg, span) + k
            lo, hi = np.maximum(addr, seg * S), np.minimum(addr + nbytes, (seg + 1) * S)
            nbytes = hi - lo
        # one request per (instruction, segment); lanes in address order (the common case) need no sort
        key = (wi_of << 36) | seg
        if len(key) > 1 and not (key[1:] >= key[:-1]).all():
            order = np.argsort(key, kind="stable")
            key, nbytes = key[order], nbytes[order]
        starts = np.flatnonzero(np.r_[True, key[1:] != key[:-1]])
        key = key[starts]
        req_wi, req_seg = wis[key >> 36], key & ((1 << 36) - 1)
        touched = np.add.reduceat(nbytes, starts)
        req_bytes = np.minimum(div(touched + SECTOR - 1, SECTOR) * SECTOR, max(m.segment_bytes, SECTOR))
        req_addr = req_seg * m.segment_bytes
        req_part = mod(div(req_addr, m.interleave_bytes), P)
        write_op = np.zeros(len(OPS), bool)
        write_op[[OPS.index("store"), RMW_WRITE]] = True
        write = write_op[prog.wi_op]
        self.bytes_written = int(req_bytes[write[req_wi]].sum())
        self.bytes_read = int(req_bytes.sum()) - self.bytes_written
        rmw_op = np.zeros(len(OPS), bool)
        rmw_op[[RMW_READ, RMW_WRITE]] = True
        rmw = rmw_op[prog.wi_op]

        def row_part(r: slice):
            return mod(div(R.address[r], m.interleave_bytes), P)

        if self.l2 is None:
            # bytes, cost and requests per (instruction, partition): dense, no sort
            cell = req_wi * P + req_part
            nb = np.bincount(cell, weights=req_bytes, minlength=prog.instructions * P)
            nreq = np.bincount(cell, minlength=prog.instructions * P)
            hit = np.flatnonzero(nreq)
            cost = fp_costs(nb[hit], gpu.dram.bytes_per_cycle)
            k_wi, k_p = hit // P, hit % P      # (instruction, partition) cells with requests
            self.dram.requests = np.bincount(k_p, weights=nreq[hit], minlength=P).astype(np.int64).tolist()
            self.dram.busy_fp = np.bincount(k_p, weights=cost, minlength=P).astype(np.int64).tolist()
            self.kp, self.kc = k_p.tolist(), cost.tolist()      # flat; instruction wi owns off[wi]:off[wi+1]
            self.off = np.searchsorted(k_wi, np.arange(prog.instructions + 1)).tolist()
            self.rmw = {wi: (prog.rows(wi), row_part(prog.rows(wi))) for wi in np.flatnonzero(rmw).tolist()}
            return
        bounds = np.append(np.flatnonzero(np.r_[True, req_wi[1:] != req_wi[:-1]]), len(req_wi)).tolist()
        lines = div(req_addr, self.l2.line)
        for j in range(len(bounds) - 1):
            a, b = bounds[j], bounds[j + 1]
            wi = int(req_wi[a])
            r = prog.rows(wi) if rmw[wi] else None
            self.table[wi] = ((req_part[a:b], lines[a:b], req_bytes[a:b]), bool(write[wi]),
                              (r, row_part(r)) if r is not None else None)

    def access(self, wi: int, t: int) -> int:
        """Serve instruction ``wi`` issued at cycle ``t``; the cycle its last request completes."""
        if self.l2 is not None:
            entry, write, rmw = self.table[wi]
            starts: dict = {}
            done = self._l2_access(entry, write, (t + self.icn) * FP, starts)
        else:
            kp, kc = self.kp, self.kc
            a, b = self.off[wi], self.off[wi + 1]
            arrive = (t + self.icn) * FP
            free = self.dram_free
            end = 0
            rmw = self.rmw.get(wi) if self.rmw else None
            if rmw is not None:
                starts = [0] * len(free)
                for j in range(a, b):
                    starts[kp[j]] = max(arrive, free[kp[j]])
            for j in range(a, b):
                p = kp[j]
                e = free[p]
                if e < arrive:
                    e = arrive
                e += kc[j]
                free[p] = e
                if e > end:
                    end = e
            done = -(-end // FP) + self.dram_lat
        if rmw is not None:
            r, parts = rmw
            if isinstance(starts, dict):
                starts = [starts.get(p, 0) for p in range(len(self.dram_free))]
            self.sample[r] = -(-np.asarray(starts, np.int64)[parts] // FP)
        return done + self.icn

    def _l2_access(self, entry, write, arrive, starts) -> int:
        parts, lines, nbytes = entry
        hit, evict = self.l2.lookup(parts, lines, write)
        c, d = self.gpu.l2, self.gpu.dram
        done = 0
        for p, h, e, nb in zip(parts.tolist(), hit.tolist(), evict.tolist(), nbytes.tolist()):
            start = max(arrive, self.l2_free[p])
            cost = fp_cost(nb, c.bytes_per_cycle)
            self.l2_free[p] = start + cost
            self.l2.busy_fp[p] += cost
            self.l2.requests[p] += 1
            starts.setdefault(p, start)
            finish = cycles(start + cost) + c.latency
            if not h or e:
                moved = (0 if h else nb) + (self.l2.line if e else 0)
                dstart = max(start + cost, self.dram_free[p])
                dcost = fp_cost(moved, d.bytes_per_cycle)
                self.dram_free[p] = dstart + dcost
                self.dram.busy_fp[p] += dcost
                self.dram.requests[p] += 1
                if not h:
                    finish = cycles(dstart + dcost) + d.latency + c.latency
            done = max(done, finish)
        return done

    def units(self) -> list[Unit]:
        return [u for u in (self.l2, self.dram) if u is not None and sum(u.requests)]

    def line_trace(self) -> str:
        return " | ".join(u.line_trace() for u in (self.l2, self.dram) if u is not None)
