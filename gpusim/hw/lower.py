"""Lowering a scheme's operations to warp instructions: what the SIMT cores execute.

The input is the scheme's :class:`~gpusim.schemes.opstream.OpPlan`, the grouped
form of its OpStream ("these threads issue ``count`` operations ``op`` on
``structure``", in program order). Lowering works group by group and never
materialises the row-sorted OpStream: the rows it makes are those of the warp
instructions, grouped by instruction.

A *lane* is a thread of a pass: a fragment, a pixel or a memory entry, or, with
the ``triangle`` thread mapping, a triangle whose thread loops over its
fragments (FreePipe, seed 000 section 3). A warp is ``warp_size`` consecutive
lanes in submission order; warps go to the SMs round robin. Warps execute
SIMT, group after group in program order: a group whose lanes issue
``count`` operations is a loop of ``max(count)`` warp instructions over the
warp's lanes, instruction ``k`` carrying the lanes with ``count > k`` (the
others are masked off). With the triangle mapping, the thread's loop over its
fragments is the outer loop: iteration ``j`` runs every group for the
``j``-th fragment of each lane's triangle. So a warp's instructions run in the
order (fragment iteration ``j``, group, ``k``).

Everything here is vectorized numpy; the event model (gpusim.hw.machine) then
walks warps and instructions.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from functools import cached_property

import numpy as np

from gpusim.errors import GpusimError
from gpusim.hw.units import div, mod
from gpusim.metrics.composite import run_starts
from gpusim.opplan import DEFAULT_MAX_OPS, OPS, OpPlan, ThreadRange
from gpusim.schemes.common.arrays import rank_in_runs

MEM, ATOMIC, ROP, SCOREBOARD = 0, 1, 2, 3
UNIT_CLASSES = ("memory", "atomic", "rop", "scoreboard")
_CLASS_OF_OP = {"load": MEM, "store": MEM, "rmw_read": MEM, "rmw_write": MEM,
                "atomic_min": ATOMIC, "atomic_max": ATOMIC, "atomic_inc": ATOMIC, "atomic_exch": ATOMIC,
                "blend": ROP, "depth_test": ROP, "stencil": ROP, "program_blend": ROP,
                "scoreboard": SCOREBOARD}
#: operations whose result a later dependent operation waits for
PRODUCES = frozenset({"load", "rmw_read", "atomic_min", "atomic_max", "atomic_inc", "atomic_exch",
                      "depth_test", "stencil", "scoreboard"})
OP_CLASS = np.array([_CLASS_OF_OP[o] for o in OPS], np.int8)
OP_PRODUCES = np.array([o in PRODUCES for o in OPS])
RMW_READ, RMW_WRITE = OPS.index("rmw_read"), OPS.index("rmw_write")


class Workload:
    """What the hardware replays: the scheme's plan and where its structures live, the screen,
    and each fragment thread's pixel and triangle.

    ``frag_pixel[t]`` and ``frag_prim[t]`` are for fragment thread ``t`` (the
    scheme's submission order).
    """

    def __init__(self, plan: OpPlan, bases: dict[str, int], width: int, height: int, frag_pixel,
                 frag_prim, result=None, triangles: int | None = None):
        """``frag_pixel`` and ``frag_prim``: arrays, or callables making them when first needed (the analytic
        level never needs the pixels)."""
        self.plan, self.bases, self.result = plan, bases, result
        self.width, self.height = width, height
        self._made = {"frag_pixel": frag_pixel, "frag_prim": frag_prim}
        if triangles is None:
            prim = self.frag_prim
            triangles = int(prim.max()) + 1 if len(prim) else 0
        self.triangles = triangles

    def _array(self, name: str) -> np.ndarray:
        got = self._made[name]
        if callable(got):
            got = got()
        got = self._made[name] = np.asarray(got, np.int64)
        return got

    @property
    def frag_pixel(self) -> np.ndarray:
        return self._array("frag_pixel")

    @property
    def frag_prim(self) -> np.ndarray:
        return self._array("frag_prim")

    @classmethod
    def of(cls, result, trace) -> "Workload":
        order = result.submission

        def pick(values):
            return lambda: values() if order is None else values()[order]

        return cls(result.plan, result.bases(), trace.width, trace.height, pick(trace.pixel_ids),
                   pick(lambda: trace.prim), result, int(trace.prim.max()) + 1 if len(trace) else 0)

    @property
    def operations(self) -> int:
        return self.plan.total_ops()


@dataclass
class PassProgram:
    """The warps of one pass: warp w runs instructions ``wi_start[w]..wi_start[w+1]-1``."""

    index: int
    name: str
    kind: str
    wi_start: np.ndarray           # per warp, plus a final end
    lanes: int                     # threads of the pass
    flush_warps: int = 0           # ALU-only warps of a flush pass (a full-screen quad, no memory ops)
    warp_triangles: np.ndarray | None = None   # fixed-function rasterizer: triangles rasterized before each
                                               # warp's fragments are all out (its last triangle + 1)
    triangles: int = 0             # triangles the fixed-function rasterizer takes in the pass
    setup_cycles: int = 0          # issue cycles of software triangle setup at each warp's start
    operations: int = 0            # operations lowered (after any sampling)
    operations_total: int = 0      # operations of the pass in the plan

    @property
    def warps(self) -> int:
        return len(self.wi_start) - 1

    @property
    def instructions(self) -> int:
        return int(self.wi_start[-1] - self.wi_start[0]) if self.warps else 0


class Rows:
    """The operations of one unit class, instruction by instruction (each instruction's lanes in lane order).

    Kept as the parts lowering made (one per plan group and pass, each a run of
    whole instructions), so units can build from them part by part; the
    columns ``op``, ``address``, ``nbytes`` and ``thread`` over all rows are
    joined on first use.
    """

    def __init__(self, parts: list[tuple]):
        self.parts = parts             # (op code, address, bytes: int or per row, thread) per part, in storage order

    def __len__(self) -> int:
        return sum(len(p[1]) for p in self.parts)

    def offsets(self) -> list[int]:
        """Row offset of each part."""
        out, at = [], 0
        for p in self.parts:
            out.append(at)
            at += len(p[1])
        return out

    def _join(self, col: int, dtype) -> np.ndarray:
        cols = [np.full(len(p[1]), p[col], dtype) if np.isscalar(p[col]) else np.asarray(p[col], dtype)
                for p in self.parts]
        return np.concatenate(cols) if cols else np.zeros(0, dtype)

    @cached_property
    def op(self) -> np.ndarray:
        return self._join(0, np.uint8)

    @cached_property
    def address(self) -> np.ndarray:
        return self._join(1, np.int64)

    @cached_property
    def nbytes(self) -> np.ndarray:
        return self._join(2, np.int64)

    @cached_property
    def thread(self) -> np.ndarray:
        return self._join(3, np.int64)


@dataclass
class Program:
    """Warp instructions of a whole run, in issue order, and the rows (operations) they carry.

    Rows are kept per unit class (``rows_of(cls)``); instruction ``i`` carries
    rows ``row_lo[i]..row_hi[i]-1`` of its class (its lanes, in lane order),
    stored instruction by instruction though not in issue order.
    """

    passes: list[PassProgram]
    # per instruction
    row_lo: np.ndarray
    row_hi: np.ndarray
    wi_op: np.ndarray
    wi_class: np.ndarray
    wi_dep: np.ndarray
    wi_produces: np.ndarray
    wi_warp: np.ndarray            # global warp number
    wi_pass: np.ndarray
    wi_group: np.ndarray           # the plan group the instruction comes from
    wi_k: np.ndarray               # its iteration inside the group's loop
    row_sets: dict[int, Rows]      # unit class -> its rows
    frag_pixel: np.ndarray = field(repr=False, default=None)   # pixel of each fragment thread

    @property
    def instructions(self) -> int:
        return len(self.wi_op)

    @property
    def operations(self) -> int:
        return sum(len(r) for r in self.row_sets.values())

    def classes(self) -> set[int]:
        return set(np.unique(self.wi_class).tolist())

    def rows_of(self, cls: int) -> Rows:
        return self.row_sets.get(cls) or Rows([])

    @cached_property
    def row_bounds(self) -> tuple[list, list]:
        """``row_lo`` and ``row_hi`` as lists (the units index them per instruction)."""
        return self.row_lo.tolist(), self.row_hi.tolist()

    def rows(self, wi: int) -> slice:
        """Rows of instruction ``wi`` in ``rows_of(wi_class[wi])``."""
        return slice(int(self.row_lo[wi]), int(self.row_hi[wi]))

    def storage(self, cls: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Instructions of class ``cls`` in row-storage order, their lane counts, and each row's instruction."""
        wis = np.flatnonzero(self.wi_class == cls)
        wis = wis[np.argsort(self.row_lo[wis], kind="stable")]
        counts = self.row_hi[wis] - self.row_lo[wis]
        return wis, counts, np.repeat(wis, counts)


def thread_mapping(gpu, p) -> str:
    """How a pass's threads become lanes: ``triangle``, ``fragment`` or ``thread`` (as they are)."""
    m = gpu.core.thread_mapping
    if p.kind != "geometry" or p.threads != "fragment":
        return "thread"
    if m == "auto":
        return "triangle" if p.software else "fragment"
    return m


@dataclass
class _Piece:
    """The rows of one group in one pass, before lanes are known."""

    group: int
    pass_index: int
    thread: np.ndarray
    k: np.ndarray | None           # iteration in the group's loop (None: all 0)
    address: np.ndarray
    nbytes: np.ndarray | int

    def take(self, idx: np.ndarray) -> "_Piece":
        """The rows ``idx`` of this piece (in that order)."""
        return _Piece(self.group, self.pass_index, self.thread[idx],
                      None if self.k is None else self.k[idx], self.address[idx],
                      self.nbytes if np.isscalar(self.nbytes) else self.nbytes[idx])


def split_by(values: np.ndarray) -> list[tuple[int, np.ndarray]]:
    """Each distinct value of an integer array with the indices holding it (ascending), in value order:
    one stable sort, not one scan per value (a k-buffer batch run has thousands of passes)."""
    if not len(values):
        return []
    order = (np.arange(len(values)) if len(values) < 2 or bool((values[1:] >= values[:-1]).all())
             else np.argsort(values, kind="stable"))
    v = values[order]
    bounds = [0, *(np.flatnonzero(v[1:] != v[:-1]) + 1).tolist(), len(v)]
    return [(int(v[a]), order[a:b]) for a, b in zip(bounds[:-1], bounds[1:])]


def _group_pieces(gi: int, g, bases: dict[str, int]) -> list[_Piece]:
    """Rows of group ``g``, split by pass: thread, loop iteration, address, bytes."""
    n = len(g.thread)
    count = g.count
    i = np.arange(n, dtype=np.int64)
    threads = i if isinstance(g.thread, ThreadRange) else g.thread
    if int(count.min()) == 1 and int(count.max()) == 1:
        seq = np.broadcast_to(np.zeros(1, np.int64), (n,))      # no allocation: every op is the first
        single = True
    else:
        i = np.repeat(i, count)
        seq = np.arange(len(i), dtype=np.int64) - np.repeat(np.cumsum(count) - count, count)
        single = False
    base = bases[g.structure]
    addr = np.asarray(g.offset(i, seq), np.int64) + base
    nbytes = np.asarray(g.bytes(i, seq), np.int32) if callable(g.bytes) else int(g.bytes)
    if g.pass_fn is None and np.isscalar(g.pass_index):
        return [_Piece(gi, int(g.pass_index), threads if single else threads[i], None if single else seq, addr,
                       nbytes)]
    pass_of = (np.asarray(g.pass_fn(i, seq), np.int64) if g.pass_fn is not None
               else np.asarray(g.pass_index, np.int64)[i])
    pieces = []
    for p, sel in split_by(pass_of):
        ii = i[sel]
        # iteration inside this pass: position among the thread's operations of the group in the pass
        k = rank_in_runs(ii)
        pieces.append(_Piece(gi, int(p), threads[ii], k if k.any() else None, addr[sel],
                             nbytes if np.isscalar(nbytes) else nbytes[sel]))
    return pieces


def _bits(n: int) -> int:
    return max(1, int(n).bit_length())


def lower(work: Workload, gpu, keep=None) -> Program:
    """Warp instructions of ``work.plan`` on ``gpu``.

    ``keep(pass_index, threads) -> bool mask`` selects threads (the sampled
    fidelity); a pass none of whose threads is kept runs whole.
    """
    plan = work.plan
    total_ops = plan.total_ops()
    if total_ops > DEFAULT_MAX_OPS:
        raise GpusimError(f"the run would lower {total_ops:,} operations, over the limit of {DEFAULT_MAX_OPS:,}; "
                          f"use a smaller trace or --fidelity sampled|analytic")
    ws = gpu.core.warp_size
    n_pass = len(plan.passes)
    modes = [thread_mapping(gpu, p) for p in plan.passes]
    pieces = [pc for gi, g in enumerate(plan.groups) for pc in _group_pieces(gi, g, work.bases)]
    totals = np.zeros(n_pass, np.int64)
    for pc in pieces:
        totals[pc.pass_index] += len(pc.thread)
    if keep is not None:
        masks = [keep(pc.pass_index, pc.thread) for pc in pieces]
        kept = np.zeros(n_pass, np.int64)
        for pc, m in zip(pieces, masks):
            kept[pc.pass_index] += int(m.sum())
        whole = (kept == 0) & (totals > 0)
        for j, (pc, m) in enumerate(zip(pieces, masks)):
            if not whole[pc.pass_index] and not m.all():
                pieces[j] = pc.take(np.flatnonzero(m))
    by_pass: list[list[_Piece]] = [[] for _ in range(n_pass)]
    for pc in pieces:
        if len(pc.thread):
            by_pass[pc.pass_index].append(pc)

    passes, inst = [], []
    rows: dict[int, list] = {}         # unit class -> row arrays of its pieces
    row_at: dict[int, int] = {}
    warp0 = 0
    for p, pk in enumerate(plan.passes):
        mode, ps = modes[p], by_pass[p]
        ops = sum(len(pc.thread) for pc in ps)
        if not ps:
            flush = -(-work.width * work.height // ws) if pk.kind == "flush" else 0
            passes.append(PassProgram(p, pk.name, pk.kind, np.zeros(1, np.int64), 0, flush,
                                      operations=0, operations_total=int(totals[p])))
            continue
        # lanes of the pass: distinct lane keys in submission order
        keys = [work.frag_prim[pc.thread] if mode == "triangle" else pc.thread for pc in ps]
        key_lo = min(int(k.min()) for k in keys)         # keys of one pass span part of the range (a batch)
        universe = max(int(k.max()) for k in keys) + 1 - key_lo
        present = np.zeros(universe, bool)
        for k in keys:
            present[k - key_lo] = True
        lane_keys = np.flatnonzero(present) + key_lo
        n_lanes = len(lane_keys)
        # each key's lane rank (None: the key is its rank)
        rank_of = None if n_lanes == universe and not key_lo else np.cumsum(present) - 1
        if any(plan.groups[pc.group].op == "scoreboard" for pc in ps):
            pix = work.frag_pixel[lane_keys] if pk.threads == "fragment" else lane_keys
            warp_of_lane = _scoreboard_warps(pix, work.width, gpu)
            first_lane = np.searchsorted(warp_of_lane, np.arange(int(warp_of_lane[-1]) + 1))
            lane_in_warp = np.arange(n_lanes) - first_lane[warp_of_lane]
        else:
            warp_of_lane = lane_in_warp = None           # lanes fill warps in order: rank // ws, rank % ws
        n_warps = int(warp_of_lane[-1]) + 1 if warp_of_lane is not None else -(-n_lanes // ws)
        # triangle mapping: iteration j of a lane's loop is its triangle's j-th fragment (in thread order)
        j_of = None
        if mode == "triangle":
            frag_present = np.zeros(len(work.frag_prim), bool)
            for pc in ps:
                frag_present[pc.thread] = True
            fr = np.flatnonzero(frag_present)
            prim = work.frag_prim[fr]
            order = np.argsort(prim, kind="stable")
            sp = prim[order]
            rank = np.empty(len(fr), np.int64)
            rank[order] = rank_in_runs(sp)
            j_of = np.zeros(len(work.frag_prim), np.int64)
            j_of[fr] = rank
        lane_bits = _bits(ws)
        placed: list = []            # (threads, k, placement) of this pass's pieces: groups of one thread set share it
        for pc, key in zip(ps, keys):
            got = next((pl for th, kk, pl in placed if kk is None and pc.k is None and len(th) == len(pc.thread)
                        and np.array_equal(th, pc.thread)), None)
            if got is None:
                got = _place(pc, key, key_lo, rank_of, warp_of_lane, lane_in_warp, j_of, n_warps, ws, lane_bits,
                             pk.name)
                placed.append((pc.thread, pc.k, got))
            order, hi, w, j, start = got
            if order is not None:
                pc = pc.take(order)
            k = pc.k
            n = len(hi)
            op = OPS.index(plan.groups[pc.group].op)
            cls = int(OP_CLASS[op])
            at = row_at.get(cls, 0)
            inst.append((w[start] + warp0, j[start] if j is not None else np.zeros(len(start), np.int64),
                         np.full(len(start), pc.group, np.int64),
                         k[start] if k is not None else np.zeros(len(start), np.int64),
                         start + at, np.append(start[1:], n) + at, np.full(len(start), p, np.int64)))
            rows.setdefault(cls, []).append((op, pc.address, pc.nbytes, pc.thread))
            row_at[cls] = at + n
        pp = PassProgram(p, pk.name, pk.kind, None, n_lanes, operations=ops, operations_total=int(totals[p]))
        if mode == "fragment":           # the fixed-function rasterizer feeds the warps in triangle order
            first_lane = (np.arange(0, n_lanes, ws) if warp_of_lane is None
                          else np.searchsorted(warp_of_lane, np.arange(n_warps)))
            pp.triangles, position = _raster_positions(work, pk, lane_keys)
            pp.warp_triangles = np.maximum.reduceat(position, first_lane)
        elif mode == "triangle":
            pp.setup_cycles = gpu.raster.setup_instructions * gpu.core.issue_cycles
        pp.wi_start = np.arange(n_warps + 1) + warp0       # global warp numbers; made instruction offsets below
        passes.append(pp)
        warp0 += n_warps
    if inst:
        w, j, g, k, lo, hi, pa = (np.concatenate(c) for c in zip(*inst))
        order = np.lexsort((k, g, j, w))
        w, g, k, lo, hi, pa = w[order], g[order], k[order], lo[order], hi[order], pa[order]
    else:
        w = g = k = lo = hi = pa = np.zeros(0, np.int64)
    row_sets = {cls: Rows(parts) for cls, parts in rows.items()}
    warp_wi_start = np.searchsorted(w, np.arange(warp0 + 1))
    for pp in passes:
        pp.wi_start = warp_wi_start[pp.wi_start] if pp.lanes else np.zeros(1, np.int64)
    wi_op = np.array([OPS.index(gr.op) for gr in plan.groups], np.int64)[g] if len(g) else g
    wi_dep = np.array([gr.dep for gr in plan.groups], bool)[g] if len(g) else np.zeros(0, bool)
    return Program(passes, lo, hi, wi_op, OP_CLASS[wi_op], wi_dep, OP_PRODUCES[wi_op], w, pa, g, k,
                   row_sets, work.frag_pixel)


def _place(pc: _Piece, key, key_lo: int, rank_of, warp_of_lane, lane_in_warp, j_of, n_warps: int, ws: int,
           lane_bits: int, name: str):
    """Where the rows of piece ``pc`` go: (row order or None if already in place, instruction key, warp and
    fragment iteration of each row in that order, first row of each instruction)."""
    r = key if rank_of is None else rank_of[key - key_lo]
    w = div(r, ws) if warp_of_lane is None else warp_of_lane[r]
    j = j_of[pc.thread] if j_of is not None else None
    k = pc.k
    bw, bj = _bits(n_warps), _bits(int(j.max()) if j is not None else 0)
    bk = _bits(int(k.max()) if k is not None else 0)
    hi = w
    if j is not None:
        hi = (hi << bj) | j
    if k is not None:
        hi = (hi << bk) | k
    if bw + bj + bk + lane_bits > 62:
        raise GpusimError(f"pass '{name}' is too large to lower ({n_warps:,} warps, "
                          f"{int(j.max()) if j is not None else 0:,} fragments per triangle, "
                          f"{int(k.max()) if k is not None else 0:,} operations per thread); "
                          f"use --fidelity sampled|analytic")
    plain = j is None and k is None and warp_of_lane is None
    full = None if plain else (hi << lane_bits) | (mod(r, ws) if lane_in_warp is None else lane_in_warp[r])
    if plain:                        # one op per lane, lanes ascending: the rows are already in place
        in_order = len(r) < 2 or bool((r[1:] > r[:-1]).all())
    else:
        in_order = len(full) < 2 or bool((full[1:] >= full[:-1]).all())
    order = None
    if not in_order:
        order = np.argsort((hi << lane_bits) | mod(r, ws) if plain else full, kind="stable")
        hi, w = hi[order], w[order]
        j = None if j is None else j[order]
    return order, hi, w, j, run_starts(hi)


def _raster_positions(work: Workload, pk, lane_keys: np.ndarray) -> tuple[int, np.ndarray]:
    """Triangles the rasterizer takes in a graphics-pipeline geometry pass, and for each lane (fragment, in
    submission order) how many of them are rasterized by the time its own is.

    A pass submits the whole scene unless the scheme says it submits fewer
    (``Pass.primitives``: a batch). Primitive ids are the positions when the
    fragments come in primitive order over the whole scene (exact, triangles
    without fragments included); otherwise a primitive's position is the
    order of its first fragment, spread over the pass's triangles.
    """
    prim = work.frag_prim[lane_keys]
    total = submitted_triangles(pk, work)
    if pk.primitives is None and (len(prim) < 2 or bool((prim[1:] >= prim[:-1]).all())):
        return total, prim + 1
    _, first, inverse = np.unique(prim, return_index=True, return_inverse=True)
    rank = np.empty(len(first), np.int64)
    rank[np.argsort(first)] = np.arange(1, len(first) + 1)
    distinct = max(1, len(first))
    return total, -(-rank[inverse] * max(total, distinct) // distinct)


def submitted_triangles(pk, work: Workload) -> int:
    """Triangles a geometry pass submits to the rasterizer: the whole scene unless the scheme's pass says
    fewer (``Pass.primitives``, a k-buffer batch)."""
    return pk.primitives if pk.primitives is not None else work.triangles


def _scoreboard_warps(pixel: np.ndarray, width: int, gpu) -> np.ndarray:
    """Warp of each lane when dispatch packs no two fragments of one scoreboard cell into a warp.

    The dispatcher fills a warp in submission order and starts a new one at a
    full warp or at a fragment whose cell the warp already holds (seed 004
    section 3.1.1: overlapping fragments go to different packets).
    """
    cell = scoreboard_cell(pixel, width, gpu.scoreboard.granularity)
    out = np.empty(len(cell), np.int64)
    w, held = 0, set()
    ws = gpu.core.warp_size
    for i, c in enumerate(cell.tolist()):
        if len(held) == ws or c in held:
            w += 1
            held = set()
        held.add(c)
        out[i] = w
    return out


def scoreboard_cell(pixel: np.ndarray, width: int, granularity: int) -> np.ndarray:
    """Cell of the coarse in-flight image holding each pixel (granularity x granularity pixels)."""
    x, y = pixel % width, pixel // width
    cells_x = -(-width // granularity)
    return (y // granularity) * cells_x + x // granularity
