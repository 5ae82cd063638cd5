"""The ``analytic`` fidelity level: cycle bounds from operation counts and unit throughputs.

Works on the scheme's OpPlan groups ("these threads issue ``count`` operations
``op`` on ``structure``"), never expanding the OpStream, so it costs
O(threads) where the event model costs O(operations). Per pass it takes the
largest of

* issue: warp instructions (per warp, the most operations any of its lanes
  issues in the group, so divergence counts) x issue cycles, plus ALU work
  (compute groups: the busiest lane's instructions per warp), over the SMs;
* latency: each lane's dependent chain (an operation that waits for a result
  adds that unit's round trip), the slowest warp, or the SM's warps' chains
  divided by the resident warps that hide each other;
* dram: requests (lanes of a warp on one ``coalescer.segment_bytes`` segment, as
  at the first operation of each lane, measured on up to 4,096 warps spread
  evenly over the group) x bytes, over all channels;
* atomic: operations over all atomic units, and the hottest address
  (operations on one word serialize at ``same_address_cycles``);
* rop: ROP service cycles of the busiest unit;
* raster: every triangle through the fixed-function front end's slowest
  stage, or its quads through the rasterizer (graphics-pipeline geometry
  passes, whose issue bound counts the helper lanes of 2x2 quads); a software
  rasterizer's vertex loads, setup and bounding-box scan on the SMs (triangle
  mapping, in the issue and dram bounds);

plus one round trip of the slowest unit the pass uses and the driver's
``driver.pass_us``. Imbalance across
partitions beyond the hottest address, queueing and L2 hits are not modelled
(the L2, when present, is assumed to catch re-use: DRAM bytes are those of the
first touch). These are estimates: ``gpusim`` reports them beside the full
model in the fidelity report.
"""

from __future__ import annotations

import numpy as np

from gpusim.hw.collector import collector_paused
from gpusim.hw.core import SimtCore, flush_cycles
from gpusim.hw.driver import pass_overhead_cycles
from gpusim.hw.lower import PRODUCES, scoreboard_warps, submitted_triangles, thread_mapping
from gpusim.hw.memory import SECTOR
from gpusim.hw.raster import INDEX_BYTES, bbox_pixels, distinct_quads, per_triangle_cycles
from gpusim.hw.scoreboard import scoreboard_cell
from gpusim.hw.unit import address_ids, entry_unit, interleave
from gpusim.metrics.composite import run_starts
from gpusim.hw.pass_schedule import TERMS, Schedule, interpolated, pass_families
from gpusim.hw.placement import Aranges, StillIssuing, count_key, group_passes, thread_ids_of
from gpusim.opplan import ThreadRange

# the units an operation goes to from the core (analytic estimates report memory traffic as DRAM's)
MEM, ATOMIC, ROP, SCOREBOARD = "coalescer", "atomic", "rop", "scoreboard"


def _lane_keys(parts: list) -> np.ndarray:
    """The sorted distinct lane keys of a pass from each group's (sorted, distinct) keys: the first when every
    group runs on the same threads, as a pass's groups usually do, else their union (a mask, no sort)."""
    if not parts:
        return np.zeros(0, np.int64)
    first = parts[0]
    if all(p is first or (len(p) == len(first) and np.array_equal(p, first)) for p in parts[1:]):
        return first
    lo, hi = min(int(p[0]) for p in parts if len(p)), max(int(p[-1]) for p in parts if len(p))
    whole = next((p for p in parts if len(p) == hi + 1 - lo), None)     # one group on every key of the range
    return whole if whole is not None else _union(parts)


def _union(parts: list) -> np.ndarray:
    """The sorted distinct values of integer arrays: a mask over their range, no sort (numpy's hashing
    ``unique`` takes seconds on tens of millions of fragments)."""
    parts = [p for p in parts if len(p)]
    if not parts:
        return np.zeros(0, np.int64)
    lo = min(int(p.min()) for p in parts)
    mask = np.zeros(max(int(p.max()) for p in parts) + 1 - lo, bool)
    for p in parts:
        mask[p - lo] = True
    return np.flatnonzero(mask) + lo


WHOLE_GROUPS = 2      # lane information of whole groups kept from pass to pass (depth peeling's every-pass loads)


