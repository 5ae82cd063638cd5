"""Lowering a scheme's operations to a program of warp instructions (gpusim.hw.program).

The input is the scheme's :class:`~gpusim.opplan.OpPlan`, the grouped form of
its OpStream ("these threads issue ``count`` operations ``op`` on
``structure``", in program order). Lowering works group by group and never
materialises the row-sorted OpStream: the rows it makes are those of the warp
instructions, grouped by instruction.

A *lane* is a thread of a pass: a fragment, a pixel or a memory entry, or, with
the ``triangle`` thread mapping, a triangle whose thread loops over its
fragments (FreePipe, seed 000 section 3) after a :class:`Compute` instruction
of triangle setup. A warp is ``warp_size`` consecutive lanes in submission
order, except a pixel shader's: its fragments spread evenly over
``ceil(4 x quads / warp_size)`` warps (helper lanes of partial 2x2 quads
counted) or, with ``raster.warp_packing = "tiles"``, in the rasterizer's
emission order (:func:`gpusim.hw.raster.emission`), dealt by screen tile to
the tiles' owners, a warp holding up to ``warp_size / 4`` quads of one
owner's tiles (:func:`fragment_lanes`). Warps
execute SIMT, group after group in program order: a group whose lanes issue
``count`` operations is a loop of ``max(count)`` warp instructions over the
warp's lanes, instruction ``k`` carrying the lanes with ``count > k``
(the others are masked off). With the triangle mapping, the thread's loop over
its fragments is the outer loop: iteration ``j`` runs every group for the
``j``-th fragment of each lane's triangle. So a warp's instructions run in the
order (fragment iteration ``j``, group, ``k``).

Each operation goes to the unit registered to take it from the core
(:func:`gpusim.hw.unit.entry_unit`). Everything here is vectorised numpy; the
SIMT cores (gpusim.hw.core) then walk warps and instructions.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

from gpusim.errors import GpusimError
from gpusim.hw.atomic import DRAM_RMW_BYTES
from gpusim.hw.program import COMPUTE, PassProgram, Program, Rows
from gpusim.hw.raster import INDEX_BYTES, bbox_pixels, emission, quad_ids, screen_quads
from gpusim.hw.rop import framebuffer_traffic
from gpusim.hw.scoreboard import scoreboard_cell
from gpusim.hw.unit import div, entry_unit, interleave, mod
from gpusim.jit import compiled_once
from gpusim.metrics.composite import run_starts
from gpusim.opplan import OPS, OpPlan, expand_counts
from gpusim.schemes.common.arrays import lex_sorted, rank_in_runs, split_by
from gpusim.schemes.common.reorder import submitted_primitives

#: operations whose result a later dependent operation waits for
PRODUCES = frozenset({"load", "rmw_read", "atomic_min", "atomic_max", "atomic_inc", "atomic_exch",
                      "depth_test", "stencil", "scoreboard"})
OP_PRODUCES = np.array([o in PRODUCES for o in OPS])
#: byte addresses of the software rasterizer's index and vertex buffers, above every scheme structure (16 and
#: 32 GiB) and within the 2^36 segments the memory path's request keys hold
INDEX_BASE, VERTEX_BASE = 1 << 34, 1 << 35


class Workload:
    """What the hardware replays: the scheme's plan and where its structures live, the screen,
    and each fragment thread's pixel and triangle.

    ``frag_pixel[t]`` and ``frag_prim[t]`` are for fragment thread ``t`` (the
    scheme's submission order).
    """

    def __init__(self, plan: OpPlan, bases: dict[str, int], width: int, height: int, frag_pixel,
                 frag_prim, triangles: int | None = None):
        """``frag_pixel`` and ``frag_prim``: arrays, or callables making them when first needed (the analytic
        level never needs the pixels)."""
        self.plan, self.bases = plan, bases
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
                   pick(lambda: trace.prim), scene_triangles(trace))

    @property
    def operations(self) -> int:
        return self.plan.total_ops()

    def emission(self, tile: int, owners: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """:func:`gpusim.hw.raster.emission` of the fragment threads (their rasterizer emission order, their
        tiles' owners and their quads' keys), made once per tile size and owner count."""
        key = f"emission{tile}x{owners}"
        if key not in self._made:
            self._made[key] = emission(self.frag_prim, self.frag_pixel, self.width, self.height, tile, owners)
        return self._made[key]


def scene_triangles(trace) -> int:
    """Triangles the scene submits: the trace's ``primitives`` metadata (the rasterizer's count, triangles that
    cover no pixel included) when it has one that covers its primitive ids, else the highest id + 1 (the count
    the k-buffer's batches are made of, gpusim.schemes.common.reorder.submitted_primitives)."""
    return submitted_primitives(trace)


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
    instructions: np.ndarray | None = None     # a compute group's ALU instructions per row (None: memory)

    def take(self, idx: np.ndarray) -> "_Piece":
        """The rows ``idx`` of this piece (in that order)."""
        return _Piece(self.group, self.pass_index, self.thread[idx],
                      None if self.k is None else self.k[idx], self.address[idx],
                      self.nbytes if np.isscalar(self.nbytes) else self.nbytes[idx],
                      None if self.instructions is None else self.instructions[idx])

    @property
    def operations(self) -> int:
        """Memory operations of the piece (ALU work has none)."""
        return 0 if self.instructions is not None else len(self.thread)


def pass_operations(plan: OpPlan) -> np.ndarray:
    """Memory operations of each pass of ``plan``, expanding only groups whose passes a function gives; counted
    once per plan (kept on it, for as long as it has these groups and passes: a sampled run lowers each of its
    samples a chunk of passes at a time, and counting them again for each had taken a fifth of its time)."""
    known = plan.__dict__.get("_pass_operations")
    if known is not None and known[0] == (len(plan.groups), len(plan.passes)):
        return known[1].copy()
    out = _count_pass_operations(plan)
    plan.__dict__["_pass_operations"] = ((len(plan.groups), len(plan.passes)), out.copy())
    return out


def _count_pass_operations(plan: OpPlan) -> np.ndarray:
    out = np.zeros(len(plan.passes), np.int64)
    for g in plan.memory_groups:
        if g.seq_pass is not None:            # op s of every thread with more than s of them, in seq_pass[s]
            fewer = np.cumsum(np.bincount(g.count))         # threads with at most s ops
            out[g.seq_pass[:len(fewer) - 1]] += len(g.count) - fewer[:-1]
        elif g.pass_fn is not None:
            out += np.bincount(np.asarray(g.pass_of(*g.expand_ops()), np.int64), minlength=len(out))
        elif np.isscalar(g.pass_index):
            out[int(g.pass_index)] += g.total
        else:
            out += np.bincount(g.pass_index, weights=g.count, minlength=len(out)).astype(np.int64)
    return out


def ops_in_passes(g, lo: int, hi: int) -> tuple[np.ndarray, np.ndarray]:
    """``(i, seq)`` of group ``g``'s operations in passes ``lo`` to ``hi - 1``, in the order
    :meth:`~gpusim.opplan.OpGroup.expand_ops` gives them; only those are expanded where the group says
    where its passes fall (a pass of its own, ``seq_pass``, a pass per thread)."""
    count = g.count
    none = np.zeros(0, np.int64)
    if g.seq_pass is not None:
        s0, s1 = (int(s) for s in np.searchsorted(g.seq_pass, [lo, hi]))
        who = np.flatnonzero(count > s0) if s1 > s0 else none
        m = np.minimum(count[who], s1) - s0
    elif g.pass_fn is None and not np.isscalar(g.pass_index):
        s0, who = 0, np.flatnonzero((g.pass_index >= lo) & (g.pass_index < hi))
        m = count[who]
    elif g.pass_fn is None:
        return g.expand_ops() if lo <= int(g.pass_index) < hi else (none, none)
    else:
        i, seq = g.expand_ops()
        p = np.asarray(g.pass_of(i, seq), np.int64)
        sel = np.flatnonzero((p >= lo) & (p < hi))
        return i[sel], seq[sel]
    return expand_counts(who, m, s0)


def _pass_major_ops(g, passes: tuple[int, int] | None) -> tuple[np.ndarray, np.ndarray, list[tuple[int, int, int]]]:
    """``(i, seq, runs)`` of a group with a ``seq_pass`` (op ``s`` of every thread in pass ``seq_pass[s]``,
    strictly ascending) in passes ``passes[0]`` to ``passes[1] - 1`` (all by default): its operations a pass at
    a time, each pass's threads in order, and each pass's (pass, first row, end row). The rows
    :func:`ops_in_passes` gives, in the order :func:`split_by` of their passes puts them, without the sort."""
    count = g.count
    top = int(count.max()) if len(count) else 0
    s0, s1 = (0, top) if passes is None else (int(x) for x in np.searchsorted(g.seq_pass, passes))
    steps = range(s0, min(s1, top))
    who = [np.flatnonzero(count > s) for s in steps]
    sizes = np.array([len(w) for w in who], np.int64)
    i = np.concatenate(who) if who else np.zeros(0, np.int64)
    seq = np.repeat(np.arange(s0, s0 + len(sizes), dtype=np.int64), sizes)
    ends = np.cumsum(sizes)
    runs = [(int(g.seq_pass[s]), int(e - m), int(e)) for s, m, e in zip(steps, sizes, ends) if m]
    return i, seq, runs


def _group_pieces(gi: int, g, bases: dict[str, int], passes: tuple[int, int] | None = None) -> list[_Piece]:
    """Rows of group ``g``, split by pass: thread, loop iteration, address, bytes; only those of passes
    ``passes[0]`` to ``passes[1] - 1`` when given."""
    n = len(g.thread)
    threads = g.thread_ids()
    runs = None
    if g.seq_pass is not None:                     # a pass per operation of a thread: made a pass at a time
        i, seq, runs = _pass_major_ops(g, passes)
    else:
        i, seq = g.expand_ops() if passes is None else ops_in_passes(g, *passes)
    if not len(i):
        return []
    instr = np.asarray(g.instructions)[i] if g.is_compute else None
    addr = np.asarray(g.offset(i, seq), np.int64)
    if not g.is_compute:                           # (a compute group's offsets are zeros: not copied again)
        addr = addr + bases[g.structure]
    nbytes = np.asarray(g.bytes(i, seq), np.int32) if callable(g.bytes) else int(g.bytes)
    if runs is not None:                           # each pass's rows lie together, its threads in order
        # copies, not views: a piece kept holds its own rows, not the whole group's
        return [_Piece(gi, p, threads[i[a:b]], None, addr[a:b].copy(),
                       nbytes if np.isscalar(nbytes) else nbytes[a:b].copy(),
                       None if instr is None else instr[a:b].copy()) for p, a, b in runs]
    pass_of = g.pass_of(i, seq)
    if np.isscalar(pass_of):
        single = n > 0 and int(g.count.min()) == 1 and int(g.count.max()) == 1   # every op is its thread's first
        whole = single and len(i) == n             # every thread's one operation, in thread order
        return [_Piece(gi, int(pass_of), threads if whole else threads[i], None if single else seq, addr, nbytes,
                       instr)]
    pieces = []
    for p, sel in split_by(np.asarray(pass_of, np.int64)):
        ii = i[sel]
        # iteration inside this pass: position among the thread's operations of the group in the pass
        k = rank_in_runs(ii)
        pieces.append(_Piece(gi, int(p), threads[ii], k if k.any() else None, addr[sel],
                             nbytes if np.isscalar(nbytes) else nbytes[sel], None if instr is None else instr[sel]))
    return pieces


def _bits(n: int) -> int:
    return max(1, int(n).bit_length())


class Pieces(list):
    """:func:`plan_pieces`: a list of pieces, and what samples of the run share, counted once (by
    :func:`share_pieces`, or by the first sample lowered): ``loads``, each piece's shared unit instances
    and the whole run's load on them (samples of one run on one GPU's memory and ROPs); ``words``, the
    run's atomic words and the operations on each."""

    loads: dict | None = None
    words: tuple | None = None
    counted_words: bool = False
    census: "Census | None" = None          # the whole run's counts, where the pieces hold only some rows
    totals: np.ndarray | None = None        # then: the run's memory operations in each pass


class Census:
    """What a sample needs to know of every operation of a run (or of a chunk of its passes) that
    :func:`plan_pieces` counts, where the pieces keep only the rows some sample may keep: the run's load on
    each shared unit's instances in each pass (:func:`_occupancy`), its atomic words and the operations on
    each (``Program.hold_scale``)."""

    def __init__(self, plan: OpPlan, gpu, passes: tuple[int, int] | None = None):
        self.gpu = gpu
        self.p_first, p_end = passes if passes is not None else (0, len(plan.passes))
        self.n_pass = p_end - self.p_first
        self.every: dict[str, np.ndarray] = {}
        self.words: list[np.ndarray] = []

    def add(self, op: str, pass_of, address: np.ndarray, nbytes) -> None:
        """Count a memory group's operations: their passes (the plan's numbers), addresses and bytes."""
        p = pass_of - self.p_first
        for name, n, key, weight in _unit_keys(op, p, address, nbytes, self.gpu):
            self.every[name] = self.every.get(name, 0) + unit_load(key, weight, self.n_pass * n)
        if entry_unit(op) == "atomic":
            self.words.append(_word_key(address, p))

    def word_ops(self) -> tuple[np.ndarray, np.ndarray] | None:
        """:func:`_word_ops` of the run's atomic operations."""
        return np.unique(np.concatenate(self.words), return_counts=True) if self.words else None


def share_pieces(pieces: Pieces, plan: OpPlan, gpu, n_pass: int) -> None:
    """Count what the samples of ``pieces`` (of a program of ``n_pass`` passes) share (:class:`Pieces`) now,
    before samples are lowered in processes of their own (each would count it again)."""
    _run_loads(pieces, plan, gpu, n_pass)
    _run_words(pieces, plan)


def _run_words(pieces: list[_Piece], plan: OpPlan) -> tuple[np.ndarray, np.ndarray] | None:
    """:func:`_word_ops` of the atomic pieces of ``pieces``, counted once per :class:`Pieces`."""
    if isinstance(pieces, Pieces) and pieces.counted_words:
        return pieces.words
    if isinstance(pieces, Pieces) and pieces.census is not None:
        words = pieces.census.word_ops()
    else:
        words = _word_ops([pc for pc in pieces if pc.instructions is None
                           and entry_unit(plan.groups[pc.group].op) == "atomic"])
    if isinstance(pieces, Pieces):
        pieces.words, pieces.counted_words = words, True
    return words


def plan_pieces(work: Workload, passes: tuple[int, int] | None = None) -> Pieces:
    """The rows of each group in each pass (of ``passes``, numbered from its first), before lanes are known;
    :func:`lower` takes them (``pieces``) when it lowers several samples of one run."""
    p_first = passes[0] if passes is not None else 0
    pieces = Pieces(pc for gi, g in enumerate(work.plan.groups) for pc in _group_pieces(gi, g, work.bases, passes))
    for pc in pieces:                  # pass numbers of this program
        pc.pass_index -= p_first
    return pieces


def check_operations(plan, gpu, passes: tuple[int, int] | None = None) -> None:
    """Refuse, in one line with advice, a run (or its passes ``passes[0]`` to ``passes[1] - 1``) that would lower
    more than ``runner.max_operations`` operations; checked before anything is built for them."""
    total_ops = plan.total_ops() if passes is None else int(pass_operations(plan)[passes[0]:passes[1]].sum())
    limit = gpu.runner.max_operations
    if total_ops > limit:
        raise GpusimError(f"the run would lower {total_ops:,} operations, over runner.max_operations = {limit:,} "
                          f"(the event model needs about 80 bytes per operation); use --fidelity analytic, which "
                          f"estimates the run without lowering, or a smaller trace")


def sample_masks(pieces: list[_Piece], keep, p_first: int = 0) -> list[np.ndarray]:
    """The rows of each piece a sample keeps: ``keep(pass, threads)`` (see :func:`lower`) asked once per pass
    (numbered from the plan's pass ``p_first``) for the threads of each of its pieces."""
    masks: list = [None] * len(pieces)
    for p, js in split_by(np.array([pc.pass_index for pc in pieces], np.int64)):
        for j, m in zip(js, keep(p + p_first, [pieces[j].thread for j in js])):
            masks[j] = m
    return masks


def lower(work: Workload, gpu, keep=None, passes: tuple[int, int] | None = None,
          pieces: list[_Piece] | None = None, warps=None) -> Program:
    """Warp instructions of ``work.plan`` on ``gpu``.

    ``keep(pass_index, threads) -> masks`` selects threads (the sampled
    fidelity, gpusim.hw.sample): given a pass and the threads of each of its
    groups, a mask per group; ``keep.triangles(ids)`` (when it has one) picks
    the software rasterizer's triangles that cover no pixel. The kept share of
    each shared unit's load and of the operations on an atomic word is
    recorded (``Program.occupancy``, ``Program.hold_scale``). ``passes``:
    only the plan's passes ``passes[0]`` to ``passes[1] - 1``, as a program of
    their own (its pass 0 is the plan's ``passes[0]``); their instructions are
    those the whole program gives them. ``pieces``: :func:`plan_pieces` of the
    same ``work`` and ``passes``, made once for several samples. ``warps(pass_index, lane_keys)``: in a
    graphics-pipeline fragment pass packed in submission order, each lane's warp (numbered from 0, ascending)
    where the pieces keep whole warps of the run's (:func:`gpusim.hw.sample.run_traffic`), or None to pack
    the lanes as they are.
    """
    plan = work.plan
    p_first, p_end = passes if passes is not None else (0, len(plan.passes))
    check_operations(plan, gpu, passes)
    ws = gpu.core.warp_size
    n_pass = p_end - p_first
    modes = [thread_mapping(gpu, p) for p in plan.passes[p_first:p_end]]
    shared = pieces if pieces is not None else plan_pieces(work, passes)
    pieces = list(shared)
    totals = getattr(shared, "totals", None)
    if totals is None:
        totals = np.zeros(n_pass, np.int64)
        for pc in pieces:
            totals[pc.pass_index] += pc.operations
    if keep is not None:
        masks = sample_masks(pieces, keep, p_first)
        words = _run_words(shared, plan)
        occupancy, own_load, reached = _occupancy(shared, masks, plan, gpu, n_pass)
        for j, (pc, m) in enumerate(zip(pieces, masks)):
            if not m.all():
                pieces[j] = pc.take(np.flatnonzero(m))
    else:
        words = occupancy = own_load = reached = None
    by_pass: list[list[_Piece]] = [[] for _ in range(n_pass)]
    for pc in pieces:
        if len(pc.thread):
            by_pass[pc.pass_index].append(pc)

    # the units the program issues to, in plan order (those of the groups with operations here)
    units = tuple(dict.fromkeys(entry_unit(plan.groups[pc.group].op) for pc in pieces
                                if pc.instructions is None and len(pc.thread)))
    passes, inst = [], []
    rows: dict[str, list] = {}         # unit -> row arrays of its pieces
    atomic_pass: list[int] = []        # the pass of each of the atomic unit's row arrays
    row_at: dict[str, int] = {}
    software = []                      # software-rasterizer passes: (pass, warps, setup cycles per warp,
                                       # triangle per lane)
    warp0 = 0
    for p, pk in enumerate(plan.passes[p_first:p_end]):
        mode, ps = modes[p], by_pass[p]
        ops = sum(pc.operations for pc in ps)
        if not ps:
            passes.append(PassProgram(p, pk.name, pk.kind, np.zeros(1, np.int64), 0, warp0,
                                      operations=0, operations_total=int(totals[p])))
            continue
        # lanes of the pass: distinct lane keys in submission order
        keys = [work.frag_prim[pc.thread] if mode == "triangle" else pc.thread for pc in ps]
        key_lo = min(int(k.min()) for k in keys)         # keys of one pass span part of the range (a batch)
        universe = max(int(k.max()) for k in keys) + 1 - key_lo
        if mode == "triangle" and pk.primitives is None:
            # a software pipeline runs a thread per submitted triangle, those that cover no pixel included
            # (a sample keeps its share of those)
            key_lo, universe = 0, max(universe + key_lo, work.triangles)
        present = np.zeros(universe, bool)
        for k in keys:
            present[k - key_lo] = True
        if mode == "triangle" and pk.primitives is None:
            if keep is None or not hasattr(keep, "triangles"):
                present[:] = True
            else:
                present |= keep.triangles(np.arange(universe))
        lane_keys = np.flatnonzero(present) + key_lo
        n_lanes = len(lane_keys)
        rank_of = _lane_ranks(present, lane_keys, key_lo)
        front = None                     # a pixel shader's lanes as the rasterizer feeds them (FragmentLanes)
        if any(plan.groups[pc.group].op == "scoreboard" for pc in ps):
            pix = work.frag_pixel[lane_keys] if pk.threads == "fragment" else lane_keys
            warp_of_lane = scoreboard_warps(pix, work.width, gpu)
        elif mode == "fragment" and gpu.raster.warp_packing == "submission":
            warp_of_lane, quads = submission_warps(work, gpu, lane_keys)
            given = warps(p, lane_keys) if warps is not None else None
            if given is not None:
                warp_of_lane = given
            front = FragmentLanes(lane_keys, warp_of_lane, _raster_positions(work, pk, lane_keys)[1], quads)
        elif mode == "fragment":
            # the rasterizer's quads dealt by tile to their owners, each packing its own into warps of up to
            # warp_size / 4 quads (4 shader lanes per quad, helper lanes of partial quads included)
            got = fragment_lanes(work, gpu, lane_keys, pk)
            if len(got.keys) > 1 and not bool((got.keys[1:] > got.keys[:-1]).all()):
                ranks = np.zeros(universe, np.int64)
                ranks[got.keys - key_lo] = np.arange(n_lanes)
                rank_of = lambda key, ranks=ranks: ranks[key - key_lo]     # noqa: E731
            lane_keys, warp_of_lane, front = got.keys, got.warp, got
        else:
            warp_of_lane = None                          # lanes fill warps in order: rank // ws, rank % ws
        if warp_of_lane is not None:
            first_lane = np.searchsorted(warp_of_lane, np.arange(int(warp_of_lane[-1]) + 1))
            lane_in_warp = np.arange(n_lanes) - first_lane[warp_of_lane]
        else:
            first_lane, lane_in_warp = np.arange(0, n_lanes, ws), None
        n_warps = int(warp_of_lane[-1]) + 1 if warp_of_lane is not None else -(-n_lanes // ws)
        # triangle mapping: iteration j of a lane's loop is its triangle's j-th fragment (in thread order)
        j_of = None
        if mode == "triangle":
            frag_present = np.zeros(len(work.frag_prim), bool)
            for pc in ps:
                frag_present[pc.thread] = True
            fr = np.flatnonzero(frag_present)
            prim = work.frag_prim[fr]
            # each warp: load its triangles' vertices, then set up and scan the largest bounding box among them
            bbox = bbox_pixels(prim - key_lo, work.frag_pixel[fr], work.width, universe)[lane_keys - key_lo]
            r = gpu.raster
            setup_cycles = gpu.core.alu_cycles(r.setup_instructions + r.pixel_instructions
                                               * np.maximum.reduceat(bbox, first_lane))
            software.append((p, np.arange(warp0, warp0 + n_warps), setup_cycles, lane_keys))
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
            order, w, j, start = got.order, got.warp, got.iteration, got.starts
            if order is not None:
                pc = pc.take(order)
            k = pc.k
            n = len(w)
            columns = (w[start] + warp0, j[start] if j is not None else np.zeros(len(start), np.int64),
                       np.full(len(start), pc.group, np.int64),
                       k[start] if k is not None else np.zeros(len(start), np.int64))
            if pc.instructions is not None:      # ALU work: the instruction's busiest lane decides its cycles
                busiest = gpu.core.alu_cycles(np.maximum.reduceat(pc.instructions, start))
                inst.append((*columns, np.zeros(len(start), np.int64), np.zeros(len(start), np.int64),
                             np.full(len(start), p, np.int64), busiest))
                continue
            unit = entry_unit(plan.groups[pc.group].op)
            at = row_at.get(unit, 0)
            inst.append((*columns, start + at, np.append(start[1:], n) + at, np.full(len(start), p, np.int64),
                         np.full(len(start), gpu.core.op_issue_cycles, np.int64)))
            rows.setdefault(unit, []).append((OPS.index(plan.groups[pc.group].op), pc.address, pc.nbytes, pc.thread))
            if unit == "atomic":
                atomic_pass.append(p)
            row_at[unit] = at + n
        pp = PassProgram(p, pk.name, pk.kind, None, n_lanes, warp0, operations=ops, operations_total=int(totals[p]))
        if mode == "fragment":           # the front end feeds the warps in triangle order
            if front is None:
                front = FragmentLanes(lane_keys, warp_of_lane, _raster_positions(work, pk, lane_keys)[1],
                                      _quads_so_far(work, lane_keys))
            pp.triangles = submitted_triangles(pk, work)
            pp.warp_triangles = np.maximum.reduceat(front.position, first_lane)
            pp.quads = int(front.quads.max())
            pp.warp_quads = np.maximum.reduceat(front.quads, first_lane)
        pp.wi_start = np.arange(n_warps + 1) + warp0       # global warp numbers; made instruction offsets below
        passes.append(pp)
        warp0 += n_warps
    if inst:
        w, j, g, k, lo, hi, pa, wi_cycles = (np.concatenate(c) for c in zip(*inst))
        order = np.lexsort((k, g, j, w))
        w, g, k, lo, hi, pa, wi_cycles = (a[order] for a in (w, g, k, lo, hi, pa, wi_cycles))
    else:
        w = g = k = lo = hi = pa = wi_cycles = np.zeros(0, np.int64)
    op_of_group = np.array([-1 if gr.is_compute else OPS.index(gr.op) for gr in plan.groups] or [0], np.int64)
    unit_of_group = np.array([COMPUTE if gr.is_compute or entry_unit(gr.op) not in units
                              else units.index(entry_unit(gr.op)) for gr in plan.groups]
                             or [0], np.int64)
    dep_of_group = np.array([gr.dep for gr in plan.groups] or [False], bool)
    wi_op, wi_unit, wi_dep = op_of_group[g], unit_of_group[g], dep_of_group[g]
    if software:                     # each warp of a software-rasterizer pass first loads and sets up its triangles
        if max(work.bases.values(), default=0) >= INDEX_BASE:
            raise GpusimError(f"the scheme's structures reach past {INDEX_BASE >> 30} GiB, where the software "
                              f"rasterizer's vertex buffers sit; use a smaller trace or fewer layers")
        if "coalescer" not in units:
            units += ("coalescer",)
        mem, vb = units.index("coalescer"), 3 * gpu.raster.vertex_bytes
        sw = np.concatenate([s[1] for s in software])
        pass_of_warp = np.concatenate([np.full(len(s[1]), s[0]) for s in software])
        setup = np.concatenate([s[2] for s in software])
        # inserted before each warp's first instruction, last first: the index load, the vertex load (it needs
        # the indices), then setup (it needs the vertices)
        prefix = [(-1, 0, 0, 0, -1, COMPUTE, True, setup)]
        for base, nb, dep in ((VERTEX_BASE, vb, True), (INDEX_BASE, INDEX_BYTES, False)):
            at = row_at.get("coalescer", 0)
            load_lo, load_hi = [], []
            for _, warps, _, tri in software:
                rows.setdefault("coalescer", []).append((OPS.index("load"), base + tri * nb, nb, tri))
                first = at + np.arange(len(warps)) * ws
                load_lo.append(first)
                load_hi.append(np.minimum(first + ws, at + len(tri)))
                at += len(tri)
            row_at["coalescer"] = at
            prefix.append((-1, 0, np.concatenate(load_lo), np.concatenate(load_hi), OPS.index("load"), mem, dep,
                           gpu.core.op_issue_cycles))
        # per inserted instruction: warp, pass, group, k, row lo, row hi, op, unit, depends, issue cycles
        for values in prefix:
            at_w = np.searchsorted(w, sw)
            w, pa, g, k, lo, hi, wi_op, wi_unit, wi_dep, wi_cycles = (
                np.insert(col, at_w, v) for col, v in zip((w, pa, g, k, lo, hi, wi_op, wi_unit, wi_dep, wi_cycles),
                                                          (sw, pass_of_warp, *values)))
    row_sets = {unit: Rows(parts) for unit, parts in rows.items()}
    warp_wi_start = np.searchsorted(w, np.arange(warp0 + 1))
    for pp in passes:
        pp.wi_start = warp_wi_start[pp.wi_start] if pp.lanes else np.zeros(1, np.int64)
    return Program(passes, units, lo, hi, wi_op, wi_unit, wi_cycles, wi_dep, (wi_op >= 0) & OP_PRODUCES[wi_op],
                   w, pa, g, k, row_sets, work.frag_pixel,
                   occupancy=occupancy, own_load=own_load, reached=reached,
                   hold_scale=_hold_scale(words, rows.get("atomic", []), atomic_pass))


def _occupancy(pieces: Pieces, masks: list[np.ndarray], plan: OpPlan, gpu,
               n_pass: int) -> tuple[dict | None, dict | None, dict | None]:
    """A sample's ``Program.occupancy``: per shared unit, (passes, instances) factors, the whole run's load on
    each instance in each pass (bytes on the memory partitions, the ROPs' framebuffer reads and writes among
    them; operations on the atomic units and ROPs) over
    the kept threads' (1 where they put none); None when every factor is 1. And ``Program.own_load``, the kept
    threads' load there (for the same units). The run's loads are counted once per ``pieces``
    (``Pieces.loads``). And ``Program.reached``: per such unit and pass, the share of the run's load there on
    the instances the kept threads reach (:func:`reached_share`)."""
    cache = _run_loads(pieces, plan, gpu, n_pass)
    every, kept = cache["every"], {}
    for entries, m in zip(cache["keys"], masks):
        for name, n, key, weight in entries:
            kept[name] = kept.get(name, 0) + np.bincount(key[m], weights=weight[m], minlength=n_pass * n)
    out = {name: np.where(k > 0, every[name] / np.maximum(k, 1e-9), 1.0).reshape(n_pass, -1)
           for name, k in kept.items()}
    out = {k: v for k, v in out.items() if not (v == 1).all()}
    reached = {k: reached_share(every[k].reshape(n_pass, -1), kept[k].reshape(n_pass, -1)) for k in out}
    return out or None, {k: kept[k].reshape(n_pass, -1) for k in out} or None, reached or None


def reached_share(run: np.ndarray, mine: np.ndarray) -> np.ndarray:
    """Per pass, the share of the run's load ``run`` (passes, instances) on the instances a sample's own load
    ``mine`` reaches (1 where the run has none): a sample of a few tiles reaches only some instances of a unit
    in a pass, and the run's load on the others stands for nothing in it (``Program.reached``)."""
    total = run.sum(axis=1)
    there = np.where(mine > 0, run, 0.0).sum(axis=1)
    return np.where(total > 0, there / np.where(total > 0, total, 1.0), 1.0)


def _run_loads(pieces, plan: OpPlan, gpu, n_pass: int) -> dict:
    """Each piece's [(shared unit, instances, instance key per row, weight per row)] and the run's load on each
    instance in each pass (``every``: the census's where the pieces hold only some rows), counted once per
    :class:`Pieces` (:func:`_occupancy`)."""
    cache = pieces.loads if isinstance(pieces, Pieces) and pieces.loads is not None else None
    if cache is None:
        census = pieces.census if isinstance(pieces, Pieces) else None
        cache = {"keys": [], "every": {} if census is None else census.every}
        for pc in pieces:
            entries = ([] if pc.instructions is not None
                       else _unit_keys(plan.groups[pc.group].op, pc.pass_index, pc.address, pc.nbytes, gpu))
            cache["keys"].append(entries)
            if census is None:
                for name, n, key, weight in entries:
                    cache["every"][name] = cache["every"].get(name, 0) + unit_load(key, weight, n_pass * n)
        if isinstance(pieces, Pieces):
            pieces.loads = cache
    return cache


def _unit_keys(op: str, pass_index, address: np.ndarray, nbytes, gpu) -> list[tuple]:
    """The shared units operations ``op`` load, each (name, instances, instance key per row: pass x instances
    + instance, load per row): the memory partitions (bytes), the atomic units and ROPs (one per operation);
    a ROP's framebuffer reads and writes load the memory partitions too, and so do atomics that read and
    write their sectors in DRAM (``atomic.dram_rmw``)."""
    mem = gpu.memory
    P = mem.partitions
    # (unit, instances, load per operation, load per byte of it)
    instances = {"coalescer": (("memory", P, 0.0, 1.0),),
                 "atomic": (("atomic", P, 1.0, 0.0),) + ((("memory", P, float(DRAM_RMW_BYTES), 0.0),)
                                                         if gpu.atomic.dram_rmw else ()),
                 "rop": (("rop", gpu.rop.units, 1.0, 0.0),) + ((("memory", P, 0.0, 2.0),)
                                                                if framebuffer_traffic(gpu) else ())}
    out = []
    for name, n, per_op, per_byte in instances.get(entry_unit(op), ()):
        key = np.asarray(pass_index, np.int64) * n + interleave(address, mem.interleave_bytes, n)
        weight = np.broadcast_to(per_op + per_byte * np.asarray(nbytes, np.float64), key.shape)
        out.append((name, n, key, weight))
    return out


def unit_load(key: np.ndarray, weight: np.ndarray, size: int) -> np.ndarray:
    """The load on each of ``size`` unit instances (keys, :func:`_unit_keys`) of rows ``key`` each of ``weight``:
    a count times the one weight where every row weighs the same (a broadcast), far faster than weighing each."""
    if weight.ndim == 1 and len(weight) and weight.strides == (0,):
        return np.bincount(key, minlength=size) * float(weight[0])
    return np.bincount(key, weights=weight, minlength=size)


def memory_load(op: str, address: np.ndarray, nbytes, gpu) -> tuple[np.ndarray, np.ndarray] | None:
    """The memory partitions' load (:func:`_unit_keys`) of operations ``op`` on ``address`` of ``nbytes`` each:
    (each row's partition, its load in bytes), or None where they load none."""
    for name, _, key, weight in _unit_keys(op, 0, address, nbytes, gpu):
        if name == "memory":
            return key, weight
    return None


def _word_key(address, pass_index: int) -> np.ndarray:
    """An atomic word in a pass, as one integer (addresses stay under 2**44 bytes)."""
    return np.asarray(address, np.int64) + (np.asarray(pass_index, np.int64) << 44)


def _word_ops(pieces: list[_Piece]) -> tuple[np.ndarray, np.ndarray] | None:
    """The atomic words (word key per pass, sorted) of the whole run and the operations on each."""
    if not pieces:
        return None
    return np.unique(np.concatenate([_word_key(pc.address, pc.pass_index) for pc in pieces]), return_counts=True)


def _hold_scale(words, parts: list, passes: list[int]) -> np.ndarray | None:
    """Per kept atomic row, in the atomic unit's row order: the whole run's operations on its word in its pass
    over the sample's (``words``: :func:`_word_ops` of the whole run); None when the sample keeps every
    operation of each word it touches, or is no sample."""
    if words is None or not parts:
        return None
    kept = np.concatenate([_word_key(part[1], p) for part, p in zip(parts, passes)])
    mine, n_kept = np.unique(kept, return_counts=True)
    ratio = words[1][np.searchsorted(words[0], kept)] / n_kept[np.searchsorted(mine, kept)]
    return None if (ratio == 1).all() else ratio


class Placement(NamedTuple):
    """Where a piece's rows go in the warps' instructions."""

    order: np.ndarray | None       # the rows in instruction order (None: already in it)
    warp: np.ndarray               # each row's warp (in that order)
    iteration: np.ndarray | None   # each row's fragment iteration (triangle mapping), or None
    starts: np.ndarray             # the first row of each instruction


def _lane_ranks(present: np.ndarray, lane_keys: np.ndarray, key_lo: int):
    """Each key's lane rank, its position among ``lane_keys`` (the ascending keys ``present`` marks, from
    ``key_lo``), as a function of an array of keys; None where every key of the range is a lane (the key is its
    rank). A sample's few lanes spread over the run's range are looked up, not ranked over the whole range (its
    cumulative sum, once per pass of every sample, had taken a fifth of a multi-pass scheme's sampled run)."""
    n_lanes, universe = len(lane_keys), len(present)
    if n_lanes == universe and not key_lo:
        return None
    if n_lanes * 16 < universe:
        return lambda key: np.searchsorted(lane_keys, key)
    dense = np.cumsum(present) - 1
    return lambda key: dense[key - key_lo]


def _place(pc: _Piece, key, key_lo: int, rank_of, warp_of_lane, lane_in_warp, j_of, n_warps: int, ws: int,
           lane_bits: int, name: str) -> Placement:
    """Where the rows of piece ``pc`` go (see :class:`Placement`)."""
    r = key if rank_of is None else rank_of(key)
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
    return Placement(order, w, j, run_starts(hi))


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


class FragmentLanes(NamedTuple):
    """A pixel shader's lanes as the rasterizer feeds them, in warp order (each warp's lanes in emission
    order)."""

    keys: np.ndarray               # each lane's fragment thread
    warp: np.ndarray               # its warp (ascending)
    position: np.ndarray | None    # the triangles rasterized by the time its own is (None: not asked for)
    quads: np.ndarray              # the quads emitted by the time its own is (a quad counts at its first fragment)


def fragment_lanes(work: Workload, gpu, lane_keys: np.ndarray, pk=None) -> FragmentLanes:
    """The lanes ``lane_keys`` (ascending fragment threads) of a pixel shader's pass packed into warps.

    The rasterizer emits them in :func:`gpusim.hw.raster.emission`'s order and
    deals each quad to the owner of its tile; an owner fills a warp with up
    to ``warp_size / 4`` of its quads in the order they come, and warps are
    numbered by their first lane's emission. ``pk``: the pass, for the
    triangle positions (:func:`_raster_positions`).
    """
    r, ws = gpu.raster, gpu.core.warp_size
    order, owner_of, quad_of = work.emission(r.tile, r.tile_owners)
    if len(lane_keys) == len(order):                 # every fragment thread: the emission order itself
        emitted = order
    else:
        present = np.zeros(len(order), bool)
        present[lane_keys] = True
        emitted = order[present[order]]
    n = len(emitted)
    qk = quad_of[emitted]
    new_quad = np.ones(n, bool)
    new_quad[1:] = qk[1:] != qk[:-1]
    quads = np.cumsum(new_quad)                      # a quad's fragments follow each other
    position = _raster_positions(work, pk, emitted)[1] if pk is not None else None
    if r.tile_owners > 1:                            # each owner's quads, in the order they come
        by_owner = np.argsort(owner_of[emitted], kind="stable")
        o = owner_of[emitted][by_owner]
        new_owner = np.ones(n, bool)
        new_owner[1:] = o[1:] != o[:-1]
        new_quad = new_quad[by_owner] | new_owner
    else:
        by_owner, new_owner = None, np.zeros(n, bool)
        new_owner[:1] = True
    quad_rank = np.cumsum(new_quad) - 1
    local = quad_rank - np.maximum.accumulate(np.where(new_owner, quad_rank, 0))    # the quad's rank at its owner
    part = local // max(1, ws // 4)
    new_warp = new_owner.copy()
    new_warp[1:] |= part[1:] != part[:-1]
    starts = np.flatnonzero(new_warp)
    size = np.diff(np.append(starts, n))
    if by_owner is None:                             # one stream: the warps come in emission order
        lanes = np.arange(n)
    else:                                            # the owners' warps, numbered by their first emitted lanes
        rank = np.argsort(by_owner[starts], kind="stable")
        size = size[rank]
        lanes = by_owner[np.repeat(starts[rank] - (np.cumsum(size) - size), size) + np.arange(n)]
    warp = np.repeat(np.arange(len(starts)), size)
    return FragmentLanes(emitted[lanes], warp, None if position is None else position[lanes], quads[lanes])


def submission_warps(work: Workload, gpu, lane_keys: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """A pixel shader's lanes ``lane_keys`` (ascending fragment threads) packed in submission order
    (``raster.warp_packing = "submission"``): each lane's warp, over ``ceil(4 x quads / warp_size)`` warps
    (the rasterizer emits 2x2 quads: 4 lanes a quad, helper lanes of partial quads included), and the quads
    emitted by the time its own is."""
    quads = _quads_so_far(work, lane_keys)
    n = len(lane_keys)
    n_warps = min(n, max(1, -(-4 * int(quads[-1]) // gpu.core.warp_size)))
    return np.arange(n, dtype=np.int64) * n_warps // n, quads


def fragment_warps(work: Workload, gpu, lane_keys: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """:func:`fragment_lanes` per lane key (ascending): each one's warp, and the quads emitted by the time its
    own is."""
    got = fragment_lanes(work, gpu, lane_keys)
    at = np.searchsorted(lane_keys, got.keys)
    warp, quads = np.empty_like(got.warp), np.empty_like(got.quads)
    warp[at], quads[at] = got.warp, got.quads
    return warp, quads


def _quads_so_far(work: Workload, lane_keys: np.ndarray) -> np.ndarray:
    """Per lane (fragment, in submission order): the 2x2 quads the rasterizer has emitted by the time it emits
    this lane's (a quad counts at its first fragment)."""
    prim, pixel = work.frag_prim[lane_keys], work.frag_pixel[lane_keys]
    kernel = _compiled_first_in_quads()
    if kernel is not None and len(prim) > 1 and bool((prim[1:] >= prim[:-1]).all()):
        quad, count = screen_quads(pixel, work.width, work.height)      # triangles in order: one pass
        first = kernel(np.asarray(prim, np.int64), quad, count)
    else:
        q = quad_ids(prim, pixel, work.width, work.height)
        first = np.zeros(len(q), bool)
        order, ascending = lex_sorted(q)        # a stable sort: each quad's first lane leads its run
        first[order[run_starts(ascending)]] = True
    return np.cumsum(first)


def _first_in_quads(prim: np.ndarray, quad: np.ndarray, quads: int) -> np.ndarray:
    """Whether each fragment is the first of its triangle in its screen quad, for fragments whose triangles
    come in order (``prim`` nondecreasing: a triangle's fragments are contiguous, so a quad's last triangle
    tells): what the stable sort of (triangle, quad) keys finds, in one pass."""
    last = np.full(quads, -1, np.int64)
    first = np.zeros(len(prim), np.bool_)
    for i in range(len(prim)):
        q = quad[i]
        if last[q] != prim[i]:
            first[i] = True
            last[q] = prim[i]
    return first


_KERNEL: list = []     # [the compiled _first_in_quads, or None], made on first use


def _compiled_first_in_quads():
    return compiled_once(_KERNEL, _first_in_quads)


def hash32(values: np.ndarray, seed: int = 0) -> np.ndarray:
    """A 32-bit multiplicative hash of integer ``values``."""
    return (values * 2654435761 + seed * 97) & 0xFFFFFFFF


def hashed(values: np.ndarray, below: int, seed: int = 0) -> np.ndarray:
    """A deterministic pseudo-random subset of integer ``values``: those whose 32-bit multiplicative hash is
    under ``below`` (``share * 2**32`` keeps about that share)."""
    return hash32(values, seed) < below


def submitted_triangles(pk, work: Workload) -> int:
    """Triangles a geometry pass submits to the rasterizer: the whole scene unless the scheme's pass says
    fewer (``Pass.primitives``, a k-buffer batch)."""
    return pk.primitives if pk.primitives is not None else work.triangles


def scoreboard_warps(pixel: np.ndarray, width: int, gpu) -> np.ndarray:
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
