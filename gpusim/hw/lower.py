"""Lowering an OpStream to warp instructions: what the SIMT cores execute.

A *lane* is a thread of a pass: a fragment, a pixel or a memory entry, or, with
the ``triangle`` thread mapping, a triangle whose thread issues its fragments'
operations in turn (FreePipe, seed 000 section 3). A warp is ``warp_size``
consecutive lanes in submission order; warps go to the SMs round robin. A
*warp instruction* is the k-th operation of every lane of a warp that has one,
split by operation and structure where lanes diverge; warps issue their
instructions in program order.

Everything here is vectorized numpy on the whole stream; the event model
(gpusim.hw.machine) then walks warps and instructions.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from gpusim.schemes.opstream import OPS, OpStream

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
    """What the hardware knows besides the stream: the screen and each fragment thread's pixel and triangle.

    ``frag_pixel[t]`` and ``frag_prim[t]`` are for fragment thread ``t`` (the
    scheme's submission order). The OpStream is expanded from the scheme's
    plan on first use (the analytic level never expands it).
    """

    def __init__(self, stream: OpStream | None, width: int, height: int, frag_pixel: np.ndarray,
                 frag_prim: np.ndarray, result=None, triangles: int | None = None):
        self._stream, self.result = stream, result
        self.triangles = int(frag_prim.max()) + 1 if triangles is None and len(frag_prim) else (triangles or 0)
        self.width, self.height = width, height
        self.frag_pixel, self.frag_prim = frag_pixel, frag_prim

    @property
    def stream(self) -> OpStream:
        if self._stream is None:
            self._stream = self.result.opstream()
        return self._stream

    @classmethod
    def of(cls, result, trace, stream: OpStream | None = None) -> "Workload":
        order = result.submission if result.submission is not None else np.arange(len(trace))
        return cls(stream, trace.width, trace.height, trace.pixel_ids()[order].astype(np.int64),
                   trace.prim[order].astype(np.int64), result,
                   int(trace.prim.max()) + 1 if len(trace) else 0)


@dataclass
class PassProgram:
    """The warps of one pass: warp w runs instructions ``wi_start[w]..wi_start[w+1]-1``."""

    index: int
    name: str
    kind: str
    wi_start: np.ndarray           # per warp, plus a final end
    lanes: int                     # threads of the pass
    flush_warps: int = 0           # ALU-only warps of a flush pass (a full-screen quad, no memory ops)
    warp_ready: np.ndarray | None = None   # cycles after the pass start each warp's triangles are rasterized
    min_cycles: int = 0            # the rasterizer's time for all the pass's triangles
    setup_cycles: int = 0          # issue cycles of software triangle setup at each warp's start

    @property
    def warps(self) -> int:
        return len(self.wi_start) - 1


@dataclass
class Program:
    """Warp instructions of a whole run, and the rows (operations) they cover.

    Row arrays are in instruction order; instruction ``i`` covers rows
    ``row_start[i]..row_start[i+1]-1``.
    """

    passes: list[PassProgram]
    # per instruction
    row_start: np.ndarray
    wi_op: np.ndarray
    wi_class: np.ndarray
    wi_dep: np.ndarray
    wi_produces: np.ndarray
    wi_warp: np.ndarray            # global warp number
    wi_pass: np.ndarray
    # per row (operation)
    op: np.ndarray
    address: np.ndarray
    nbytes: np.ndarray
    thread: np.ndarray
    seq: np.ndarray                # position of the row in the OpStream (submission order)
    cell_pixel: np.ndarray         # pixel of fragment rows (-1 elsewhere): scoreboard cells, tiles
    structure: np.ndarray

    @property
    def instructions(self) -> int:
        return len(self.wi_op)

    def classes(self) -> set[int]:
        return set(np.unique(self.wi_class).tolist())

    def rows(self, wi: int) -> slice:
        return slice(int(self.row_start[wi]), int(self.row_start[wi + 1]))

    def class_rows(self, cls: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Instructions of unit class ``cls``, their lane counts, and their rows (instruction by instruction)."""
        wis = np.flatnonzero(self.wi_class == cls)
        counts = np.diff(self.row_start)[wis]
        rows = (np.repeat(self.row_start[wis], counts)
                + np.arange(counts.sum()) - np.repeat(np.cumsum(counts) - counts, counts))
        return wis, counts, rows


def thread_mapping(gpu, p) -> str:
    """How a pass's threads become lanes: ``triangle``, ``fragment`` or ``thread`` (as they are)."""
    m = gpu.core.thread_mapping
    if p.kind != "geometry" or p.threads != "fragment":
        return "thread"
    if m == "auto":
        return "triangle" if p.software else "fragment"
    return m


def lower(work: Workload, gpu, keep: np.ndarray | None = None) -> Program:
    """Warp instructions of ``work.stream`` on ``gpu``; ``keep`` selects rows (the sampled fidelity)."""
    s = work.stream
    ws = gpu.core.warp_size
    rows = np.arange(len(s)) if keep is None else np.flatnonzero(keep)
    pass_of = s.pass_index[rows].astype(np.int64)
    thread = s.thread[rows]
    fragment_pass = np.array([p.threads == "fragment" for p in s.passes] + [False], bool)
    frag_rows = fragment_pass[pass_of]
    cell_pixel = np.full(len(rows), -1, np.int64)
    if len(work.frag_pixel):
        cell_pixel[frag_rows] = work.frag_pixel[np.minimum(thread[frag_rows], len(work.frag_pixel) - 1)]
    mapping = np.array([thread_mapping(gpu, p) == "triangle" for p in s.passes] + [False], bool)
    tri_rows = mapping[pass_of]
    lane_key = thread.astype(np.int64).copy()
    if tri_rows.any():
        lane_key[tri_rows] = work.frag_prim[thread[tri_rows]]
    # stable: keep program order (and fragment order inside a triangle) within each lane
    key = pass_of * (1 << 40) + lane_key
    if len(key) and np.any(key[1:] < key[:-1]):
        order = np.argsort(key, kind="stable")
        rows, pass_of, lane_key, thread, cell_pixel = (a[order] for a in (rows, pass_of, lane_key, thread,
                                                                           cell_pixel))
    n = len(rows)
    new_lane = np.ones(n, bool)
    if n:
        new_lane[1:] = (lane_key[1:] != lane_key[:-1]) | (pass_of[1:] != pass_of[:-1])
    lane_id = np.cumsum(new_lane) - 1                      # global lane number
    lane_first = np.flatnonzero(new_lane)
    pos = np.arange(n) - lane_first[lane_id]               # program position inside the lane
    lane_pass = pass_of[lane_first]
    pass_first_lane = np.searchsorted(lane_pass, np.arange(len(s.passes) + 1))
    lane_rank = np.arange(len(lane_first)) - pass_first_lane[lane_pass]
    sb_pass = np.zeros(len(s.passes) + 1, bool)
    op = s.op[rows]
    sb_code = OPS.index("scoreboard")
    if (op == sb_code).any():
        sb_pass[np.unique(pass_of[op == sb_code])] = True
    warp_in_pass = lane_rank // ws
    for pi in np.flatnonzero(sb_pass):
        lanes = np.flatnonzero(lane_pass == pi)
        warp_in_pass[lanes] = _scoreboard_warps(cell_pixel[lane_first[lanes]], work.width, gpu)
    # global warp number: passes in order, warps in order inside
    warps_per_pass = np.zeros(len(s.passes), np.int64)
    if len(lane_first):
        np.maximum.at(warps_per_pass, lane_pass, warp_in_pass + 1)
    pass_warp0 = np.concatenate([[0], np.cumsum(warps_per_pass)])
    warp = (pass_warp0[lane_pass] + warp_in_pass)[lane_id]
    code = op.astype(np.int64) * 256 + s.structure[rows]
    max_pos = int(pos.max()) + 1 if n else 1
    if n and int(warp.max() + 1) * max_pos < (1 << 50):
        key = (warp * max_pos + pos) * 4096 + code
        order = np.argsort(key, kind="stable")        # lanes stay in lane order
        key = key[order]
        new_wi = np.r_[True, key[1:] != key[:-1]]
    else:
        order = np.lexsort((lane_id, code, pos, warp))
        w_, p_, c_ = warp[order], pos[order], code[order]
        new_wi = np.r_[True, (w_[1:] != w_[:-1]) | (p_[1:] != p_[:-1]) | (c_[1:] != c_[:-1])] if n else new_lane[:0]
    thread0 = thread                                   # lane order (lane_first indexes it)
    rows, thread, cell_pixel = rows[order], thread[order], cell_pixel[order]
    row_start = np.append(np.flatnonzero(new_wi), n)
    first = row_start[:-1]
    wi_op = s.op[rows[first]].astype(np.int64)
    dep = np.logical_or.reduceat(s.dep[rows], first) if len(first) else np.zeros(0, bool)
    wi_warp = warp[order[first]]
    wi_pass = pass_of[order[first]]
    warp_wi_start = np.searchsorted(wi_warp, np.arange(int(pass_warp0[-1]) + 1))
    passes = []
    rate = gpu.raster.triangles_per_cycle
    lane_prim = np.full(len(lane_first), -1, np.int64)
    fr = np.flatnonzero(fragment_pass[lane_pass])
    if len(fr) and len(work.frag_prim):
        lane_prim[fr] = work.frag_prim[thread0[lane_first[fr]]]
    for i, p in enumerate(s.passes):
        w0, w1 = int(pass_warp0[i]), int(pass_warp0[i + 1])
        lanes = int(pass_first_lane[i + 1] - pass_first_lane[i])
        flush = -(-work.width * work.height // ws) if p.kind == "flush" else 0
        pp = PassProgram(i, p.name, p.kind, warp_wi_start[w0:w1 + 1], lanes, flush)
        mode = thread_mapping(gpu, p)
        if mode == "fragment":         # the fixed-function rasterizer feeds the warps in triangle order
            sel = lane_pass == i
            ready = np.zeros(w1 - w0, np.int64)
            if sel.any():
                np.maximum.at(ready, warp_in_pass[sel], np.ceil((lane_prim[sel] + 1) / rate).astype(np.int64))
            pp.warp_ready, pp.min_cycles = ready, int(np.ceil(work.triangles / rate))
        elif mode == "triangle":
            pp.setup_cycles = gpu.raster.setup_instructions * gpu.core.issue_cycles
        passes.append(pp)
    return Program(passes, row_start, wi_op, OP_CLASS[wi_op], dep, OP_PRODUCES[wi_op], wi_warp, wi_pass,
                   s.op[rows], s.address[rows].astype(np.int64), s.bytes[rows].astype(np.int64), thread,
                   rows, cell_pixel, s.structure[rows])


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
