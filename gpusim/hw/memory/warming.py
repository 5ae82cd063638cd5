"""Functional warming of the L2 for the sampled level (gpusim.hw.sample): a sample's hits and misses are the run's.

A replicate of the sampled level keeps some screen tiles' threads on a GPU cut down to a share of its SMs.
Its L2 cannot be "the sample's share of the cache": whether a line is still there when a thread comes back
to it depends on every line the whole GPU touched in between, mostly by threads the sample leaves out. A
slice cut to the sample's share of the run's lines misses far less than the run's when the run thrashes
(the k-buffer on the fidelity corpus's thesis frame, laptop-ampere: 311,037 misses at the full level, a
tenth of that scaled up from such a sample, which then ran 44% short).

So the sample takes its L2 outcomes from the run, as sampling simulators warm their caches functionally
from the whole instruction stream (SMARTS: Wunderlich et al., ISCA 2003):

* The run is lowered as the full level lowers it. Every request its instructions send down the memory path
  (the core's loads and stores; the ROPs' framebuffer reads and writes where they take that path) goes
  through an LRU model of the slices: the same partitions, sets, ways, write-back and write-allocate as
  :class:`gpusim.hw.memory.l2.L2Slice`, one lookup per line an instruction touches (its other requests to
  the line take that lookup's outcome).
* In the order the full level issues them, approximately: a pass after the one before; within a pass the
  warps start in a sliding window of the GPU's resident warps (``R = sms x warps_per_sm``), instruction
  ``k`` of the pass's ``w``-th warp at ``w x K / R + k`` (``K``: the pass's instructions per warp). On that
  thesis-frame case this order gives 317,683 misses against the event order's 311,037 (warp after warp
  gives 176,343).
* Each lookup gets its outcome: a hit, a miss, or a miss whose fill evicts a dirty line (one line more to
  the next level). A miss is spread over the lanes (segments) of the instruction that share the line.
* A sample's request takes the share of the run's misses its own lanes carry: each lane finds the run's
  segment of the same operation (the same thread's instruction of the same plan group and loop iteration)
  on the same line, the request's miss probability is the sum of their shares, and a hash of the request
  draws its outcome (deterministic). The sample packs its lanes into warps of its own, which touch a line in
  more instructions than the run's (2.1 requests a line lookup against 2.6 on foliage 384x384 with the
  k-buffer): taking a whole miss per request there counted 1.3x the run's misses. A request's repeat (the
  ROPs' write after their read of a sector) hits; a request none of whose lanes is an operation of the run
  looks up the slice's own tags.

Measured (the k-buffer, laptop-ampere): on the thesis frame the sample now runs 2.6% over the full level (44%
short before); on foliage 384x384 (1.7M fragments) its misses are 4.84M against the full level's 5.03M and
its cycles 3.3% short (8.8% before).

The L2's service times and the rest of the GPU's share of each slice are the sampled level's as before
(``Program.occupancy``); only the hit-or-miss decision comes from the run. The replay and the lanes' search
are compiled with numba where it is installed (gpusim.jit; about 4 s for foliage 384x384's 44M segments,
besides lowering the run, 1.9 s); without it the same functions run in Python, with the same results,
slowly.
"""

from __future__ import annotations

import numpy as np

from gpusim.hw.memory.coalescer import instruction_writes, touched_segments
from gpusim.hw.memory.level import SECTOR
from gpusim.hw.unit import FP, div, fp_costs, interleave, mod, within_instance
from gpusim.jit import compiled_once

HIT, MISS, MISS_DIRTY = 0, 1, 2          # a request's outcome
SEEN = 1024                              # distinct lines an instruction's outcomes are remembered for


