"""The ``analytic`` fidelity level: cycle bounds from operation counts and unit throughputs.

Works on the scheme's OpPlan groups ("these threads issue ``count`` operations
``op`` on ``structure``"), never expanding the OpStream, so it costs
O(threads) where the event model costs O(operations). Per pass it takes the
largest of

* issue: warp instructions (per warp, the most operations any of its lanes
  issues in the group, so divergence counts) x issue cycles, plus ALU work
  (compute groups: the busiest lane's instructions per warp), on the busiest SM
  (warps dealt round the SMs). The warps are the pass's as lowering packs its
  lanes: a pixel shader's fragments spread over the warps of their 2x2 quads'
  lanes (helper lanes; with raster.warp_packing = "tiles", warps of quads of
  one owner's tiles), warps of consecutive triangles for a software
  rasterizer, the scoreboard's dispatch; a group on some of the lanes issues in
  every warp that holds one of them;
* latency: each lane's dependent chain (an operation that waits for a result
  adds that unit's round trip; a memory operation also its warp instruction's
  requests on its busiest partition, served back to back; an atomic one its
  instruction's operations on its busiest word, ``same_address_cycles`` apart),
  the slowest warp, or the SM's warps' chains divided by the resident warps that
  hide each other; a triangle thread's warp (software rasterizer) first loads
  its triangles' indices, then vertices, and runs the setup and its largest
  bounding box's scan, then each iteration of its threads' loops: each group
  of the loop's body as often as the lane that issues it most, a dependent
  operation waiting once for the warp's last result (SIMT: :class:`_SimtLoop`);
* dram: requests as the coalescer makes them (one per warp instruction and
  ``coalescer.segment_bytes`` segment its lanes touch, of their bytes there in
  whole sectors), measured on every operation of the lanes of a sample of warps
  in runs spread over the group, x bytes, over all channels; with an L2, only
  its misses (and the dirty lines they evict); the ROPs' framebuffer reads and
  writes coalesce the same way (gpusim.hw.rop: a read and a write of each
  sector, the write a hit in the L2 where there is one);
* l2: with an L2, every request's bytes through the slices (see
  :class:`_L2Model` for its hits);
* atomic: operations over all atomic units, and the hottest address
  (operations on one word serialize at ``same_address_cycles``);
* rop: ROP service cycles of the busiest unit;
* raster: every triangle through the fixed-function front end's slowest
  stage, or its quads through the rasterizer (graphics-pipeline geometry
  passes, whose issue bound counts the helper lanes of 2x2 quads); a software
  rasterizer's vertex loads, setup and bounding-box scan on the SMs (triangle
  mapping, in the issue and dram bounds);
* phases: in a pass of thread lanes whose warps are all resident at once (they
  start together), the warps go through the groups in step, so each group's
  units do not overlap the next's: the sum over groups of each group's
  busiest unit (an SM's issue port, the DRAM, the L2, the atomic units, the
  busiest ROP);
* front_end: in a pixel shader's pass, a warp starts once the front end has its
  fragments out, so each unit (an SM's issue port, the DRAM, the L2, the atomic
  units, the busiest ROP) serves a warp's work only after that: when such a
  queue fed in warp order is done (:func:`_fed`) where the unit falls behind the
  front end (otherwise the last warps' work and chains after the front end are
  the raster bound's tail);

plus one round trip of the slowest unit the pass uses (a memory request's at
the pass's L2 miss ratio) and the driver's ``driver.pass_us``. Imbalance across
partitions beyond the hottest address and queueing are not modelled. These are
estimates: ``gpusim`` reports them beside the full model in the fidelity report.
"""

from __future__ import annotations

import numpy as np

from gpusim.hw.atomic import DRAM_RMW_BYTES
from gpusim.hw.collector import collector_paused
from gpusim.hw.core import SimtCore, flush_cycles
from gpusim.hw.driver import pass_overhead_cycles
from gpusim.hw.lower import (PRODUCES, _quads_so_far, _raster_positions, fragment_warps, scoreboard_warps,
                             submitted_triangles, thread_mapping)
from gpusim.hw.memory import SECTOR
from gpusim.hw.memory.coalescer import WRITE_OPS, touched_segments
from gpusim.hw.raster import INDEX_BYTES, bbox_pixels, per_triangle_cycles
from gpusim.hw.rop import framebuffer_traffic
from gpusim.hw.scoreboard import scoreboard_cell
from gpusim.hw.unit import address_ids, entry_unit, interleave
from gpusim.metrics.composite import run_starts
from gpusim.schemes.common.arrays import rank_in_runs
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
    """Quads of a pass's fragments: the count computed once per distinct set of fragments (depth peeling's
    thousands of passes run over the same ones), the per-lane running count kept for the last set."""

    def __init__(self):
        self.seen: dict[tuple, int] = {}
        self.last: tuple = (None, None)
        self.packed: tuple = (None, None)

    def quads(self, keys: np.ndarray, work) -> int:
        """How many 2x2 quads the lanes ``keys`` fill."""
        fingerprint = (len(keys), int(keys[0]), int(keys[-1]), int(keys.sum()), int((keys * keys).sum()))
        if fingerprint not in self.seen:
            self.seen[fingerprint] = int(self.so_far(keys, work)[-1])
        return self.seen[fingerprint]

    def warps(self, keys: np.ndarray, work, gpu) -> tuple[np.ndarray, np.ndarray]:
        """Per lane key (ascending): its warp as lowering packs a pixel shader's fragments (quads of one
        owner's tiles, gpusim.hw.lower's ``fragment_warps``), and the quads emitted by the time its own is."""
        fingerprint = (len(keys), int(keys[0]), int(keys[-1]), int(keys.sum()))
        if self.packed[0] != fingerprint:
            self.packed = (fingerprint, fragment_warps(work, gpu, keys))
        return self.packed[1]

    def so_far(self, keys: np.ndarray, work) -> np.ndarray:
        """Per lane: the quads emitted by the time its own is (gpusim.hw.lower's ``_quads_so_far``)."""
        if keys is not self.last[0]:
            self.last = (keys, _quads_so_far(work, keys))
        return self.last[1]


def _distinct(a: np.ndarray) -> int:
    """How many distinct values (no sort when ``a`` is already sorted, as a warp's lanes usually are)."""
    if len(a) > 1 and not (a[1:] >= a[:-1]).all():
        a = np.sort(a)
    return int(np.count_nonzero(a[1:] != a[:-1])) + 1 if len(a) else 0


def _as_slice(idx: np.ndarray):
    """``idx`` as a slice when it is a run of consecutive integers (a view, no gather), else ``idx``."""
    if len(idx) and int(idx[-1]) - int(idx[0]) + 1 == len(idx) and (len(idx) < 2 or (
            idx.strides[0] != 0 and bool((idx[1:] > idx[:-1]).all()))):
        return slice(int(idx[0]), int(idx[-1]) + 1)
    return idx


def _covering(parts: list) -> np.ndarray:
    """The sorted distinct values of the thread arrays ``parts``: one of them when it is a run that holds every
    other (a pass's groups over all its fragments, or some of them), else their union."""
    for q in parts:
        if isinstance(_as_slice(q), slice) and all(not len(o) or (int(o.min()) >= int(q[0]) and int(o.max()) <= int(
                q[-1])) for o in parts if o is not q):
            return q
    return _union(parts)


def _sorted_distinct(a: np.ndarray) -> np.ndarray:
    """The distinct values of ``a``, ascending (a sort: numpy's hashing ``unique`` is slower)."""
    a = np.sort(a)
    return a[np.r_[True, a[1:] != a[:-1]]] if len(a) else a


