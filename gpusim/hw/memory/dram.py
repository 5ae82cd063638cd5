"""DRAM channels, one per memory partition.

Requests that reach a channel straight from the coalescer are served an
instruction at a time: an instruction's requests to one partition back to
back, ``bytes / dram.bytes_per_cycle`` together, from when they arrive or the
channel frees; they complete ``dram.latency`` later. A request from a level
above (an L2 miss, with any dirty line it evicts) is served on its own. Where
``atomic.dram_rmw`` is set, the partition's atomic unit holds the channel for
each operation's sector read and write (gpusim.hw.atomic). In a sampled
program a channel also serves its share of the rest of the GPU's requests
(gpusim.hw.background) ahead of the sample's next one.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from gpusim.config import param
from gpusim.hw.background import background
from gpusim.hw.memory.level import MemoryLevel, Requests
from gpusim.hw.unit import FP, div, fp_costs, mod, register_unit, run_divisor


@dataclass(frozen=True)
class DramConfig:
    """One DRAM channel per partition."""

    bytes_per_cycle: float = param(13.67, unit="bytes/cycle", doc="channel bandwidth per shader cycle", gt=0)
    latency: int = param(400, unit="cycles", doc="access latency (row activation, CAS, return)", min=0)


@register_unit
class DramChannel(MemoryLevel):
    name = "dram"
    Config = DramConfig
    terminal = True

    @classmethod
    def needed(cls, program, gpu) -> bool:
        """Also where the atomic units read and write their sectors in DRAM (``atomic.dram_rmw``)."""
        from gpusim.hw.atomic import dram_atomics
        return super().needed(program, gpu) or (cls.name in gpu.memory.levels and dram_atomics(program, gpu))

    def __init__(self, config: DramConfig, machine):
        super().__init__(machine)
        self.rate, self.latency = config.bytes_per_cycle, config.latency
        # a sampled program: the pool of the rest of the GPU's requests (gpusim.hw.background), each
        # instruction's pass
        self.pool = background(self.program, "memory")
        self.wi_pass = self.program.wi_pass.tolist() if self.pool is not None else None
        # a sampled program: per instruction, what its held sub-cycles are divided by to stand for the run's
        # (gpusim.hw.unit.run_held)
        self.wi_run = (None if self.run_busy_fp is None
                       else run_divisor(self.program, "memory")[self.program.wi_pass].tolist())
        self._lo = self._hi = self._part = self._cost = self._extra = None

    def prepare(self, chunks: list[Requests], write: np.ndarray) -> None:
        """Per (instruction, partition): the bytes of its requests, served together (dense over each chunk)."""
        P = self.instances
        cells, nbs, nreqs = [], [], []
        for q in chunks:
            r0 = int(q.rank[0])
            cell = (q.rank - r0) * P + q.partition
            span = (int(q.rank[-1]) - r0 + 1) * P
            b_ = np.bincount(cell, weights=q.nbytes, minlength=span)
            n_ = np.bincount(cell, minlength=span)
            hit = np.flatnonzero(n_)
            cells.append(hit + r0 * P)
            nbs.append(b_[hit].astype(np.int64))     # whole bytes
            nreqs.append(n_[hit])
        if not chunks:
            return
        order = chunks[0].order
        hit, nb, nreq = np.concatenate(cells), np.concatenate(nbs), np.concatenate(nreqs)
        cost = fp_costs(nb, self.rate)
        rank, part = div(hit, P), mod(hit, P)      # (instruction, partition) cells, in storage order
        self.requests = np.bincount(part, weights=nreq, minlength=P).astype(np.int64).tolist()
        self.busy_fp = np.bincount(part, weights=cost, minlength=P).astype(np.int64).tolist()
        # instruction wi owns cells lo[wi]:hi[wi]
        bounds = np.searchsorted(rank, np.arange(len(order) + 1))
        n = len(write)
        lo, hi = np.zeros(n, np.int64), np.zeros(n, np.int64)
        lo[order], hi[order] = bounds[:-1], bounds[1:]
        self._lo, self._hi, self._part, self._cost = lo.tolist(), hi.tolist(), part.tolist(), cost.tolist()
        held = self.occupy(cost, order[rank], part)
        # a sampled program: what each cell brings to the pool of the rest of the GPU's requests
        self._extra = None if held is cost else (held - cost).tolist()

    def access(self, wi: int, arrive_fp: int, starts: list | None) -> int:
        free, part, cost = self.free, self._part, self._cost
        if self.pool is not None:               # each partition's share of the rest of the GPU's requests first
            end = self.pool.serve(self.wi_pass[wi], self._lo[wi], self._hi[wi], part, cost, self._extra, free,
                                  arrive_fp, starts)
            return -(-end // FP) + self.latency
        end = 0
        for j in range(self._lo[wi], self._hi[wi]):
            p = part[j]
            e = free[p] if free[p] > arrive_fp else arrive_fp
            if starts is not None:
                starts[p] = e                   # an instruction has one cell per partition it reaches
            e += cost[j]
            free[p] = e
            if e > end:
                end = e
        return -(-end // FP) + self.latency

    def take(self, p: int, at_fp: int, cost_fp: int, extra_fp: int, wi: int) -> int:
        """Channel ``p`` serves ``cost_fp`` sub-cycles of instruction ``wi``'s work (an atomic's read-modify-write,
        or an L2 miss), from ``at_fp`` or when it is free; in a sampled program it stands for ``extra_fp`` more
        of the rest of the GPU's (gpusim.hw.background). The sub-cycle it starts."""
        free = self.free
        if self.pool is not None:
            start = self.pool.start(self.wi_pass[wi], p, free[p], at_fp, extra_fp, cost_fp)
        else:
            start = free[p] if free[p] > at_fp else at_fp
        free[p] = start + cost_fp
        return start

    def serve_for(self, cost_fp: np.ndarray, wi: np.ndarray, partition: np.ndarray, requests: np.ndarray) -> list:
        """Work another unit does in the channels (the atomic units' read-modify-writes, ``atomic.dram_rmw``):
        ``cost_fp`` sub-cycles of ``requests`` requests per (instruction ``wi``, ``partition``) cell, counted in
        the channels' busy cycles and requests; how long each cell stands for in its channel (:meth:`occupy`).
        The other unit takes the channel (:meth:`take`) as it serves the cell."""
        P = self.instances
        self.busy_fp = (np.asarray(self.busy_fp) + np.bincount(partition, weights=cost_fp, minlength=P)
                        ).astype(np.int64).tolist()
        self.requests = (np.asarray(self.requests) + np.bincount(partition, weights=requests, minlength=P)
                         ).astype(np.int64).tolist()
        return np.asarray(self.occupy(cost_fp, wi, partition), np.int64).tolist()

    def request_costs(self, nbytes: np.ndarray) -> np.ndarray:
        return fp_costs(nbytes, self.rate)

    def serve_request(self, partition: int, cost_fp: int, at_fp: int, held_fp: int, wi: int) -> int:
        start = self.take(partition, at_fp, cost_fp, held_fp - cost_fp, wi)
        if self.run_busy_fp is not None:
            self.run_busy_fp[partition] += round(held_fp / self.wi_run[wi])
        self.busy_fp[partition] += cost_fp
        self.requests[partition] += 1
        return -(-(start + cost_fp) // FP) + self.latency

    def idle_at(self) -> int:
        """The cycle every channel has served its requests, and in a sampled program its share of what is left
        in the pool of the rest of the GPU's."""
        free = self.free if self.pool is None else self.pool.settled(self.free)
        return -(-max(free) // FP)