class Segments:
    """The memory-path rows of a program cut into the coalescing segments they touch, in row-storage order
    (an instruction's segments are adjacent): each segment's instruction, thread, L2 set (over all slices)
    and tag."""

    def __init__(self, program, gpu):
        S, m, l2 = gpu.coalescer.segment_bytes, gpu.memory, gpu.l2
        self.sets = l2.size_bytes // (l2.line_bytes * l2.ways)
        from gpusim.hw.rop import framebuffer_traffic
        units = ("coalescer", "rop") if framebuffer_traffic(gpu) else ("coalescer",)
        wis, counts, address, thread = [], [], [], []
        for unit in units:
            rows = program.rows_of(unit)
            if not len(rows):
                continue
            w, c, _ = program.storage(unit)
            span, first = touched_segments(rows.address, np.maximum(rows.nbytes, 1), S)
            th = rows.thread
            if span is not None:                     # a row wider than a segment touches several
                th = np.repeat(th, span)
                c = np.add.reduceat(span, np.cumsum(c) - c) if len(c) else c
            wis.append(w)
            counts.append(c)
            address.append(first * S)
            thread.append(th)
        cat = (lambda a, t: np.concatenate(a).astype(t) if a else np.zeros(0, t))  # noqa: E731
        self.wis, counts = cat(wis, np.int64), cat(counts, np.int64)    # instructions in storage order
        self.hi = np.cumsum(counts)                                         # and their segments' ends
        self.lo = self.hi - counts
        self.address = address = cat(address, np.int64)
        self.wi = np.repeat(self.wis, counts).astype(np.int32)
        self.thread = cat(thread, np.int64).astype(np.int32)
        part = interleave(address, m.interleave_bytes, m.partitions)
        line = div(within_instance(address, m.interleave_bytes, m.partitions), l2.line_bytes)
        self.set = (part * self.sets + mod(line, self.sets)).astype(np.int32)
        self.tag = div(line, self.sets)

    def __len__(self) -> int:
        return len(self.wi)


def issue_order(program, gpu, wis: np.ndarray) -> np.ndarray:
    """Instructions ``wis`` in the order the full level about issues them (see the module docstring)."""
    resident = gpu.core.sms * gpu.core.warps_per_sm
    warp = program.wi_warp[wis]
    first_wi = np.searchsorted(program.wi_warp, warp)              # the warp's first instruction
    p = program.wi_pass[wis]
    per_warp = np.array([pp.instructions / max(1, pp.warps) for pp in program.passes] or [0.0])
    first_warp = np.array([pp.first_warp for pp in program.passes] or [0], np.int64)
    start = (warp - first_warp[p]) * (per_warp[p] / resident) + (wis - first_wi)
    return np.lexsort((wis, start, p))


def _lru_outcomes(lo, hi, set_of, tag_of, dirties, sets_total, ways, code, lanes):
    """The LRU model of the slices over instructions whose segments are ``lo[i]..hi[i]-1``, in that order
    (``set_of``, ``tag_of``: each segment's set and tag; ``dirties[i]``: whether instruction ``i`` writes):
    one lookup per line an instruction touches, whose outcome every segment of the line gets in ``code``, and
    in ``lanes`` the instruction's segments (lanes) on the line, over which its miss is spread."""
    tags = np.full((sets_total, ways), -1, np.int64)
    age = np.zeros((sets_total, ways), np.int64)
    dirty = np.zeros((sets_total, ways), np.bool_)
    seen_set = np.zeros(SEEN, np.int64)
    seen_tag = np.zeros(SEEN, np.int64)
    seen_code = np.zeros(SEEN, np.int64)
    seen_lanes = np.zeros(SEEN, np.int64)
    clock = 0
    for i in range(len(lo)):
        n_seen = 0
        for s in range(lo[i], hi[i]):
            st, tg = set_of[s], tag_of[s]
            c = -1
            for j in range(n_seen):
                if seen_set[j] == st and seen_tag[j] == tg:
                    c = seen_code[j]
                    seen_lanes[j] += 1
                    break
            if c >= 0:
                code[s] = c
                continue
            clock += 1
            found, oldest = -1, 0
            for w in range(ways):
                if tags[st, w] == tg:
                    found = w
                    break
                if age[st, w] < age[st, oldest]:
                    oldest = w
            if found >= 0:
                c = HIT
            else:
                c = MISS_DIRTY if tags[st, oldest] >= 0 and dirty[st, oldest] else MISS
                found = oldest
                tags[st, found] = tg
                dirty[st, found] = False
            age[st, found] = clock
            if dirties[i]:
                dirty[st, found] = True
            code[s] = c
            if n_seen < SEEN:
                seen_set[n_seen], seen_tag[n_seen], seen_code[n_seen], seen_lanes[n_seen] = st, tg, c, 1
                n_seen += 1
        for s in range(lo[i], hi[i]):
            st, tg = set_of[s], tag_of[s]
            lanes[s] = 1
            for j in range(n_seen):
                if seen_set[j] == st and seen_tag[j] == tg:
                    lanes[s] = min(seen_lanes[j], 65535)
                    break