class _QuadMemo:
    """Quads of a pass's fragments, computed once per distinct set of fragments (depth peeling's thousands of
    passes run over the same ones)."""

    def __init__(self):
        self.seen: dict[tuple, int] = {}
        self.last: tuple = (None, 0)

    def quads(self, keys: np.ndarray, work) -> int:
        if keys is self.last[0]:               # the same lanes' keys as the pass before
            return self.last[1]
        self.last = (keys, self._quads(keys, work))
        return self.last[1]

    def _quads(self, keys: np.ndarray, work) -> int:
        fingerprint = (len(keys), int(keys[0]), int(keys[-1]), int(keys.sum()), int((keys * keys).sum()))
        got = self.seen.get(fingerprint)
        if got is None:
            got = self.seen[fingerprint] = distinct_quads(work.frag_prim[keys], work.frag_pixel[keys], work.width,
                                                          work.height)
        return got


def _distinct(a: np.ndarray) -> int:
    """How many distinct values (no sort when ``a`` is already sorted, as a warp's lanes usually are)."""
    if len(a) > 1 and not (a[1:] >= a[:-1]).all():
        a = np.sort(a)
    return int(np.count_nonzero(a[1:] != a[:-1])) + 1 if len(a) else 0


def _hottest(addr: np.ndarray) -> int:
    """Most operations on one address."""
    ops = address_ids(addr)[1]
    return int(ops.max()) if len(ops) else 0


def _warp_max(values: np.ndarray, ws: int) -> np.ndarray:
    """Per warp of ``ws`` consecutive lanes, the largest value."""
    full = len(values) - len(values) % ws
    head = np.maximum.reduceat(values[:full], np.arange(0, full, ws)) if full else values[:0]
    if full == len(values):
        return head
    return np.append(head, max(values[full:].max(), values.dtype.type(0)))    # a partial warp, padded with 0


class _Packing:
    """How a pass's lanes fill warps: ``ws`` consecutive lanes a warp, or (a pass behind the scoreboard)
    as dispatch packs them, no two fragments of one cell in a warp (gpusim.hw.lower)."""

    def __init__(self, ws: int, keys: np.ndarray | None = None, warp: np.ndarray | None = None):
        self.ws, self.keys, self.warp = ws, keys, warp

    def runs(self, keys: np.ndarray) -> np.ndarray:
        """Start of each warp's run in ``keys`` (ascending lane keys of the pass)."""
        if self.warp is None:
            return np.arange(0, len(keys), self.ws)
        return run_starts(self.warp[np.searchsorted(self.keys, keys)])

    def warp_max(self, values: np.ndarray, keys: np.ndarray) -> np.ndarray:
        """Per warp, the largest of its lanes' ``values`` (one per key of ``keys``)."""
        if self.warp is None:
            return _warp_max(values, self.ws)
        return np.maximum.reduceat(values, self.runs(keys)) if len(values) else values

    def warp_rank(self, keys: np.ndarray, of: np.ndarray) -> np.ndarray:
        """The warp (its rank among the warps of ``keys``) of each key in ``of``."""
        pos = np.searchsorted(keys, of)
        if self.warp is None:
            return pos // self.ws
        starts = np.zeros(len(keys), np.int64)
        starts[self.runs(keys)] = 1
        return (np.cumsum(starts) - 1)[pos]


