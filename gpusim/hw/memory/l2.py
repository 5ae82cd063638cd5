"""L2 slices, one per memory partition: set-associative, LRU, write-back, write-allocate.

A slice holds lines of its partition's share of the address space only (every ``memory.partitions``-th block
of ``memory.interleave_bytes``); it numbers them within that share, so its sets index the share's lines one
after another and every set is used.

An instruction's requests are looked up one at a time, in the order the
coalescer makes them. Each occupies its slice for ``bytes / l2.bytes_per_cycle``
from when it arrives or the slice frees; a hit completes ``l2.latency`` later,
a miss (and a dirty line it evicts, one line more) goes on to the next level
and completes ``l2.latency`` after that level's reply. The cache's contents
carry from pass to pass.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from gpusim.config import param
from gpusim.hw.memory.level import MemoryLevel, Requests
from gpusim.hw.memory.warming import HIT, MISS_DIRTY, request_codes
from gpusim.hw.unit import (FP, BUSY, REQUESTS, UTILISATION, Stat, div, fp_costs, register_unit,
                            within_instance)
from gpusim.metrics.composite import run_starts


@dataclass(frozen=True)
class L2Config:
    """One L2 slice per partition (set-associative, LRU, write-allocate)."""

    size_bytes: int = param(0, unit="bytes", doc="capacity per slice (0: no L2; requests go to the next level)",
                            min=0)
    line_bytes: int = param(128, unit="bytes", doc="line size", min=1)
    ways: int = param(16, unit="ways", doc="associativity", min=1)
    latency: int = param(100, unit="cycles", doc="hit latency", min=0)
    bytes_per_cycle: float = param(64.0, unit="bytes/cycle", doc="slice bandwidth", gt=0)

    def __post_init__(self):
        if self.size_bytes % (self.line_bytes * self.ways):
            raise ValueError(f"size_bytes ({self.size_bytes}) must be a multiple of line_bytes x ways "
                             f"({self.line_bytes * self.ways})")


@register_unit
class L2Slice(MemoryLevel):
    """Tag store of every slice: ``sets`` sets of ``ways`` lines per slice. A set is a dict from tag to dirty
    flag in recency order (least recent first), made when first touched."""

    name = "l2"
    Config = L2Config
    STATS = (BUSY, REQUESTS, UTILISATION, Stat("hits", "requests", "requests that hit"),
             Stat("misses", "requests", "requests that missed"))
    carries_state = True        # what a pass leaves in the cache, the next one finds

    def __init__(self, config: L2Config, machine):
        super().__init__(machine)
        self.line, self.ways, self.latency = config.line_bytes, config.ways, config.latency
        self.interleave = machine.gpu.memory.interleave_bytes, machine.gpu.memory.partitions   # bytes, slices
        self.rate = config.bytes_per_cycle
        self.sets = config.size_bytes // (config.line_bytes * config.ways)
        self.tags: dict[int, dict] = {}          # set (partition * sets + index) -> {tag: dirty}
        self.hits = [0] * self.instances
        self.misses = [0] * self.instances
        self.table: list = []
        # a sampled program (gpusim.hw.unit.occupancy): what the rest of the GPU's requests add to a slice after
        # the instruction that came with them, and that instruction (gpusim.hw.background: why here, not pooled)
        self.after, self.last = [0] * self.instances, [-1] * self.instances
        # a sample (gpusim.hw.memory.warming): the run's outcome of each request, where the run has it
        self.outcomes = getattr(self.program, "l2_outcomes", None)
        self.gpu = machine.gpu

    @classmethod
    def present(cls, config: L2Config) -> bool:
        return config.size_bytes > 0

    def prepare(self, chunks: list[Requests], write: np.ndarray) -> None:
        """Per instruction: its requests (partition, line, slice sub-cycles, next-level sub-cycles on a miss,
        and with a dirty eviction) and whether it writes."""
        self.table = [None] * len(write)
        if not chunks:
            return
        wi = np.concatenate([q.wi for q in chunks])
        nbytes = np.concatenate([q.nbytes for q in chunks])
        address = np.concatenate([q.address for q in chunks])
        part = np.concatenate([q.partition for q in chunks])
        bounds = np.append(run_starts(wi), len(wi)).tolist()
        cost, miss, evict = (fp_costs(nbytes, self.rate), self.next.request_costs(nbytes),
                             self.next.request_costs(nbytes + self.line))
        held = [self.occupy(c, wi, part, c is cost) for c in (cost, miss, evict)]
        line = div(within_instance(address, *self.interleave), self.line)     # numbered in the slice's share
        if self.outcomes is not None:
            code = request_codes(self.program, self.gpu, self.outcomes, wi, address).tolist()
        else:
            code = [-1] * len(wi)
        reqs = list(zip(part.tolist(), line.tolist(), cost.tolist(), miss.tolist(),
                        evict.tolist(), *(h.tolist() for h in held), code))
        first = wi[bounds[:-1]].tolist()
        w_ = write.tolist()
        for i, a, b in zip(first, bounds[:-1], bounds[1:]):
            self.table[i] = (reqs[a:b], w_[i])

    def lookup(self, p: int, line: int, write: bool, code: int = -1) -> tuple[bool, bool]:
        """(hit, a dirty line was evicted) for one request; the line becomes the set's most recent. ``code``: a
        sample's request's outcome in the run (gpusim.hw.memory.warming), which decides instead of the tags."""
        if code >= 0:
            if code == HIT:
                self.hits[p] += 1
                return True, False
            self.misses[p] += 1
            return False, code == MISS_DIRTY
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

    def access(self, wi: int, arrive_fp: int, starts: list | None) -> int:
        reqs, write = self.table[wi]
        free, busy, requests, nxt, latency = self.free, self.busy_fp, self.requests, self.next, self.latency
        done = 0
        after = self.after
        for p, line, cost, miss_cost, evict_cost, held, miss_held, evict_held, code in reqs:
            start = free[p]
            if after[p] and self.last[p] != wi:     # a sample: the rest of the GPU's requests that came with
                start += after[p]                    # the instruction before
                after[p] = 0
            if start < arrive_fp:
                start = arrive_fp
            if starts is not None and starts[p] < 0:
                starts[p] = start
            end = start + cost
            free[p] = end
            if held != cost:
                after[p] += held - cost
                self.last[p] = wi
            busy[p] += cost
            requests[p] += 1
            hit, evict = self.lookup(p, line, write, code)
            if hit:
                finish = -(-end // FP) + latency
            else:
                finish = nxt.serve_request(p, evict_cost if evict else miss_cost, end,
                                           evict_held if evict else miss_held, wi) + latency
            if finish > done:
                done = finish
        return done

    def idle_at(self) -> int:
        return -(-max(f + a for f, a in zip(self.free, self.after)) // FP)

    def values(self, total_cycles: int) -> dict:
        return super().values(total_cycles) | {"hits": list(self.hits), "misses": list(self.misses)}

    def summary(self, total_cycles: int) -> dict:
        h, m = sum(self.hits), sum(self.misses)
        return super().summary(total_cycles) | {"hits": h, "misses": m, "hit_rate": h / (h + m) if h + m else 0.0}