def _run_segment(thread, pass_of, group, k, set_of, tag_of, offsets, perm, r_wi, r_set, r_tag, wi_pass, wi_group,
                 wi_k, out):
    """For each of a sample's segments (its ``thread``, pass, plan ``group``, loop iteration ``k``, set and
    tag): the run's segment of the same operation and line (found among the run's segments of the thread,
    ``perm[offsets[t]:offsets[t + 1]]``), or -1."""
    for s in range(len(thread)):
        t, c = thread[s], -1
        if t + 1 < len(offsets):
            for q in range(offsets[t], offsets[t + 1]):
                j = perm[q]
                w = r_wi[j]
                if (r_set[j] == set_of[s] and r_tag[j] == tag_of[s] and wi_pass[w] == pass_of[s]
                        and wi_group[w] == group[s] and wi_k[w] == k[s]):
                    c = j
                    break
        out[s] = c


_KERNELS: dict[str, list] = {"lru": [], "run_segment": []}      # compiled on first use (gpusim.jit.compiled_once)


def _kernel(name: str, func):
    return compiled_once(_KERNELS[name], func) or func


class Outcomes:
    """Every L2 request of a run and its outcome, for a sample's requests to take (:func:`request_codes`): per
    segment of the run's memory-path rows, its share of its line's miss (the miss over the instruction's
    segments on the line; 0 for a hit) and whether the miss evicted a dirty line."""

    def __init__(self, program, gpu):
        segs = Segments(program, gpu)
        order = issue_order(program, gpu, segs.wis)
        code = np.zeros(len(segs), np.uint8)
        lanes = np.zeros(len(segs), np.uint16)
        from gpusim.hw.rop import framebuffer_traffic
        writes = instruction_writes(program, framebuffer_traffic(gpu))[segs.wis[order]]
        _kernel("lru", _lru_outcomes)(segs.lo[order], segs.hi[order], segs.set, segs.tag, writes,
                                      gpu.memory.partitions * segs.sets, gpu.l2.ways, code, lanes)
        # a line's miss spread over the instruction's segments (lanes) on it: a sample's request takes the
        # share of it its own lanes carry
        self.miss = np.where(code > 0, 1.0 / lanes, 0.0).astype(np.float32)
        self.dirty = code == MISS_DIRTY
        # per slice, the run's misses (one per line lookup) and those that evict a dirty line
        part = segs.set // max(1, segs.sets)
        self.misses = np.bincount(part, weights=self.miss, minlength=gpu.memory.partitions)
        self.dirty_misses = np.bincount(part, weights=np.where(self.dirty, self.miss, 0.0),
                                        minlength=gpu.memory.partitions)
        # the run's segments by thread, for a sample's operations to find theirs
        threads = int(segs.thread.max()) + 1 if len(segs) else 0
        self.offsets = np.append(0, np.cumsum(np.bincount(segs.thread, minlength=threads)))
        self.perm = np.argsort(segs.thread, kind="stable")
        self.wi, self.set, self.tag = segs.wi, segs.set, segs.tag
        self.wi_pass, self.wi_group, self.wi_k = program.wi_pass, program.wi_group, program.wi_k

    def next_level(self, gpu) -> dict:
        """What the run's misses bring to the DRAM, per partition: ``requests`` (one per miss: the first request
        to the line, a segment of at least a sector; the instruction's others to the line hit) and
        ``busy_cycles`` (its bytes, and a dirty line's more where the miss evicts one), as the L2 slice sends
        them (gpusim.hw.memory.l2)."""
        nbytes = max(gpu.coalescer.segment_bytes, SECTOR)
        miss, evict = fp_costs(np.array([nbytes, nbytes + gpu.l2.line_bytes]), gpu.dram.bytes_per_cycle)
        busy = (self.misses * miss + self.dirty_misses * (evict - miss)) / FP
        return {"requests": self.misses, "busy_cycles": busy}

    def of(self, thread, pass_of, group, k, set_of, tag_of) -> np.ndarray:
        """The run's segment of each of a sample's segments (-1: not an operation of the run): the same
        thread's, in the same pass, plan group and loop iteration, on the same line (a thread that reads a
        line in every pass of a multi-pass scheme finds each pass's own)."""
        out = np.full(len(thread), -1, np.int64)
        _kernel("run_segment", _run_segment)(thread, pass_of, group, k, set_of, tag_of, self.offsets, self.perm,
                                             self.wi, self.set, self.tag, self.wi_pass, self.wi_group, self.wi_k,
                                             out)
        return out


