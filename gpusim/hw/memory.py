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
from gpusim.opplan import OPS
from gpusim.hw.units import FP, Unit, cycles, div, fp_costs, mod
from gpusim.metrics.composite import run_starts

SECTOR = 32     # bytes


class DramChannels(Unit):
    name = "dram"


class L2Slices(Unit):
    """Tag store of all slices: ``sets`` sets of ``ways`` lines per slice, LRU, write-back.

    A set is a dict from tag to dirty flag in recency order (least recent
    first), made when first touched: requests are looked up one at a time in
    the order the instruction makes them.
    """

    name = "l2"

    def __init__(self, gpu):
        super().__init__(gpu.memory.partitions)
        c = gpu.l2
        self.line = c.line_bytes
        self.ways = c.ways
        self.sets = c.size_bytes // (c.line_bytes * c.ways)
        self.tags: dict[int, dict] = {}          # set (partition * sets + index) -> {tag: dirty}
        self.hits = [0] * self.instances
        self.misses = [0] * self.instances

    def lookup(self, p: int, line: int, write: bool) -> tuple[bool, bool]:
        """(hit, a dirty line was evicted) for one request; the line becomes the set's most recent."""
        s = p * self.sets + line % self.sets
        tag = line // self.sets
        d = self.tags.get(s)
        if d is None:
            d = self.tags[s] = {}
        if tag in d:
            d[tag] = d.pop(tag) or write
            self.hits[p] += 1
            return True, False
        self.misses[p] += 1
        evict = False
        if len(d) >= self.ways:
            evict = d.pop(next(iter(d)))
        d[tag] = write
        return False, evict

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
        # rmw instructions: the sub-cycle each partition started serving them (None without unsynchronised RMW)
        self.rmw_starts: dict[int, list] | None = None
        self.rmw_merged: list = []          # (instructions, starts) served in other processes (gpusim.hw.parallel)
        self.prog = program
        # access(wi, t): serve instruction wi issued at cycle t; the cycle its last request is back at the core
        self.access = self._l2_path
        self._build(program)

    def _build(self, prog: Program) -> None:
        m, gpu = self.gpu.memory, self.gpu
        P = m.partitions
        wis, counts, _ = prog.storage(MEM)
        if not len(wis):
            return
        R = prog.rows_of(MEM)
        los = prog.row_lo[wis]
        write_op = np.zeros(len(OPS), bool)
        write_op[[OPS.index("store"), RMW_WRITE]] = True
        write = write_op[prog.wi_op]
        rmw_op = np.zeros(len(OPS), bool)
        rmw_op[[RMW_READ, RMW_WRITE]] = True
        rmw = rmw_op[prog.wi_op]
        if rmw.any():
            self.rmw_starts = {}
        # part by part (arrays the allocator reuses), or all rows at once when there are many small parts
        # (a k-buffer batch run: thousands), where numpy's per-call cost would dominate
        parts = (zip(R.parts, R.offsets()) if len(R.parts) <= 64
                 else [((None, R.address, R.nbytes, None), 0)])
        chunks = [q for part, off in parts for q in self._requests(part, off, los, counts, m)]
        self.bytes_written = sum(int(nb[write[wis[rank]]].sum()) for rank, _, nb in chunks)
        self.bytes_read = sum(int(nb.sum()) for _, _, nb in chunks) - self.bytes_written

        def part_of(seg):
            return mod(div(seg * m.segment_bytes, m.interleave_bytes), P)

        if self.l2 is None:
            # bytes, cost and requests per (instruction, partition), chunk by chunk (dense over the chunk)
            cells, nbs, nreqs = [], [], []
            for rank, seg, nb in chunks:
                r0 = int(rank[0])
                cell = (rank - r0) * P + part_of(seg)
                span = (int(rank[-1]) - r0 + 1) * P
                b_ = np.bincount(cell, weights=nb, minlength=span)
                n_ = np.bincount(cell, minlength=span)
                hit = np.flatnonzero(n_)
                cells.append(hit + r0 * P)
                nbs.append(b_[hit].astype(np.int64))     # whole bytes
                nreqs.append(n_[hit])
            hit, nb, nreq = np.concatenate(cells), np.concatenate(nbs), np.concatenate(nreqs)
            cost = fp_costs(nb, gpu.dram.bytes_per_cycle)
            k_rank, k_p = div(hit, P), mod(hit, P)      # (instruction, partition) cells with requests, in storage order
            self.dram.requests = np.bincount(k_p, weights=nreq, minlength=P).astype(np.int64).tolist()
            self.dram.busy_fp = np.bincount(k_p, weights=cost, minlength=P).astype(np.int64).tolist()
            # instruction wi owns cells lo[wi]:hi[wi] (kp: partition, kc: sub-cycles)
            bounds = np.searchsorted(k_rank, np.arange(len(wis) + 1))
            lo, hi = np.zeros(prog.instructions, np.int64), np.zeros(prog.instructions, np.int64)
            lo[wis], hi[wis] = bounds[:-1], bounds[1:]
            rmw_wis = set(np.flatnonzero(rmw).tolist())
            self.access = self._dram_access(lo.tolist(), hi.tolist(), k_p.tolist(), cost.tolist(), rmw_wis)
            return
        req_rank, req_seg, req_bytes = (np.concatenate(c) for c in zip(*chunks))
        req_wi = wis[req_rank]
        bounds = np.append(run_starts(req_wi), len(req_wi)).tolist()
        # per request: partition, line, L2 sub-cycles, DRAM sub-cycles on a miss, and with a dirty eviction
        reqs = list(zip(part_of(req_seg).tolist(), div(req_seg * m.segment_bytes, self.l2.line).tolist(),
                        fp_costs(req_bytes, gpu.l2.bytes_per_cycle).tolist(),
                        fp_costs(req_bytes, gpu.dram.bytes_per_cycle).tolist(),
                        fp_costs(req_bytes + self.l2.line, gpu.dram.bytes_per_cycle).tolist()))
        first_wi = req_wi[bounds[:-1]].tolist()
        w_, r_ = write.tolist(), rmw.tolist()
        self.table: list = [None] * prog.instructions     # instruction -> (requests, write, rmw)
        for wi, a, b in zip(first_wi, bounds[:-1], bounds[1:]):
            self.table[wi] = (reqs[a:b], w_[wi], r_[wi])

    @staticmethod
    def _requests(part, off: int, los: np.ndarray, counts: np.ndarray, m, chunk: int = 1 << 20):
        """Coalesced requests (instruction rank in storage order, segment, bytes) of one part of the rows,
        a chunk of whole instructions at a time (arrays small enough for the allocator to reuse)."""
        _, address, nbytes, _ = part
        a, b = np.searchsorted(los, [off, off + len(address)])
        ends = np.cumsum(counts[a:b])
        out = []
        S = m.segment_bytes
        lo = 0
        while lo < b - a:
            hi = max(lo + 1, int(np.searchsorted(ends, (ends[lo - 1] if lo else 0) + chunk, side="right")))
            r0, r1 = (ends[lo - 1] if lo else 0), ends[hi - 1]
            addr = address[r0:r1]
            nb = max(int(nbytes), 1) if np.isscalar(nbytes) else np.maximum(nbytes[r0:r1], 1)
            wi_of = np.repeat(np.arange(a + lo, a + hi), counts[a + lo:a + hi])
            seg = div(addr, S)
            if (mod(addr, S) + nb > S).any():       # an access wider than a segment touches several
                nb = np.broadcast_to(nb, addr.shape)
                span = div(addr + nb - 1, S) - seg + 1
                k = np.arange(span.sum()) - np.repeat(np.cumsum(span) - span, span)
                wi_of, addr, nb = np.repeat(wi_of, span), np.repeat(addr, span), np.repeat(nb, span)
                seg = np.repeat(seg, span) + k
                nb = np.minimum(addr + nb, (seg + 1) * S) - np.maximum(addr, seg * S)
            # one request per (instruction, segment); lanes in address order (the common case) need no sort
            key = (wi_of << 36) | seg
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
            out.append((key >> 36, key & ((1 << 36) - 1), req_bytes))
            lo = hi
        return out

    def _l2_path(self, wi: int, t: int) -> int:
        """``access`` with an L2: each request through its slice (hit at ``l2.bytes_per_cycle`` and
        ``l2.latency``), a miss or a dirty eviction on to the DRAM channel behind it."""
        reqs, write, rmw = self.table[wi]
        arrive = (t + self.icn) * FP
        l2, l2_free, dram_free = self.l2, self.l2_free, self.dram_free
        l2_busy, l2_req, d_busy, d_req = l2.busy_fp, l2.requests, self.dram.busy_fp, self.dram.requests
        l2_lat, miss_lat = self.gpu.l2.latency, self.gpu.dram.latency + self.gpu.l2.latency
        starts = [-1] * len(dram_free) if rmw else None     # first start per partition
        done = 0
        for p, line, cost, dmiss, devict in reqs:
            start = l2_free[p]
            if start < arrive:
                start = arrive
            if rmw and starts[p] < 0:
                starts[p] = start
            end = start + cost
            l2_free[p] = end
            l2_busy[p] += cost
            l2_req[p] += 1
            hit, evict = l2.lookup(p, line, write)
            if hit:
                finish = -(-end // FP) + l2_lat
            else:
                dstart = dram_free[p] if dram_free[p] > end else end
                dcost = devict if evict else dmiss
                dram_free[p] = dstart + dcost
                d_busy[p] += dcost
                d_req[p] += 1
                finish = -(-(dstart + dcost) // FP) + miss_lat
            if finish > done:
                done = finish
        if rmw:
            self.rmw_starts[wi] = starts
        return done + self.icn

    def sample(self) -> np.ndarray | None:
        """Per row of the memory instructions: the cycle an ``rmw_read`` sampled memory or an ``rmw_write``
        landed (its partition started serving it), -1 for other rows; None without RMW instructions."""
        if self.rmw_starts is None:
            return None
        prog = self.prog
        R = prog.rows_of(MEM)
        out = np.full(len(R), -1, np.int64)
        wis, starts = self.rmw_start_arrays()
        if len(wis):
            lo, counts = prog.row_lo[wis], prog.row_hi[wis] - prog.row_lo[wis]
            k = np.repeat(np.arange(len(wis)), counts)
            rows = np.arange(len(k)) - np.repeat(np.cumsum(counts) - counts, counts) + lo[k]
            part = mod(div(R.address[rows], self.gpu.memory.interleave_bytes), self.gpu.memory.partitions)
            out[rows] = cycles(starts[k, part])
        return out

    def rmw_start_arrays(self) -> tuple[np.ndarray, np.ndarray]:
        """The RMW instructions served so far and, per partition, the sub-cycle each started serving them."""
        P = self.gpu.memory.partitions
        got = [(np.fromiter(self.rmw_starts, np.int64, len(self.rmw_starts)),
                np.array(list(self.rmw_starts.values()), np.int64).reshape(-1, P))] + self.rmw_merged
        return np.concatenate([w for w, _ in got]), np.concatenate([a for _, a in got])

    def _dram_access(self, lo: list, hi: list, kp: list, kc: list, rmw_wis: set):
        """``access`` without an L2: instruction ``wi``'s cells ``lo[wi]:hi[wi]`` (partition ``kp``, sub-cycles
        ``kc``), each served by its channel back to back; a closure over locals, as it runs once per
        instruction."""
        icn, lat, free = self.icn, self.dram_lat, self.dram_free
        tail = lat + icn

        def access(wi: int, t: int) -> int:
            arrive = (t + icn) * FP
            end = 0
            for j in range(lo[wi], hi[wi]):
                p = kp[j]
                e = free[p]
                if e < arrive:
                    e = arrive
                e += kc[j]
                free[p] = e
                if e > end:
                    end = e
            return -(-end // FP) + tail

        if not rmw_wis:
            return access
        rmw_starts = self.rmw_starts

        def access_rmw(wi: int, t: int) -> int:
            if wi not in rmw_wis:
                return access(wi, t)
            arrive = (t + icn) * FP
            end = 0
            starts = [-1] * len(free)          # an instruction has one cell per partition it reaches
            for j in range(lo[wi], hi[wi]):
                p = kp[j]
                e = free[p]
                if e < arrive:
                    e = arrive
                starts[p] = e
                e += kc[j]
                free[p] = e
                if e > end:
                    end = e
            rmw_starts[wi] = starts
            return -(-end // FP) + tail

        return access_rmw

    def idle_at(self) -> int:
        """The cycle every channel and slice is free again."""
        return cycles(max(self.dram_free + self.l2_free))

    def units(self) -> list[Unit]:
        return [u for u in (self.l2, self.dram) if u is not None and sum(u.requests)]

    def line_trace(self) -> str:
        return " | ".join(u.line_trace() for u in (self.l2, self.dram) if u is not None)