def _requests(inst: np.ndarray, addr: np.ndarray, nbytes: np.ndarray, segment: int) -> tuple[np.ndarray, np.ndarray]:
    """The coalescer's requests of accesses (warp instruction ``inst``, byte ``addr``, ``nbytes`` each): one per
    instruction and segment touched (an access over a segment boundary touches several), of the bytes its lanes
    touch there rounded up to sectors, at most the segment; (request keys ``inst << 36 | segment``, ascending, and
    their bytes; ``inst`` there its rank among the instructions when the numbers need more than 27 bits)."""
    seg = addr // segment
    span = (addr + nbytes - 1) // segment - seg + 1
    cross = np.flatnonzero(span > 1)
    if len(cross) and int(span[cross].max()) == 2:   # one boundary at most: a second piece where it is crossed
        cut = (seg[cross] + 1) * segment
        first = nbytes.copy()
        first[cross] = cut - addr[cross]
        inst = np.concatenate((inst, inst[cross]))
        seg = np.concatenate((seg, seg[cross] + 1))
        nbytes = np.concatenate((first, addr[cross] + nbytes[cross] - cut))
    elif len(cross):
        _, seg = touched_segments(addr, nbytes, segment)
        inst, addr, nbytes = np.repeat(inst, span), np.repeat(addr, span), np.repeat(nbytes, span)
        nbytes = np.minimum(addr + nbytes, (seg + 1) * segment) - np.maximum(addr, seg * segment)
    key, _ = _instruction_keys(inst, seg)
    same = len(nbytes) > 0 and not (nbytes != nbytes[0]).any()    # every access the same size: counts suffice
    if len(key) > 1 and not (key[1:] >= key[:-1]).all():
        if same:           # stable: numpy's radix/timsort, faster on the runs of ascending keys lanes give
            key = np.sort(key, kind="stable")
        else:
            order = np.argsort(key, kind="stable")
            key, nbytes = key[order], nbytes[order]
    starts = run_starts(key)
    if same:
        touched = np.diff(np.append(starts, len(key))) * nbytes[0]
    else:
        touched = np.add.reduceat(nbytes, starts) if len(key) else nbytes
    return key[starts], np.minimum(-(-touched // SECTOR) * SECTOR, max(segment, SECTOR))


def _instruction_keys(inst: np.ndarray, low: np.ndarray) -> tuple[np.ndarray, np.ndarray | None]:
    """Keys ``inst << 36 | low`` that order operations by (warp instruction, ``low``: a segment or word, below 2**36),
    and the instructions to map their high bits back to: None where the instructions fit 27 bits, else their
    distinct values, the keys holding each one's rank among them (in order)."""
    if len(inst) and int(inst.max()) >= (1 << 27):
        distinct, rank = np.unique(inst, return_inverse=True)
        return (rank.reshape(inst.shape).astype(np.int64) << 36) + low, distinct
    return (inst << 36) + low, None


def _busiest_port(per_warp: np.ndarray, c) -> float:
    """The issue cycles of the busiest scheduler port, ``per_warp[w]`` each warp's (on SM ``w % sms``,
    :meth:`SimtCore.place`). Where every SM holds all its warps at once (at most ``warps_per_sm``), warp ``w``
    keeps slot ``w // sms`` and so port ``slot % schedulers`` (gpusim.hw.core); more warps than slots take the
    slots as they free, spreading over the ports, so an SM's issue is shared by its schedulers evenly."""
    n = len(per_warp)
    sm = SimtCore.place(n, c.sms)
    if c.schedulers > 1 and n <= c.sms * c.warps_per_sm:
        port = sm * c.schedulers + (np.arange(n) // c.sms) % c.schedulers
        return float(np.bincount(port, weights=per_warp, minlength=c.sms * c.schedulers).max(initial=0.0))
    return float(np.bincount(sm, weights=per_warp, minlength=c.sms).max(initial=0.0)) / c.schedulers


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
    """How a pass's lanes fill warps: ``ws`` consecutive lanes a warp, or (a pass behind the scoreboard) as
    dispatch packs them, no two fragments of one cell in a warp (gpusim.hw.lower): ``warp`` of each of ``keys``."""

    def __init__(self, ws: int, keys: np.ndarray | None = None, warp: np.ndarray | None = None):
        self.ws, self.keys, self.warp = ws, keys, warp


SEG_MASK = (1 << 36) - 1  # a request key's segment (below its warp instruction)
OP_SAMPLE = 1 << 17      # operations a memory group's coalescing and L2 sample holds at most (about; half without an L2)


def _op_sample(lanes: np.ndarray, counts: np.ndarray, ws: int, every: bool, wide: bool) -> tuple:
    """A spread sample of a group's operations: (thread index, operation number, the position of its lane in
    ``lanes``) of the first operation of the lanes of at most 2,048 warps, or (``every``) of all the operations of the
    lanes of as many warps as hold about :data:`OP_SAMPLE` of them (16 at least); the warps in
    :data:`SAMPLE_BLOCKS` runs of consecutive warps spread evenly over ``lanes`` (a run keeps the re-use of lines
    between neighbouring warps). ``wide``: twice the warps and operations (an L2's reuse distances need them; the
    coalescer's requests do not)."""
    n = len(lanes)
    c0, uniform = _uniform(counts)
    most = 4096 if wide else 2048
    if not every or (uniform and c0 <= 1):
        pos = _warp_positions(n, ws, most)
        return lanes[pos], np.broadcast_to(np.zeros(1, np.int64), pos.shape), pos
    mean = -(-int(counts.sum()) // max(1, n))
    pos = _warp_positions(n, ws, int(np.clip(most * OP_SAMPLE // (4096 * ws * max(1, mean)), 16, most)))
    c = np.asarray(_take(counts, pos), np.int64)
    rank = np.repeat(np.arange(len(pos)), c)
    first = np.cumsum(c) - c
    return lanes[pos][rank], np.arange(len(rank), dtype=np.int64) - first[rank], pos[rank]


SAMPLE_BLOCKS = 16       # runs of consecutive warps a group's sample is taken in


def _loop_instructions(tri: np.ndarray, ws: int) -> tuple[np.ndarray, int]:
    """The warp instruction of each fragment of triangle threads (``tri``: each fragment's triangle), numbered
    warp ``tri // ws`` times the iterations plus the iteration (the fragment's rank among its triangle's, in
    thread order); and the iterations."""
    if len(tri) > 1 and not (tri[1:] >= tri[:-1]).all():
        order = np.argsort(tri, kind="stable")
        j = np.empty(len(tri), np.int64)
        j[order] = rank_in_runs(tri[order])
    else:
        j = rank_in_runs(tri)
    iterations = int(j.max(initial=0)) + 1
    return (tri // ws) * iterations + j, iterations


class _SimtLoop:
    """Triangle threads' loops over their fragments (a software rasterizer), per warp: SIMT, a warp runs
    iteration ``j`` of its threads' loops on its lanes' ``j``-th fragments together. Each group of the loop's
    body issues as many times as the lane that issues it most (the others idle), and a dependent operation
    after a producer waits once for the warp's last result, whichever lane's it is. So an iteration lasts the
    sum over the body's groups of each group's longest lane, not its longest lane's sum: a lane whose fragment
    is dropped after 20 loads and one that finds its entry at the third and stores there take 20 loads and
    then the store's wait for the last of them (FreePipe MDTS's colour pass)."""

    def __init__(self, frags, frag_inst: np.ndarray, iterations: int, n_warps: int, dense: bool | None = None):
        """``frags``: the pass's fragments (a slice or ids); ``frag_inst``: per fragment of the trace, its warp
        instruction (:func:`_loop_instructions`), of ``n_warps`` warps of ``iterations`` each. ``dense``: index
        the iterations by the warp instructions themselves (by default where there are not many more of them
        than fragments), else rank the ones some fragment runs."""
        inst = frag_inst[frags]
        span = n_warps * iterations
        if dense is None:
            dense = span <= 8 * len(inst) + 4096
        if dense:
            self.id_of, self.n, self.warp_of = frag_inst, span, None     # per fragment: its iteration's index
        else:
            uniq, ids = np.unique(inst, return_inverse=True)
            self.n, self.warp_of = len(uniq), uniq // iterations
            self.id_of = np.zeros(len(frag_inst), np.int64)
            self.id_of[frags] = ids
        self.iterations, self.n_warps = iterations, n_warps
        self.frags = frags
        self.cycles = np.zeros(self.n)
        self._present = None

    def add(self, fr, counts, per_op: float, wait: float) -> None:
        """A group of the body on fragments ``fr`` (a slice or ids), issuing ``counts`` operations each (one
        for all, or one per fragment) of ``per_op`` cycles each, and a wait of ``wait`` cycles once per
        iteration where any of them issues."""
        whole = isinstance(fr, slice) and isinstance(self.frags, slice) and fr == self.frags
        if np.ndim(counts) == 0 and whole:                 # every lane the same count: every iteration run
            if self._present is None:
                self._present = np.bincount(self.id_of[self.frags], minlength=self.n) > 0
            most = self._present * float(counts)
        else:
            ids = self.id_of[fr]
            most = np.zeros(self.n)
            np.maximum.at(most, ids, np.broadcast_to(np.asarray(counts, np.float64), ids.shape))
        self.cycles += most * per_op
        if wait:
            self.cycles += (most > 0) * wait

    def per_warp(self) -> np.ndarray:
        """Each warp's loop cycles: the sum of its iterations'."""
        if self.warp_of is None:
            return self.cycles.reshape(self.n_warps, self.iterations).sum(axis=1)
        return np.bincount(self.warp_of, weights=self.cycles, minlength=self.n_warps)[:self.n_warps]


def _instruction_words(inst: np.ndarray, word: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The distinct (instruction, word) pairs of operations, by instruction then word: each pair's instruction, and
    the operations on it, from one sort of :func:`_instruction_keys` (a triangle thread's loop over a screen-wide
    triangle numbers its instructions past 27 bits: their ranks there)."""
    if not len(inst):
        return inst, np.zeros(0, np.int64)
    key, distinct = _instruction_keys(inst, word)
    key = np.sort(key)
    starts = run_starts(key)
    high = key[starts] >> 36
    return high if distinct is None else distinct[high], np.diff(np.append(starts, len(key)))


def _warp_waits(warp: np.ndarray, waits: np.ndarray, ws: int):
    """Per triangle, the cycles its warp's atomic instructions wait for their busiest words (``waits`` of the
    sampled instructions of warps ``warp``, summed over each warp's; a warp the sample missed waits the sampled
    warps' mean): a function of the lane keys (triangles, ``ws`` a warp)."""
    n = int(warp.max(initial=-1)) + 1
    total = np.bincount(warp, weights=waits, minlength=n)
    sampled = np.bincount(warp, minlength=n) > 0
    fill = float(total[sampled].mean()) if sampled.any() else 0.0

    def at(keys: np.ndarray) -> np.ndarray:
        w = keys // ws
        out = np.full(len(keys), fill)
        inside = w < n
        out[inside] = np.where(sampled[w[inside]], total[w[inside]], fill)
        return out
    return at


def _warp_positions(n: int, ws: int, warps: int) -> np.ndarray:
    """Positions of the lanes of at most ``warps`` warps of ``n`` lanes (all when fewer): :data:`SAMPLE_BLOCKS`
    runs of consecutive warps spread evenly."""
    n_warps = -(-n // ws)
    if n_warps <= warps:
        return np.arange(n)
    run = max(1, warps // SAMPLE_BLOCKS)
    first = np.linspace(0, n_warps - run, SAMPLE_BLOCKS).astype(np.int64)
    w = np.unique((first[:, None] + np.arange(run)).ravel())
    idx = (w[:, None] * ws + np.arange(ws)).ravel()
    return idx[idx < n]


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


def _scoreboard_bound(held: list, warp_of, wchain: np.ndarray, entries: int) -> tuple[float, float]:
    """The scoreboard's serialisation: (the busiest cell's and the entries' bound, the conflicts' bound).

    A warp holds its fragments' cells for its whole latency chain, so the fragments of one cell run one warp after
    another (the busiest cell's sum of its warps' chains), and the warps in flight hold at most ``entries`` cells
    at once (cell-cycles held over the entries). And a warp starts only once every one of its cells is free: with
    the warps waiting together, each time cells free the first waiting warps whose cells are all free start (in
    submission order, a warp first whose cells no earlier starting warp takes), so the warps start in rounds (the
    lexicographically first independent sets of the conflict graph, :func:`_conflict_rounds`); a warp ends its
    chain after the last warp before it on each of its cells ended (the longest such path)."""
    worst = conflicts = 0.0
    for held_keys, cells in held:
        warp = warp_of(held_keys)
        worst = max(worst, float(np.bincount(cells, weights=wchain[warp]).max(initial=0.0)))
        span = int(cells.max(initial=0)) + 1
        pairs = _sorted_distinct(warp * span + cells)      # (warp, cell) held
        worst = max(worst, float(wchain[pairs // span].sum()) / entries)
        conflicts = max(conflicts, _conflict_rounds(pairs // span, pairs % span, wchain))
    return worst, conflicts


def _conflict_rounds(warp: np.ndarray, cell: np.ndarray, chain: np.ndarray) -> float:
    """The end of the last warp when warps holding ``cell`` (pairs, by warp) start in rounds: in each, the warps
    of the lexicographically first maximal set of waiting warps that share no cell (found a step at a time: the
    waiting warps first in submission order on each of their cells start, and the warps sharing a cell with
    them wait for the next round); a warp starts when the warps before it on its cells have ended, and runs its
    ``chain``."""
    n = len(chain)
    if not len(warp):
        return 0.0
    by_cell = np.lexsort((warp, cell))
    pw, pc = warp[by_cell], cell[by_cell]
    cell_of = np.cumsum(np.r_[False, pc[1:] != pc[:-1]])          # dense cell numbers, ascending
    free_at = np.zeros(int(cell_of[-1]) + 1)                      # each cell's last holder's end
    end = np.zeros(n)
    big = np.iinfo(np.int64).max
    while len(pw):                                # a round; pw, cell_of: the pairs of the warps still waiting
        cell_start = run_starts(cell_of)
        candidate = np.zeros(n, bool)
        candidate[pw] = True
        started = np.zeros(n, bool)
        while candidate.any():
            live = candidate[pw]
            first = np.repeat(np.minimum.reduceat(np.where(live, pw, big), cell_start),
                              np.diff(np.append(cell_start, len(pw))))
            behind = np.bincount(pw[live & (pw != first)], minlength=n)
            go = candidate & (behind == 0)            # first on every one of its cells among the candidates
            started |= go
            taken = np.zeros(len(free_at), bool)
            taken[cell_of[go[pw]]] = True
            candidate &= ~go
            candidate[pw[taken[cell_of] & candidate[pw]]] = False      # they share a cell with a starting warp
        mine = started[pw]
        start = np.zeros(n)
        np.maximum.at(start, pw[mine], free_at[cell_of[mine]])
        end[started] = start[started] + chain[started]
        free_at[cell_of[mine]] = end[pw[mine]]
        pw, cell_of = pw[~mine], cell_of[~mine]
    return float(end.max())


class _PassWarps:
    """The warps of a pass as lowering packs its lanes (``keys``: the pass's lane keys, ascending): a pixel
    shader's fragments spread evenly over the warps of their 2x2 quads' lanes (helper lanes included; or
    quads of one owner's tiles, ``raster.warp_packing``), a
    software rasterizer's warps of ``warp_size`` consecutive triangles (``triangles`` of them, those without a
    fragment included), the scoreboard's dispatch (``packing``), or ``warp_size`` consecutive lanes."""

    def __init__(self, mapping: str, keys: np.ndarray, packing: _Packing, ws: int, triangles: int, quads, work,
                 gpu):
        self.keys, self.ws, self.quads = keys, ws, 0
        self._memo: dict[int, tuple] = {}     # id(keys) -> (keys, their warps): :meth:`of`
        self.scale = None                     # (warps, lanes): a lane's warp is its rank x warps // lanes
        self.contiguous = len(keys) > 0 and int(keys[-1]) - int(keys[0]) + 1 == len(keys)
        if mapping == "fragment" and len(keys):
            self.quads = quads.quads(keys, work)
        if packing.warp is not None:
            self.mode, self.packing = "dispatch", packing
            self.n = int(packing.warp.max(initial=-1)) + 1
        elif mapping == "triangle":
            self.mode, self.n = "triangle", -(-triangles // ws)
        elif mapping == "fragment" and len(keys) and gpu.raster.warp_packing == "submission":
            self.mode = "spread"
            self.n = min(len(keys), max(1, -(-4 * self.quads // ws)))
            self.scale = (self.n, len(keys))
        elif mapping == "fragment" and len(keys):
            self.mode = "owner"
            self.warp, self.quads_so_far = quads.warps(keys, work, gpu)
            self.n = int(self.warp.max()) + 1
        else:
            self.mode, self.n = "consecutive", -(-len(keys) // ws)

    def rank(self, keys: np.ndarray) -> np.ndarray:
        """The position of each key among the pass's."""
        if self.contiguous:
            return keys - int(self.keys[0])
        return np.searchsorted(self.keys, keys)

    def of(self, keys: np.ndarray) -> np.ndarray:
        """The warp of each lane key (kept for the arrays asked again: a group's threads, the pass's keys)."""
        memo = self._memo.get(id(keys))
        if memo is not None and memo[0] is keys:
            return memo[1]
        w = self._of(keys)
        self._memo[id(keys)] = (keys, w)
        return w

    def _of(self, keys: np.ndarray) -> np.ndarray:
        if self.mode == "triangle":
            return keys // self.ws
        if self.mode == "dispatch":
            return self.packing.warp[np.searchsorted(self.packing.keys, keys)]
        if self.mode == "spread":
            return self.rank(keys) * self.scale[0] // self.scale[1]
        if self.mode == "owner":
            return self.warp[self.rank(keys)]
        return self.rank(keys) // self.ws

    def sum_of(self, values, keys: np.ndarray) -> np.ndarray:
        """Per warp of the pass, the sum of its lanes' ``values`` (one per key of ascending ``keys``, or one for
        all)."""
        out = np.zeros(self.n)
        if not len(keys):
            return out
        w = self.of(keys)
        if np.ndim(values) == 0:
            return out + np.bincount(w, minlength=self.n) * float(values)
        if self.mode == "owner":          # a warp's lanes need not be consecutive keys
            return np.bincount(w, weights=np.asarray(values, np.float64), minlength=self.n)
        runs = run_starts(w)
        out[w[runs]] = np.add.reduceat(np.asarray(values, np.float64), runs)
        return out

    def max_of(self, values, keys: np.ndarray) -> np.ndarray:
        """Per warp of the pass, the largest of its lanes' ``values`` (one per key of ascending ``keys``, or one
        for all), 0 in a warp without one of them."""
        out = np.zeros(self.n)
        if not len(keys):
            return out
        w = self.of(keys)
        if self.mode == "owner":
            np.maximum.at(out, w, values)
            return out
        runs = run_starts(w)
        out[w[runs]] = values if np.ndim(values) == 0 else np.maximum.reduceat(values, runs)
        return out


def _fed(ready: np.ndarray, demand: np.ndarray, servers: int) -> tuple[float, bool]:
    """When a unit that serves each warp's ``demand`` (cycles) once the warp is ``ready``, in warp order, is done:
    the largest over warps ``j`` of ``ready[j]`` plus the demand of the warps from ``j`` on (a queue fed by the
    front end); and whether a backlog decides it (the largest is at a warp before the last: the unit fell behind
    the front end), not the last warp's own work after the front end. ``servers``: instances the warps are dealt
    round (a scheduler's issue port each), else one."""
    n = len(ready)
    if not n:
        return 0.0, False
    k = -(-n // servers)
    pad = k * servers - n
    r = np.append(ready, np.full(pad, -np.inf)).reshape(k, servers)
    d = np.append(demand, np.zeros(pad)).reshape(k, servers)
    before = np.cumsum(d, axis=0) - d
    start = r - before
    done = d.sum(axis=0) + start.max(axis=0)
    s = int(done.argmax())
    last = k - 1 if s < servers - pad else k - 2          # the server's last warp
    return float(done[s]), bool(start[last, s] < start[:, s].max())


class _ReadyMemo:
    """Per warp of a pixel shader's pass, the cycle the front end has its fragments out (as the full model's
    front end: every stage's cumulative time at the warp's last triangle, or its quads so far at the
    rasterizer's rate), kept for passes over the same fragments."""

    def __init__(self):
        self.last: tuple = (None, None, None)

    def ready(self, pk, keys: np.ndarray, warps: "_PassWarps", work, gpu, quad_memo: _QuadMemo) -> np.ndarray:
        memo = (keys, submitted_triangles(pk, work), warps.n)
        if self.last[0] is keys and self.last[1] == memo[1:]:
            return self.last[2]
        _, position = _raster_positions(work, pk, keys)
        quads = warps.quads_so_far if warps.mode == "owner" else quad_memo.so_far(keys, work)
        out = warps.max_of(np.maximum(position * per_triangle_cycles(gpu), quads / gpu.raster.quads_per_cycle),
                           keys)
        out = np.maximum.accumulate(out)     # a warp with no lane of its own: when the one before it is
        self.last = (keys, memo[1:], out)
        return out


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


class _L2Model:
    """What an L2 (``l2.size_bytes`` per partition, write-allocate, LRU, its contents carried from pass to pass)
    catches of a pass's requests, from static counts only (a pass's time must not depend on which passes were
    timed before it). Its capacity is every slice's lines (a slice's sets index its own share of the lines). A line
    a pass touches first misses if no earlier pass touched its structure, and otherwise is still there when the
    lines every pass so far touched fit (a share ``capacity / footprint`` of them otherwise); a line touched again
    in the pass hits when the lines touched in between fit (:meth:`_L2Pass.misses`). A miss after the L2 has
    filled evicts a line, one line more to the DRAM when that line was written. A hit's round trip is the L2's, a
    miss's adds the DRAM's; only misses reach the DRAM (the request's bytes); every request holds its slice for
    its bytes."""

    def __init__(self, plan, result, placement, groups_of_pass, gpu, work):
        self.present = gpu.l2.size_bytes > 0
        m = gpu.memory
        self.hit_lat = 2 * m.interconnect_latency + gpu.dram.latency
        self.dram_lat = 0
        self.vertex_bytes = gpu.raster.vertex_bytes
        self.dram_rate, self.l2_rate = gpu.dram.bytes_per_cycle, gpu.l2.bytes_per_cycle
        if not self.present:
            return
        self.hit_lat, self.dram_lat = 2 * m.interconnect_latency + gpu.l2.latency, gpu.dram.latency
        line = self.line = gpu.l2.line_bytes
        self.capacity = gpu.l2.size_bytes // gpu.l2.line_bytes * m.partitions       # lines, every slice's
        self.resident = gpu.core.sms * gpu.core.warps_per_sm           # warps running at once
        structures = getattr(result, "structures", None)
        if structures is not None:
            alloc = {s.name: -(-s.allocated_bytes // line) for s in structures}
        else:                                   # only the layout: a structure reaches the next one's base
            bases = sorted(result.bases().items(), key=lambda kv: kv[1])
            alloc = {a: -(-(b - x) // line) for (a, x), (_, b) in zip(bases, bases[1:])}
        ops: dict = {}
        first: dict = {}
        n_pass = len(plan.passes)
        in_pass = [set() for _ in range(n_pass)]
        # the structures the memory path serves: the core's loads and stores, the ROPs' framebuffer traffic
        framebuffer = framebuffer_traffic(gpu)
        through = [not g.is_compute and (entry_unit(g.op) == MEM or framebuffer and entry_unit(g.op) == ROP)
                   for g in plan.groups]
        for p, gis in enumerate(groups_of_pass):
            for gi in gis:
                g = plan.groups[gi]
                if not through[gi]:
                    continue
                in_pass[p].add(g.structure)
                first.setdefault(g.structure, p)
        for g, t in zip(plan.groups, through):
            if t:
                ops[g.structure] = ops.get(g.structure, 0) + int(g.total)
        # a structure's lines: those it allocates, at most one per operation on it
        self.lines = {s: max(1, min(alloc.get(s, ops[s]), ops[s])) for s in ops}
        software = [p for p, pk in enumerate(plan.passes) if thread_mapping(gpu, pk) == "triangle"]
        self.vertex_first = software[0] if software else -1
        vertex_lines = -(-work.triangles * (INDEX_BYTES + 3 * gpu.raster.vertex_bytes) // line)
        # lines every pass up to p touched, and each pass's own
        footprint = np.zeros(n_pass)
        for s, p in first.items():
            footprint[p] += self.lines[s]
        if software:
            footprint[self.vertex_first] += vertex_lines
        self.footprint = np.cumsum(footprint)
        self.own = np.array([sum(self.lines[s] for s in ss) + (vertex_lines if p in software else 0)
                             for p, ss in enumerate(in_pass)], np.float64)
        self.first = first
        # dirty lines: those of structures a pass up to p writes
        written = np.zeros(n_pass)
        firsts_w: dict = {}
        for p, gis in enumerate(groups_of_pass):
            for gi in gis:
                g = plan.groups[gi]
                if through[gi] and (g.op in WRITE_OPS or entry_unit(g.op) == ROP):
                    firsts_w.setdefault(g.structure, p)
        for s, p in firsts_w.items():
            written[p] += self.lines[s]
        self.written = np.cumsum(written)

    def evicting(self, p: int) -> float:
        """The share of pass ``p``'s misses that evict a dirty line (one line more to the DRAM): those after the
        L2 has filled with the lines of the passes so far, times the share of those lines written."""
        before, after = (self.footprint[p - 1] if p else 0.0), self.footprint[p]
        if after <= self.capacity:
            return 0.0
        full = 1.0 if before >= self.capacity else (after - self.capacity) / (after - before)
        return full * self.written[p] / after

    def pass_state(self, p: int) -> "_L2Pass":
        return _L2Pass(self, p)

    def service(self, nbytes: float, miss: float) -> float:
        """Cycles a partition serves a request of ``nbytes`` that misses the L2 with probability ``miss``: its
        slice's, then the DRAM's on a miss (the DRAM's alone without an L2)."""
        if not self.present:
            return nbytes / self.dram_rate
        return nbytes / self.l2_rate + miss * nbytes / self.dram_rate

    def latency(self, miss: float) -> float:
        """The round trip of a memory request that misses the L2 with probability ``miss``."""
        return self.hit_lat + miss * self.dram_lat

    def kept(self, p: int) -> float:
        """The share of lines an earlier pass left that pass ``p`` still finds."""
        return min(1.0, self.capacity / self.footprint[p]) if self.footprint[p] else 1.0

    def again(self, p: int) -> float:
        """The share of the lines pass ``p`` touched that are still there when it touches them again."""
        return min(1.0, self.capacity / self.own[p]) if self.own[p] else 1.0


class _L2Pass:
    """One pass's L2 requests and misses (all misses without an L2)."""

    def __init__(self, model: _L2Model, p: int):
        self.model, self.p = model, p
        self.seen: dict = {}                      # structure -> its lines touched so far in the pass
        self.threads: dict = {}                   # structure -> the threads of the pass's groups on it so far
        self.requests = self.missed = 0.0         # bytes requested, bytes that missed

    def misses(self, structure: str, threads, ops: float, requests: float, nbytes: float, addr: np.ndarray,
               warp: np.ndarray, seq: np.ndarray, warps: int, at: int) -> tuple[float, float]:
        """A memory group's DRAM bytes per request and the share of its ``requests`` (of ``nbytes`` each) that miss.
        ``ops`` operations on ``structure`` by ``threads`` (their ids and selection in the pass) in ``warps`` warps,
        from the warps' instruction ``at`` on; ``addr``: the addresses of a sample of them, ``warp`` the warp (in
        the group's order) and ``seq`` the operation number of each.

        Warps run in waves of the resident ones, each wave's warps an instruction at a time together, so between
        two touches of a line the L2 sees the lines of the warp instructions issued in between (LRU's reuse
        distance); a touch finds its line when those fit. In the sample, a line's first touch is a line the pass
        brings in (a line its threads touched in an earlier group of the pass, when still there, hits); the
        sample's counts stand for the group's (times its operations over the sample's)."""
        m = self.model
        if not m.present:
            self._count(requests * nbytes, 1.0)
            return nbytes, 1.0
        wave = max(1, min(warps, m.resident))
        steps = int(seq.max(initial=0)) + 1
        clock = (warp // wave) * wave * steps + seq * wave + warp % wave     # the order warp instructions issue in
        lines = addr // m.line
        lines -= lines.min(initial=0)
        span = int(clock.max(initial=0)) + 1
        if int(lines.max(initial=0)) < (1 << 62) // span:     # (line, clock) pairs in order, in one sort
            key = np.sort(lines * span + clock)
            ln, t = key // span, key % span
        else:
            order = np.lexsort((clock, lines))
            ln, t = lines[order], clock[order]
        again = np.r_[False, ln[1:] == ln[:-1]]
        per_inst = _distinct((clock << 28) + (lines & ((1 << 28) - 1))) / max(1, _distinct(clock))
        far = float(np.count_nonzero(again & (np.r_[0, np.diff(t)] * per_inst > m.capacity)))
        scale = ops / max(1, len(addr))
        first = float(len(ln) - np.count_nonzero(again)) * scale
        mine = self.threads.setdefault(structure, [])
        th, sel = threads
        before = next((a for t_, s_, a in mine if (t_ is th or (len(t_) == len(th) and np.array_equal(t_, th)))
                       and s_ is sel), None)
        if before is None:
            mine.append((th, sel, at))
        total = m.lines[structure]
        seen = self.seen.get(structure, 0.0)
        if before is not None:           # the same threads again: their own lines, brought in ``at - before`` ago
            if (at - before) * wave * per_inst <= m.capacity:
                first = 0.0
            new = 0.0
        else:
            new = max(0.0, min(seen + first, total) - seen)
            self.seen[structure] = seen + new
        cold = 1.0 if m.first[structure] >= self.p else 1.0 - m.kept(self.p)
        # first touches beyond the structure's lines are lines other warps touched (the sample's gaps hide when)
        missed = new * cold + far * scale + (first - new) * (1.0 - m.again(self.p))
        miss = min(1.0, missed / requests) if requests else 0.0
        self._count(requests * nbytes, miss)
        return miss * (nbytes + m.evicting(self.p) * m.line), miss

    def _count(self, nbytes: float, miss: float) -> float:
        self.requests += nbytes
        self.missed += nbytes * miss
        return miss

    def vertex_misses(self, triangles: int) -> tuple[float, float]:
        """A software rasterizer's vertex and index loads: the DRAM's bytes per byte loaded, and the share that
        misses."""
        m = self.model
        if not m.present:
            return 1.0, 1.0
        miss = 1.0 if m.vertex_first >= self.p else 1.0 - m.kept(self.p)
        self._count(triangles * (INDEX_BYTES + 3 * m.vertex_bytes), miss)
        return miss * (1.0 + m.evicting(self.p) * m.line / (INDEX_BYTES + 3 * m.vertex_bytes)), miss

    def miss_ratio(self) -> float:
        return self.missed / self.requests if self.requests else (0.0 if self.model.present else 1.0)


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
        self.dram_bytes = np.zeros(n_pass)            # bytes the DRAM serves (with an L2: its misses)
        self.l2_bytes = np.zeros(n_pass)              # bytes of every memory request (an L2 slice serves each)
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
        self.ready_memo = _ReadyMemo()         # and the cycles the front end has each warp's fragments out
        self.whole_groups: list = []           # the last groups met whole: (threads, triangle mapping, lane info)
        self.nested: dict = {}                 # each count array's threads still issuing, as the last pass had them
        self.last_still: list = []             # the threads still issuing of the last pass timed
        self.sel_lanes: dict = {}              # the last pass's lane info of threads still issuing, by their set
        self.ascending: dict = {}              # group -> whether its thread ids ascend
        self.units_of: dict = {}               # ROP group -> the unit of each of its threads' first address
        self.framebuffer = framebuffer_traffic(gpu)   # ROP operations read and write through the memory path
        self.l2 = _L2Model(plan, result, self.placement, self.groups_of_pass, gpu, work)

    def _contiguous_round_trip(self, nbytes: int, miss: float) -> float:
        """The round trip of a warp instruction reading ``nbytes`` contiguous bytes that miss the L2 with
        probability ``miss``: the latency, and its requests on the busiest partition (the interleave's blocks
        dealt round the partitions) served back to back."""
        m = self.gpu.memory
        blocks = -(-nbytes // m.interleave_bytes)
        busiest = min(nbytes, -(-blocks // m.partitions) * m.interleave_bytes)
        return self.l2.latency(miss) + self.l2.service(-(-busiest // SECTOR) * SECTOR, miss)

    def per_pass(self) -> tuple:
        return self.wis, self.alu, self.dram_bytes, self.atomic_ops, self.hottest, self.rop_unit, self.l2_bytes

    def _traffic(self, g, thread, sel, lanes, counts, nb, lane_inst, warps: "_PassWarps", ops: float, warp_ops,
                 at: int, l2: "_L2Pass", demand: dict | None, p: int, copies: int) -> tuple:
        """A group's memory requests as the coalescer makes them, added to pass ``p``'s L2 and DRAM bytes (and
        to the front end's demand): coalescing and the L2's lines on a spread sample of its operations (every
        operation of the sampled lanes: a thread's later operations may straddle segments its first does not).
        ``copies``: 1 for the core's loads and stores, 2 for the ROPs' framebuffer reads and their writes (the
        write finds the line the read brought in; without an L2 both reach the DRAM). The requests' keys, their
        mean bytes and the share that misses the L2."""
        gpu, m = self.gpu, self.gpu.memory
        segment = gpu.coalescer.segment_bytes
        i_s, seq_s, _ = _op_sample(lanes, counts, gpu.core.warp_size, g.seq_pass is None and g.pass_fn is None,
                                   self.l2.present)
        warp_s = warps.of(thread[i_s]) if lane_inst is None else lane_inst[thread[i_s]]
        addr = self.bases[g.structure] + np.asarray(g.offset(i_s, seq_s), np.int64)
        nb_s = np.broadcast_to(np.asarray(nb if nb is not None else g.bytes(i_s, seq_s), np.int64), addr.shape)
        inst = warp_s * (int(seq_s.max(initial=0)) + 1) + seq_s    # the warp instruction of each
        wkey, req_b = _requests(inst, addr, np.maximum(nb_s, 1), segment)
        requests_per_lane = len(wkey) / max(1, len(addr))
        req_bytes = float(req_b.mean()) if len(req_b) else float(SECTOR)
        requests = ops * requests_per_lane
        per_request, miss = l2.misses(g.structure, (thread, sel), ops, requests, req_bytes, addr, warp_s, seq_s,
                                      warps.n, at)
        # the copies after the first hit the L2 (the line is in) or, without one, go to the DRAM as the first did
        dram_per_request = per_request + (copies - 1) * (0.0 if self.l2.present else req_bytes)
        self.l2_bytes[p] += copies * requests * req_bytes
        self.dram_bytes[p] += requests * dram_per_request
        if warp_ops is not None and self.l2.present:
            demand["l2"] += warp_ops * (copies * requests_per_lane * req_bytes
                                        / (gpu.l2.bytes_per_cycle * m.partitions))
        if warp_ops is not None:
            demand["dram"] += warp_ops * (requests_per_lane * dram_per_request
                                          / (gpu.dram.bytes_per_cycle * m.partitions))
        return wkey, req_bytes, miss

    def time(self, p: int) -> dict:
        """Pass ``p``'s record (name, kind, cycles, warps, the bound that decided it), its figures in the arrays."""
        plan, bases, work, gpu = self.plan, self.bases, self.work, self.gpu
        c, m = gpu.core, gpu.memory
        ws, cost = c.warp_size, c.op_issue_cycles
        alu_cost = c.issue_cycles / c.alu_issue_width   # an ALU instruction of a warp (alu_issue_width a lane-cycle)
        segment = gpu.coalescer.segment_bytes
        lat, overhead, placement, ids = self.lat, self.overhead, self.placement, self.ids
        groups_of_pass, quad_memo, nested = self.groups_of_pass, self.quad_memo, self.nested
        wis, alu, dram_bytes, atomic_ops, hottest, rop_unit, l2_bytes = self.per_pass()
        l2 = self.l2.pass_state(p)           # the L2's lines touched so far in this pass, its requests and misses
        used, ascending, units_of = self.used, self.ascending, self.units_of
        traffic = self._traffic
        last_still, sel_lanes = self.last_still, self.sel_lanes
        pk = plan.passes[p]
        if pk.kind == "flush":
            return {"name": pk.name, "kind": pk.kind, "bound": "flush", "warps": 0,
                    "cycles": flush_cycles(c) + overhead}
        last_producer, last_serial, waited = None, None, False
        steps = 0                             # instructions a warp has issued before the group (the busiest lane's)
        adds: list = []                       # each group's lane info, dependent-chain cycles per lane, threads
        pass_keys: list = []                  # the lane keys of each group in the pass
        met: list = []                        # each group's threads, selection, lanes and counts in the pass
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
                    warp_threads = 0
                else:
                    lo = int(lanes.min())
                    size = int(lanes.max()) + 1 - lo
                    threads_in = np.bincount(lanes - lo, minlength=size)
                    present = np.flatnonzero(threads_in)
                    threads_in, keys = threads_in[present], lo + present
                    warp_threads = 0
                got = (lanes, lo, size, threads_in, present, warp_threads, keys, distinct)
                cached.append((thread, memo, got))
                if sel is None and packing.warp is None:
                    self.whole_groups = [(thread, triangles, got)] + self.whole_groups[:WHOLE_GROUPS - 1]
            if memo is not None and packing.warp is None:
                made_lanes[id(sel)] = (sel, thread, triangles, got)
            lanes, lo, size, threads_in, present, warp_threads, keys, distinct = got
            pass_keys.append(keys)
            met.append((gi, g, thread, sel, issuing, known, compute, cls, produces, nb, lanes_sel, counts, got, n))
        self.last_still, self.sel_lanes = list(still.values()), made_lanes
        if not met:
            return {"name": pk.name, "kind": pk.kind, "cycles": overhead, "warps": 0, "bound": "empty"}
        # the pass's warps, as lowering packs them (helper lanes, triangles, the scoreboard's dispatch)
        mapping = thread_mapping(gpu, pk)
        lane_keys = _lane_keys(pass_keys)
        tris = (submitted_triangles(pk, work) if pk.primitives is None else int(lane_keys.max()) + 1) \
            if triangles else 0
        warps = _PassWarps(mapping, lane_keys, packing, ws, tris, quad_memo, work, gpu)
        warp_issue = np.zeros(warps.n)        # each warp's cycles on its SM's issue port
        # triangle threads: each warp's iterations of its loops (SIMT), and the warps' atomic waits
        loop = None
        if triangles:                         # each fragment's warp instruction (iteration) in its thread's loop
            frags = _as_slice(_covering([ids[i] for i in groups_of_pass[p]]))
            frag_tri = work.frag_prim[frags]
            inst_p, iterations = _loop_instructions(frag_tri, ws)
            frag_inst = np.zeros(len(work.frag_prim), np.int64)
            frag_inst[frags] = inst_p
            loop = _SimtLoop(frags, frag_inst, iterations, warps.n)
        loop_waits: list = []
        phases = 0.0                          # the groups one after another, each as long as its busiest unit
        fed = mapping == "fragment" and len(lane_keys) > 0     # the front end feeds the warps at its rate
        demand = {u: np.zeros(warps.n) for u in ("dram", "l2", "atomic", "rop")} if fed else None
        for gi, g, thread, sel, issuing, known, compute, cls, produces, nb, lanes_sel, counts, got, n in met:
            lanes, lo, size, threads_in, present, warp_threads, keys, distinct = got
            c0, uniform = _uniform(counts)
            # per present lane: its operations (not needed when every lane runs one thread with the same count)
            if uniform:
                per_lane = None if threads_in is None else threads_in if c0 == 1 else threads_in * c0
            elif distinct:
                per_lane = np.asarray(counts, np.float64)
            else:
                per_lane = np.bincount(lanes - lo, weights=counts, minlength=size)[present]
            # warp instructions: each warp of the pass holding the group's lanes issues its busiest lane's count
            per_warp = warps.max_of(c0 if per_lane is None else per_lane, keys)
            busiest = float(per_warp.sum())
            if compute:
                alu[p] += busiest * alu_cost
                warp_issue += per_warp * alu_cost
            else:
                wis[p] += busiest
                warp_issue += per_warp * cost
            before = (dram_bytes[p], l2_bytes[p], atomic_ops[p], rop_unit[p].max())     # (the phases bound)
            phase_issue = _busiest_port(per_warp, c) * (alu_cost if compute else cost)
            at, steps = steps, steps + (1 if compute else (c0 if uniform else int(counts.max(initial=0))))
            ops = float(c0 * len(counts) if uniform else counts.sum())
            warp_ops = warps.sum_of(c0 if per_lane is None else per_lane, keys) if fed and not compute else None
            # coalescing (on a spread sample of warps), the hottest address, the units' loads
            # threads with no operation in this group have no address (a list walk of zero nodes)
            live = None if not len(counts) or (c0 if uniform else int(counts.min())) > 0 else counts > 0
            lanes_live = lanes_sel if live is None else lanes_sel[live]
            counts_live = counts if live is None else counts[live]
            mem_lat, atomic_lat, serial = lat[MEM], lat[ATOMIC], None
            # a triangle thread's loop: its warp's instruction at iteration j carries its triangles' j-th fragments
            # the warp instruction of a lane: of a triangle thread's loop, its iteration's (frag_inst), else its warp's
            lane_inst = frag_inst if triangles else None
            if not len(lanes_live) or compute:
                pass                             # no thread issues this group in this pass, or no memory
            elif cls == MEM:
                wkey, req_bytes, miss = traffic(g, thread, sel, lanes_live, counts_live, nb, lane_inst, warps, ops,
                                                warp_ops, at, l2, demand, p, 1)
                # a warp instruction's requests to one partition are served back to back before its result is
                # back: the busiest partition's requests of each instruction, on average
                cell = (wkey >> 36) * m.partitions + interleave((wkey & SEG_MASK) * segment, m.interleave_bytes,
                                                                m.partitions)
                cell = np.sort(cell)
                starts = run_starts(cell)
                per_cell = np.diff(np.append(starts, len(cell)))
                runs = run_starts(cell[starts] // m.partitions)
                own = float(np.maximum.reduceat(per_cell, runs).mean()) if len(runs) else 0.0
                mem_lat = self.l2.latency(miss) + own * self.l2.service(req_bytes, miss)
            elif cls == ROP and g.seq_pass is not None and len(placement[gi][2]) > 1:
                addr = None
            else:
                zero = np.broadcast_to(np.zeros(1, np.int64), lanes_live.shape)
                addr = bases[g.structure] + np.asarray(g.offset(lanes_live, zero), np.int64)
            if not len(lanes_live) or compute:
                pass
            elif cls == ATOMIC:
                atomic_ops[p] += ops
                if warp_ops is not None:
                    demand["atomic"] += warp_ops / (gpu.atomic.ops_per_cycle * m.partitions)
                if gpu.atomic.dram_rmw:          # each reads and writes its sector in DRAM
                    dram_bytes[p] += ops * DRAM_RMW_BYTES
                    if warp_ops is not None:
                        demand["dram"] += warp_ops * (DRAM_RMW_BYTES / (gpu.dram.bytes_per_cycle * m.partitions))
                hottest[p] = max(hottest[p], float(_hottest(addr)))
                # lanes of one instruction on one word serialize: the instruction's result waits for its busiest
                # word's operations, same_address_cycles apart
                i_s, seq_s, pos_s = _op_sample(lanes_live, counts_live, ws,
                                               g.seq_pass is None and g.pass_fn is None, self.l2.present)
                words = bases[g.structure] + np.asarray(g.offset(i_s, seq_s), np.int64)
                steps_ = int(seq_s.max(initial=0)) + 1
                inst = (warps.of(thread[i_s]) if lane_inst is None else lane_inst[thread[i_s]]) * steps_ + seq_s
                winst, per_word = _instruction_words(inst, words & SEG_MASK)
                runs = run_starts(winst)
                waits = (np.maximum.reduceat(per_word, runs) - 1) * float(gpu.atomic.same_address_cycles)
                if lane_inst is None:            # an instruction an operation: the mean instruction's wait
                    atomic_lat = lat[ATOMIC] + (float(waits.mean()) if len(waits) else 0.0)
                else:                            # a triangle thread's warp: its own instructions' waits
                    serial = _warp_waits(winst[runs] // (steps_ * iterations), waits, ws)
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
                load = np.bincount(unit, weights=counts_live * svc, minlength=gpu.rop.units)
                rop_unit[p] += load
                if self.framebuffer:        # a read and a write of each sector its instructions touch
                    traffic(g, thread, sel, lanes_live, counts_live, nb, lane_inst, warps, ops, warp_ops, at, l2,
                            demand, p, 2)
                if warp_ops is not None and load.sum():
                    demand["rop"] += warp_ops * (svc * load.max() / load.sum())     # at the busiest unit's share
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
            unit_lat = mem_lat if cls == MEM else atomic_lat if cls == ATOMIC else lat.get(cls, 0)
            if g.dep and produces:
                add = add + (c0 if same else per_lane) * unit_lat
                if serial is not None:
                    add = add + serial(keys)
            elif g.dep and lp is not None and not waited:
                add = add + (1 if same or threads_in is None else threads_in) * lp
                if last_serial is not None:
                    add = add + last_serial(keys)
            phases += max(phase_issue,
                          (dram_bytes[p] - before[0]) / (gpu.dram.bytes_per_cycle * m.partitions),
                          (l2_bytes[p] - before[1]) / (gpu.l2.bytes_per_cycle * m.partitions) if self.l2.present else 0,
                          (atomic_ops[p] - before[2]) / (gpu.atomic.ops_per_cycle * m.partitions),
                          rop_unit[p].max() - before[3])
            adds.append((got, add, (thread, issuing.count, issuing.s, sel) if known and issuing is not None
                         and g.seq_pass is not None else None))
            if loop is not None:                 # the group's part of each iteration of its warps' loops
                loop.add(_as_slice(thread if sel is None else thread[lanes_sel]), c0 if uniform else counts,
                         (alu_cost if compute else cost) + (unit_lat if g.dep and produces else 0.0),
                         lp if g.dep and not produces and lp is not None and not waited else 0.0)
                if g.dep and produces and serial is not None:
                    loop_waits.append(serial)
                elif g.dep and not produces and lp is not None and not waited and last_serial is not None:
                    loop_waits.append(last_serial)
            if produces:
                last_producer, last_serial, waited = unit_lat, serial, False
            elif g.dep:
                waited = True
        if not adds:
            return {"name": pk.name, "kind": pk.kind, "cycles": overhead, "warps": 0, "bound": "empty"}
        chain = _chain_on_lanes(adds, nested)
        chain_keys, lane_chain = chain if chain is not None else _chain_on_range(adds)
        del adds, chain
        wchain = warps.max_of(lane_chain, chain_keys)
        if mapping == "triangle":
            # SIMT: a warp runs each iteration of its threads' loops on its lanes' j-th fragments together
            # (_SimtLoop), so its chain is the sum over iterations, not its longest lane's sum
            by_iteration = loop.per_warp()
            for w_ in loop_waits:
                by_iteration = by_iteration + w_(np.arange(warps.n) * ws)
            wchain = np.maximum(wchain, by_iteration)
            # software rasterizer: a thread per submitted triangle (warps of consecutive triangles, those that cover
            # no pixel included) loads its indices, then its vertices, sets up and scans its bounding box (a warp
            # its largest box) before its fragments' operations
            r = gpu.raster
            box = bbox_pixels(frag_tri, work.frag_pixel[frags], work.width, tris)
            setup_w = _warp_max(box, ws) * (r.pixel_instructions * alu_cost) + r.setup_instructions * alu_cost
            vertex_dram, vertex_miss = l2.vertex_misses(tris)
            # the index load's round trip, then the vertex load's, each with its instruction's requests on the
            # busiest partition (the warp's triangles' bytes are contiguous)
            fetch = [self._contiguous_round_trip(min(ws, tris) * nb, vertex_miss)
                     for nb in (INDEX_BYTES, 3 * r.vertex_bytes)]
            wchain += 2 * cost + sum(fetch) + c.alu_cycles(r.setup_instructions + r.pixel_instructions
                                                           * _warp_max(box, ws))
            warp_issue += 2 * cost + setup_w
            wis[p] += 2 * warps.n
            alu[p] += float(setup_w.sum())
        n_warps = len(wchain)
        sm = SimtCore.place(n_warps, c.sms)
        per_sm = np.bincount(sm, weights=wchain, minlength=c.sms)
        n_sm = np.bincount(sm, minlength=c.sms)
        bounds = {
            "issue": _busiest_port(warp_issue, c),
            "latency": float(max(wchain.max(), (per_sm / np.maximum(1, np.minimum(n_sm, c.warps_per_sm))).max())),
            "dram": dram_bytes[p] / (gpu.dram.bytes_per_cycle * m.partitions),
            "atomic": atomic_ops[p] / (gpu.atomic.ops_per_cycle * m.partitions),
            "atomic_address": hottest[p] * gpu.atomic.same_address_cycles,
            "rop": float(rop_unit[p].max()),
        }
        if mapping == "thread" and warps.n <= c.sms * c.warps_per_sm:
            # every warp resident from the start: they go through the groups in step, each group's units in turn
            bounds["phases"] = phases
        if held:
            bounds["scoreboard"], bounds["scoreboard_conflicts"] = _scoreboard_bound(
                held, warps.of, wchain, gpu.scoreboard.entries)
        if fed:
            # the front end sees every triangle, and emits the fragments' 2x2 quads
            bounds["raster"] = max(submitted_triangles(pk, work) * per_triangle_cycles(gpu),
                                   warps.quads / gpu.raster.quads_per_cycle)
            # a warp starts once the front end has its fragments out, so a unit serves each warp's work only after
            # that, and the last warps' chains run after the front end is done
            ready = self.ready_memo.ready(pk, lane_keys, warps, work, gpu, quad_memo)
            demand["issue"] = warp_issue
            fed_by = [_fed(ready, d, c.issue_ports if u == "issue" else 1) for u, d in demand.items()]
            # the front end's last warps' chains, and their own work, end after it (the raster bound's tail);
            # a unit's backlog of work the front end fed faster than it serves is the front_end bound
            bounds["raster"] = max(bounds["raster"], float((ready + wchain).max()),
                                   *(v for v, backlog in fed_by if not backlog))
            bounds["front_end"] = max((v for v, backlog in fed_by if backlog), default=0.0)
        elif mapping == "triangle":
            vertex_bytes = tris * (INDEX_BYTES + 3 * r.vertex_bytes)
            l2_bytes[p] += vertex_bytes
            dram_bytes[p] += vertex_bytes * vertex_dram
            bounds["dram"] = dram_bytes[p] / (gpu.dram.bytes_per_cycle * m.partitions)
            used[p].add(MEM)
        if self.l2.present:
            bounds["l2"] = l2_bytes[p] / (gpu.l2.bytes_per_cycle * m.partitions)
        limit = max(bounds, key=bounds.get)
        extra = int(np.ceil(max(self.l2.latency(l2.miss_ratio()) if u == MEM else lat[u] for u in used[p]))) + overhead
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
            _, at, w = how
            mix.append((p, at, w))
            used[p] = set().union(*(used[q] for q in at))
            passes.append(interpolated([schedule.records[q] for q in at], at, w) | {"name": pk.name})
    for arr in arrays:
        arr[copy_to] = arr[copy_from]
        for p, at, w in mix:
            arr[p] = sum(wi * arr[q] for wi, q in zip(w, at))
    for x in passes:
        x.pop(TERMS, None)
    total = sum(x["cycles"] for x in passes)
    wis, _, dram_bytes, atomic_ops, _, rop_unit, _ = arrays
    every = set().union(*used)
    # the ROPs' framebuffer traffic too, and atomics that read and write DRAM
    memory = MEM in every or (ROP in every and framebuffer_traffic(gpu)) or (ATOMIC in every and gpu.atomic.dram_rmw)
    units_built = [name for name, on in (("dram", memory), ("atomic", ATOMIC in every), ("rop", ROP in every),
                                         ("scoreboard", SCOREBOARD in every)) if on]
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