def _warp_sample(lanes: np.ndarray, ws: int, warps: int = 4096) -> np.ndarray:
    """The lanes of at most ``warps`` warps spread evenly over ``lanes`` (all of them when fewer)."""
    n_warps = -(-len(lanes) // ws)
    if n_warps <= warps:
        return lanes
    first = np.linspace(0, n_warps - 1, warps).astype(np.int64) * ws
    idx = (first[:, None] + np.arange(ws)).ravel()
    return lanes[idx[idx < len(lanes)]]


def _pass_packing(plan, groups: list[int], placement, p: int, work, gpu) -> _Packing:
    """Consecutive lanes, or the scoreboard dispatch's packing when a group of the pass goes through it: of every
    lane of the pass, as gpusim.hw.lower packs them (a multi-pass k-buffer's peel test runs on fragments that do
    not reach the scoreboard)."""
    if not any(plan.groups[gi].op == "scoreboard" for gi in groups):
        return _Packing(gpu.core.warp_size)
    lanes = []
    for gi in groups:
        sel = placement[gi][2][p]
        sel = sel() if isinstance(sel, StillIssuing) else sel
        threads = plan.groups[gi].thread_ids()
        lanes.append(threads if sel is None else threads[placement[gi][0][sel]])
    keys = np.unique(np.concatenate(lanes))
    return _Packing(gpu.core.warp_size, keys, scoreboard_warps(work.frag_pixel[keys], work.width, gpu))


def _scoreboard_bound(held: list, keys: np.ndarray, wchain: np.ndarray, packing: "_Packing",
                      entries: int) -> float:
    """The scoreboard's serialisation: a warp holds its fragments' cells for its whole latency chain, so the
    fragments of one cell run one warp after another (the busiest cell's sum of its warps' chains), and
    the warps in flight hold at most ``entries`` cells at once (cell-cycles held over the entries)."""
    worst = 0.0
    for held_keys, cells in held:
        warp = packing.warp_rank(keys, held_keys)
        worst = max(worst, float(np.bincount(cells, weights=wchain[warp]).max(initial=0.0)))
        pairs = np.unique(warp * (int(cells.max(initial=0)) + 1) + cells)      # (warp, cell) held
        worst = max(worst, float(wchain[pairs // (int(cells.max(initial=0)) + 1)].sum()) / entries)
    return worst


def _take(values: np.ndarray, idx) -> np.ndarray:
    """``values[idx]``, a broadcast again when ``values`` is one (one value for every thread)."""
    if len(values) > 1 and values.strides[0] == 0:
        return np.broadcast_to(values[:1], (len(idx),))
    return values[idx]


def _uniform(counts: np.ndarray) -> tuple[int, bool]:
    """The first count, and whether every count equals it (no pass over a broadcast)."""
    if not len(counts):
        return 0, False
    c0 = int(counts[0])
    return c0, (counts.strides[0] == 0 or int(counts.min()) == c0 == int(counts.max()))


def _chain_on_lanes(adds: list, nested: dict):
    """Each lane's dependent chain on the sorted keys of the pass's largest group, when every other group's
    lanes are among them: (keys, cycles per key), adding each group's cycles in program order as
    :func:`_chain_on_range` does (so the same sums), without an array over the key range; None otherwise."""
    top = max(adds, key=lambda a: len(a[0][6]))
    k0 = top[0][6]
    k_lo, k_hi = int(k0[0]), int(k0[-1])
    contiguous = k_hi - k_lo + 1 == len(k0)
    start = np.float64(0.0)                  # the groups on every lane first: a number (the same sums)
    lead = 0
    for got, add, _ in adds:
        if not ((got is top[0] or got[6] is k0) and np.ndim(add) == 0):
            break
        start, lead = start + add, lead + 1
    vals = np.full(len(k0), start)
    mask = rel = None
    for got, add, how in adds[lead:]:
        keys = got[6]
        if got is top[0] or keys is k0:
            vals += add
            continue
        if not len(keys) or int(keys[0]) < k_lo or int(keys[-1]) > k_hi:
            return None
        if contiguous:
            pos = keys - k_lo
        elif how is not None and top[2] is not None and how[0] is top[2][0]:
            # both a seq_pass group's threads still issuing, on the same threads: this one's among the top's
            made = nested.get(count_key(how[1]))
            among = made[3] if made is not None and made[1] is how[3] and made[2] is top[2][3] else \
                how[1][top[2][3]] > how[2]
            if np.ndim(add) == 0:
                if np.count_nonzero(among) != len(keys):
                    return None
                np.add(vals, add, out=vals, where=among)     # only there: the same sums, no positions
                continue
            pos = np.flatnonzero(among)
            if len(pos) != len(keys):
                return None
        elif 32 * len(keys) < len(k0):
            pos = np.searchsorted(k0, keys)
            if not (k0[pos] == keys).all():
                return None
        else:
            if mask is None:
                mask, rel = np.zeros(k_hi - k_lo + 1, bool), k0 - k_lo
            mask[keys - k_lo] = True
            pos = np.flatnonzero(mask[rel])
            mask[keys - k_lo] = False
            if len(pos) != len(keys):
                return None
        vals[pos] += add
    if all(np.ndim(a) == 0 for _, a, _ in adds) and np.ndim(top[1]) == 0 and top[1] > 0 and \
            all(a >= 0 for _, a, _ in adds):
        return k0, vals                        # every lane's chain is positive
    nz = vals > 0
    return (k0, vals) if nz.all() else (k0[nz], vals[nz])


def _chain_on_range(adds: list):
    """Each lane's dependent chain on an array over the key range: (keys with a chain, their cycles)."""
    chain = None
    positions: dict = {}                  # present lanes' positions in the chain array
    for got, add, _ in adds:
        lanes, lo, size, threads_in, present, warp_threads, keys, distinct = got
        if present is None:
            present = lanes - lo
        base, have = chain if chain is not None else (lo, np.zeros(0))
        if lo < base or lo + size > base + len(have):
            new_base = min(base, lo)
            grown = np.zeros(max(base + len(have), lo + size) - new_base)
            grown[base - new_base:base - new_base + len(have)] = have
            base, have = new_base, grown
            chain = (base, have)
        if len(present) == size:            # every key of the range
            have[lo - base:lo - base + size] += add
        else:                               # (groups on the same lanes share the positions)
            held_at = positions.get((id(got), lo - base))
            if held_at is None or held_at[0] is not got:
                held_at = positions[id(got), lo - base] = (got, present + (lo - base))
            have[held_at[1]] += add
    present = np.flatnonzero(chain[1] > 0)        # every lane issues, so a present lane has a chain
    return chain[0] + present, chain[1][present]


class _PassTimer:
    """Times one pass at a time on the per-unit bounds, keeping what passes over the same threads share (lane
    information, thread sets, quads); the per-pass figures (warp instructions, ALU cycles, DRAM bytes, atomic
    operations, the hottest address, ROP service per unit, the units used) go into arrays over the passes."""

    def __init__(self, result, work, gpu):
        self.result, self.work, self.gpu = result, work, gpu
        plan = self.plan = result.plan
        self.bases = result.bases()
        m = gpu.memory
        icn = m.interconnect_latency
        self.lat = {MEM: 2 * icn + gpu.dram.latency + (gpu.l2.latency if gpu.l2.size_bytes else 0),
                    ATOMIC: 2 * icn + gpu.atomic.latency, ROP: 2 * icn + gpu.rop.latency, SCOREBOARD: 0}
        n_pass = len(plan.passes)
        self.wis = np.zeros(n_pass)
        self.alu = np.zeros(n_pass)               # issue cycles of ALU work (compute groups)
        self.dram_bytes = np.zeros(n_pass)
        self.atomic_ops = np.zeros(n_pass)
        self.hottest = np.zeros(n_pass)
        self.rop_unit = np.zeros((n_pass, gpu.rop.units))
        self.used: list[set] = [set() for _ in range(n_pass)]
        # where each group's operations fall: per pass, the threads (None: all) issuing them
        aranges = Aranges(max((len(g.thread) for g in plan.groups), default=0))
        counted: dict = {}
        self.placement = [group_passes(g, aranges, counted) for g in plan.groups]
        self.ids = thread_ids_of(plan, aranges)
        self.groups_of_pass: list[list[int]] = [[] for _ in range(n_pass)]
        for gi, (_, _, where) in enumerate(self.placement):
            for p in where:
                self.groups_of_pass[p].append(gi)
        self.overhead = pass_overhead_cycles(gpu)      # the driver issues each pass
        self.quad_memo = _QuadMemo()           # passes over the same fragments (depth peeling's) share their quads
        self.whole_groups: list = []           # the last groups met whole: (threads, triangle mapping, lane info)
        self.nested: dict = {}                 # each count array's threads still issuing, as the last pass had them
        self.last_still: list = []             # the threads still issuing of the last pass timed
        self.sel_lanes: dict = {}              # the last pass's lane info of threads still issuing, by their set
        self.ascending: dict = {}              # group -> whether its thread ids ascend
        self.units_of: dict = {}               # ROP group -> the unit of each of its threads' first address

    def per_pass(self) -> tuple:
        return self.wis, self.alu, self.dram_bytes, self.atomic_ops, self.hottest, self.rop_unit

    def time(self, p: int) -> dict:
        """Pass ``p``'s record (name, kind, cycles, warps, the bound that decided it), its figures in the arrays."""
        plan, bases, work, gpu = self.plan, self.bases, self.work, self.gpu
        c, m = gpu.core, gpu.memory
        ws, cost = c.warp_size, c.op_issue_cycles
        alu_cost = c.issue_cycles / c.alu_issue_width   # an ALU instruction of a warp (alu_issue_width a lane-cycle)
        segment = gpu.coalescer.segment_bytes
        lat, overhead, placement, ids = self.lat, self.overhead, self.placement, self.ids
        groups_of_pass, quad_memo, nested = self.groups_of_pass, self.quad_memo, self.nested
        wis, alu, dram_bytes, atomic_ops, hottest, rop_unit = self.per_pass()
        used, ascending, units_of = self.used, self.ascending, self.units_of
        last_still, sel_lanes = self.last_still, self.sel_lanes
        pk = plan.passes[p]
        if pk.kind == "flush":
            return {"name": pk.name, "kind": pk.kind, "bound": "flush", "warps": 0,
                    "cycles": flush_cycles(c, -(-work.width * work.height // ws)) + overhead}
        last_producer, waited = None, False
        adds: list = []                       # each group's lane info, dependent-chain cycles per lane, threads
        pass_keys: list = []                  # the lane keys of each group in the pass
        held: list = []                       # scoreboard groups: (lane keys, cell of each)
        packing = _pass_packing(plan, groups_of_pass[p], placement, p, work, gpu)
        still: dict = {}                      # the threads still issuing, by count array and op
        made_lanes: dict = {}                 # their lane info, by set (sel_lanes of the next pass)
        lane_cache: list = []                 # [(threads, (lanes, first key, key range, threads per present
                                              #   lane, present lanes from the first, warp max, lane keys,
                                              #   whether each lane runs one thread))]
        triangles = thread_mapping(gpu, pk) == "triangle"
        if packing.warp is None:              # a whole group's lanes, as the last passes over it had them
            lane_cache = [(th, None, v) for th, tri, v in self.whole_groups if tri == triangles]
        for gi in groups_of_pass[p]:          # in program order
            g = plan.groups[gi]
            li, cnt, where = placement[gi]
            sel = where[p]
            memo = issuing = None
            if isinstance(sel, StillIssuing):   # groups over one count array (views of it) share the threads
                issuing = sel
                memo = (*count_key(sel.count), sel.s)
                sel = still[memo] if memo in still else still.setdefault(memo, sel(nested, [*still.values(),
                                                                                               *last_still]))
            n = len(g.thread)
            thread = ids[gi]
            if gi not in ascending:
                ascending[gi] = isinstance(g.thread, ThreadRange) or len(thread) < 2 or \
                    bool((thread[1:] > thread[:-1]).all())
            # lanes in ascending order, one thread each, known without a pass over them: all of the group's, or
            # a seq_pass group's threads still issuing (lanes 0..n-1 of its, picked in order)
            known = not triangles and ascending[gi] and (sel is None or issuing is not None)
            compute = g.is_compute
            cls, produces = (None, False) if compute else (entry_unit(g.op), g.op in PRODUCES)
            nb = g.bytes if not callable(g.bytes) else None
            if sel is None:
                lanes_sel, counts = li, cnt
            elif g.seq_pass is not None:          # lanes 0..n-1, an operation each (group_passes)
                lanes_sel, counts = sel, cnt[:len(sel)]
            else:
                lanes_sel, counts = li[sel], _take(cnt, sel)
            if compute:                       # ALU work: its instructions stand for the operation count
                counts = _take(np.asarray(g.instructions), lanes_sel)
            else:
                used[p].add(cls)
            # per lane: the group's threads it runs (several fragments of one triangle); groups of one pass on
            # the same threads (a thread's successive operations) share it
            # (whole groups, or seq_pass groups' threads still issuing, which are lanes 0..n-1 of theirs)
            cached = lane_cache if sel is None or memo is not None else []
            got = next((v for th, key, v in cached
                        if key == memo and (th is thread or (len(th) == n and np.array_equal(th, thread)))), None)
            if got is None and memo is not None and packing.warp is None:    # the same set in the last pass
                was = sel_lanes.get(id(sel))
                if was is not None and was[0] is sel and was[1] is thread and was[2] == triangles:
                    got = was[3]
                    cached.append((thread, memo, got))
            if got is None:
                lanes = thread if sel is None else thread[lanes_sel]
                if triangles:
                    lanes = work.frag_prim[lanes]
                # the lanes present (offsets from lo, ascending; None: lanes - lo) and the threads each runs (None:
                # one each): a thread per lane when the threads are ascending lanes (a fragment or pixel each), no
                # pass over the whole key range
                distinct = known or len(lanes) < 2 or bool((lanes[1:] > lanes[:-1]).all())
                if distinct:
                    lo = int(lanes[0])          # lane keys from lo (a batch's fragments are a slice of them)
                    size = int(lanes[-1]) + 1 - lo
                    present, threads_in, keys = None, None, lanes
                    warp_threads = -(-len(lanes) // ws) if packing.warp is None else \
                        packing.warp_max(np.ones(len(lanes), np.int64), keys).sum()
                else:
                    lo = int(lanes.min())
                    size = int(lanes.max()) + 1 - lo
                    threads_in = np.bincount(lanes - lo, minlength=size)
                    present = np.flatnonzero(threads_in)
                    threads_in, keys = threads_in[present], lo + present
                    warp_threads = packing.warp_max(threads_in, keys).sum()
                got = (lanes, lo, size, threads_in, present, warp_threads, keys, distinct)
                cached.append((thread, memo, got))
                if sel is None and packing.warp is None:
                    self.whole_groups = [(thread, triangles, got)] + self.whole_groups[:WHOLE_GROUPS - 1]
            if memo is not None and packing.warp is None:
                made_lanes[id(sel)] = (sel, thread, triangles, got)
            lanes, lo, size, threads_in, present, warp_threads, keys, distinct = got
            pass_keys.append(keys)
            c0, uniform = _uniform(counts)
            # per present lane: its operations (not needed when every lane runs one thread with the same count)
            if uniform:
                per_lane = None if threads_in is None else threads_in if c0 == 1 else threads_in * c0
            elif distinct:
                per_lane = np.asarray(counts, np.float64)
            else:
                per_lane = np.bincount(lanes - lo, weights=counts, minlength=size)[present]
            # warp instructions: lanes in order, each warp issues its busiest lane's count
            busiest = warp_threads * c0 if uniform else packing.warp_max(per_lane, keys).sum()
            if compute:
                alu[p] += busiest * alu_cost
            else:
                wis[p] += busiest
            ops = float(c0 * len(counts) if uniform else counts.sum())
            # first operation of each thread: coalescing (on a spread sample of warps) and the hottest address
            # threads with no operation in this group have no address (a list walk of zero nodes)
            live = None if not len(counts) or (c0 if uniform else int(counts.min())) > 0 else counts > 0
            lanes_live = lanes_sel if live is None else lanes_sel[live]
            counts_live = counts if live is None else counts[live]
            if not len(lanes_live) or compute:
                pass                             # no thread issues this group in this pass, or no memory
            elif cls == MEM:
                sample = _warp_sample(lanes_live, ws)
                zero = np.broadcast_to(np.zeros(1, np.int64), sample.shape)
                addr = bases[g.structure] + np.asarray(g.offset(sample, zero), np.int64)
                bytes_ = float(nb) if nb is not None else float(np.mean(g.bytes(sample, zero)))
                seg = addr // segment
                wkey = ((np.arange(len(seg)) // ws) << 36) + seg
                requests_per_lane = _distinct(wkey) / max(1, len(seg))
                req_bytes = min(max(segment, SECTOR),
                                -(-bytes_ / requests_per_lane // SECTOR) * SECTOR)
                dram_bytes[p] += ops * requests_per_lane * req_bytes
            elif cls == ROP and g.seq_pass is not None and len(placement[gi][2]) > 1:
                addr = None
            else:
                zero = np.broadcast_to(np.zeros(1, np.int64), lanes_live.shape)
                addr = bases[g.structure] + np.asarray(g.offset(lanes_live, zero), np.int64)
            if not len(lanes_live) or compute:
                pass
            elif cls == ATOMIC:
                atomic_ops[p] += ops
                hottest[p] = max(hottest[p], float(_hottest(addr)))
            elif cls == ROP:
                if addr is None:                # a group over many passes: each thread's unit, found once
                    if gi not in units_of:
                        every = np.arange(n, dtype=np.int64)
                        units_of[gi] = interleave(bases[g.structure] + np.asarray(
                            g.offset(every, np.broadcast_to(np.zeros(1, np.int64), every.shape)), np.int64),
                            m.interleave_bytes, gpu.rop.units).astype(np.min_scalar_type(gpu.rop.units))
                    unit = units_of[gi][lanes_live]
                else:
                    unit = interleave(addr, m.interleave_bytes, gpu.rop.units)
                svc = (gpu.blender.cycles_per_op + (nb or 0) / gpu.blender.bytes_per_cycle
                       if g.op == "program_blend" else 1.0 / gpu.rop.ops_per_cycle)
                rop_unit[p] += np.bincount(unit, weights=counts_live * svc, minlength=gpu.rop.units)
            elif cls == SCOREBOARD:
                keys_live = thread[lanes_live]
                held.append((keys_live, scoreboard_cell(work.frag_pixel[keys_live], work.width,
                                                        gpu.scoreboard.granularity)))
            # dependent chains per lane: every operation issues; a dependent producer waits for each result,
            # and the first dependent operation after a producer waits once per thread
            # (the same for every lane when each runs one thread with the same operations: a number)
            same = uniform and distinct
            add = (c0 if same else per_lane) * (alu_cost if compute else cost)
            lp = last_producer
            if g.dep and produces:
                add += (c0 if same else per_lane) * lat[cls]
            elif g.dep and lp is not None and not waited:
                add += (1 if same or threads_in is None else threads_in) * lat[lp]
            adds.append((got, add, (thread, issuing.count, issuing.s, sel) if known and issuing is not None
                         and g.seq_pass is not None else None))
            if produces:
                last_producer, waited = cls, False
            elif g.dep:
                waited = True
        self.last_still, self.sel_lanes = list(still.values()), made_lanes
        if not adds:
            return {"name": pk.name, "kind": pk.kind, "cycles": overhead, "warps": 0, "bound": "empty"}
        chain = _chain_on_lanes(adds, nested)
        chain_keys, lane_chain = chain if chain is not None else _chain_on_range(adds)
        del adds, chain
        wchain = packing.warp_max(lane_chain, chain_keys)
        n_warps = len(wchain)
        sm = SimtCore.place(n_warps, c.sms)
        per_sm = np.bincount(sm, weights=wchain, minlength=c.sms)
        n_sm = np.bincount(sm, minlength=c.sms)
        bounds = {
            "issue": float(np.ceil(wis[p] / min(c.sms, n_warps)) * cost + alu[p] / min(c.sms, n_warps)),
            "latency": float(max(wchain.max(), (per_sm / np.maximum(1, np.minimum(n_sm, c.warps_per_sm))).max())),
            "dram": dram_bytes[p] / (gpu.dram.bytes_per_cycle * m.partitions),
            "atomic": atomic_ops[p] / (gpu.atomic.ops_per_cycle * m.partitions),
            "atomic_address": hottest[p] * gpu.atomic.same_address_cycles,
            "rop": float(rop_unit[p].max()),
        }
        if held:
            bounds["scoreboard"] = _scoreboard_bound(held, chain_keys, wchain, packing, gpu.scoreboard.entries)
        mapping = thread_mapping(gpu, pk)
        keys = _lane_keys(pass_keys) if mapping in ("fragment", "triangle") else np.zeros(0, np.int64)
        if mapping == "fragment" and len(keys) and packing.warp is None:
            # the front end sees every triangle; the pixel shader runs 4 lanes per 2x2 quad (helper lanes)
            quads = quad_memo.quads(keys, work)
            bounds["issue"] *= max(1.0, 4 * quads / len(keys))
            bounds["raster"] = max(submitted_triangles(pk, work) * per_triangle_cycles(gpu),
                                   quads / gpu.raster.quads_per_cycle)
        elif mapping == "triangle":
            # software rasterizer: a thread per submitted triangle loads its vertices, sets up and scans its
            # bounding box; a warp lasts as long as its largest box
            tris = submitted_triangles(pk, work) if pk.primitives is None else int(keys.max()) + 1
            frags = _union([ids[i] for i in groups_of_pass[p]])
            r = gpu.raster
            box = bbox_pixels(work.frag_prim[frags], work.frag_pixel[frags], work.width, tris)
            setup = float((r.setup_instructions + r.pixel_instructions * _warp_max(box, ws)).sum()) * alu_cost
            sw_warps = -(-tris // ws)
            bounds["issue"] += (setup + 2 * sw_warps * cost) / min(c.sms, sw_warps)
            dram_bytes[p] += tris * (INDEX_BYTES + 3 * r.vertex_bytes)
            bounds["dram"] = dram_bytes[p] / (gpu.dram.bytes_per_cycle * m.partitions)
            used[p].add(MEM)
        limit = max(bounds, key=bounds.get)
        extra = max(lat[u] for u in used[p]) + overhead
        return {"name": pk.name, "kind": pk.kind, "cycles": int(np.ceil(bounds[limit])) + extra, "warps": n_warps,
                "bound": limit, TERMS: ({k: float(v) for k, v in bounds.items()}, extra)}


def analytic_timing(result, work, gpu, interpolate: bool = True) -> dict:
    """The analytic level's record of a run: per pass the bound that decided it; passes alike in their work timed
    once and counted again, or (``interpolate``) a long family's shrinking passes interpolated between timed ones
    (gpusim.hw.pass_schedule)."""
    with collector_paused():
        return _analytic_timing(result, work, gpu, interpolate)


def _analytic_timing(result, work, gpu, interpolate: bool) -> dict:
    timer = _PassTimer(result, work, gpu)
    plan, m = timer.plan, gpu.memory
    fam_of, families = pass_families(plan, timer.placement, timer.groups_of_pass, timer.bases, timer.ids)
    schedule = Schedule(families, timer.time, interpolate)
    arrays = timer.per_pass()
    used = timer.used
    passes = []
    copy_to, copy_from, mix = [], [], []        # repeats' figures are their pass's; interpolated ones between two
    for p, pk in enumerate(plan.passes):
        if fam_of[p] < 0:
            passes.append(timer.time(p))
            continue
        how = schedule.how[p]
        if how[0] == "timed":
            passes.append(schedule.records[p])
        elif how[0] == "repeat":
            q = how[1]
            copy_to.append(p)
            copy_from.append(q)
            used[p] = used[q]
            passes.append(schedule.records[q] | {"name": pk.name, "repeat_of": q})
        else:
            _, a, b, w = how
            mix.append((p, a, b, w))
            used[p] = used[a] | used[b]
            passes.append(interpolated(schedule.records[a], schedule.records[b], a, b, w) | {"name": pk.name})
    for arr in arrays:
        arr[copy_to] = arr[copy_from]
        for p, a, b, w in mix:
            arr[p] = arr[a] + w * (arr[b] - arr[a])
    for x in passes:
        x.pop(TERMS, None)
    total = sum(x["cycles"] for x in passes)
    wis, _, dram_bytes, atomic_ops, _, rop_unit = arrays
    every = set().union(*used)
    units_built = [name for name, cls in (("dram", MEM), ("atomic", ATOMIC), ("rop", ROP), ("scoreboard", SCOREBOARD))
                   if cls in every]
    busy = {"dram": dram_bytes.sum() / gpu.dram.bytes_per_cycle, "atomic": atomic_ops.sum() / gpu.atomic.ops_per_cycle,
            "rop": rop_unit.sum()}
    inst = {"dram": m.partitions, "atomic": m.partitions, "rop": gpu.rop.units}
    units = {u: {"busy_cycles": float(busy[u]), "utilisation_mean": float(busy[u]) / (total * inst[u]) if total else 0.0}
             for u in units_built if u in busy}
    return {"fidelity": "analytic", "gpu": gpu.name, "instructions": int(wis.sum()),
            "operations": int(plan.total_ops()), "passes": passes, "units_built": units_built, "units": units,
            "rmw_hazards": None, "total": int(total),
            "repeated_passes": sum("repeat_of" in x for x in passes),
            "interpolated_passes": sum("interpolated" in x for x in passes)}