def _mix(h: np.ndarray, v) -> np.ndarray:
    """``h`` combined with ``v`` (uint64) by splitmix64's finaliser."""
    x = (h * np.uint64(0x9E3779B97F4A7C15)) ^ v
    x = (x ^ (x >> np.uint64(30))) * np.uint64(0xBF58476D1CE4E5B9)
    x = (x ^ (x >> np.uint64(27))) * np.uint64(0x94D049BB133111EB)
    return x ^ (x >> np.uint64(31))


def _request_key(wi: np.ndarray, address: np.ndarray, seed: int = 0) -> np.ndarray:
    """A 64-bit key of each (instruction, segment address), and with ``seed`` a draw from it."""
    with np.errstate(over="ignore"):
        return _mix(_mix(wi.astype(np.uint64) + np.uint64(seed), address.astype(np.uint64)), np.uint64(0))


def request_codes(program, gpu, outcomes: Outcomes, wi: np.ndarray, address: np.ndarray) -> np.ndarray:
    """The outcome of each of a sample's L2 requests (instruction ``wi``, segment ``address``): a miss with the
    probability its lanes carry of the run's misses (the sum over its lanes of the run's miss on the lane's
    line over the lanes that shared it), a dirty eviction the same way, drawn by a hash of the request
    (deterministic; the expected misses are the run's share the sample's lanes carry), and HIT for its
    repeat (a ROP's write after its read); -1 where none of its lanes is an operation of the run (the
    slice's tags decide)."""
    segs = Segments(program, gpu)
    run = outcomes.of(segs.thread, program.wi_pass[segs.wi], program.wi_group[segs.wi], program.wi_k[segs.wi],
                      segs.set, segs.tag)
    found = run >= 0
    mine = _request_key(segs.wi, segs.address)
    keys, slot = np.unique(mine, return_inverse=True)
    miss = np.bincount(slot, weights=np.where(found, outcomes.miss[run], 0.0), minlength=len(keys))
    dirty = np.bincount(slot, weights=np.where(found, outcomes.miss[run] * outcomes.dirty[run], 0.0),
                        minlength=len(keys))
    known = np.bincount(slot, weights=found, minlength=len(keys)) > 0
    asked = _request_key(wi, address)
    at = np.minimum(np.searchsorted(keys, asked), max(0, len(keys) - 1))
    known_request = (keys[at] == asked) & known[at] if len(keys) else np.zeros(len(asked), bool)
    draw = (_request_key(wi, address, seed=gpu.sample.seed + 1) >> np.uint64(11)).astype(np.float64) / 2.0 ** 53
    out = np.where(draw < dirty[at], MISS_DIRTY, np.where(draw < miss[at], MISS, HIT)) if len(keys) else \
        np.full(len(asked), -1)
    again = np.ones(len(asked), bool)           # a request's repeat (a ROP's write after its read) finds the line
    again[np.unique(asked, return_index=True)[1]] = False
    return np.where(known_request, np.where(again, HIT, out), -1)
