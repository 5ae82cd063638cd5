"""The program format: what the SIMT cores execute, pass by pass.

A :class:`Program` is made by lowering (gpusim.hw.lower) from a scheme's
OpPlan. Each pass holds warps; each warp runs a thread program of typed
instructions, in issue order:

* :class:`Compute`: ALU work that holds the SM's issue port for ``cycles``
  (a software rasterizer's triangle setup);
* :class:`MemoryOp`: one warp instruction of an operation (gpusim.opplan.OPS)
  sent to its ``unit`` (the unit that takes it from the core: the coalescer
  for loads and stores, the atomic unit, the ROP, the scoreboard), with each
  active lane's byte ``address``, ``nbytes`` and thread. It holds the issue
  port for ``issue_cycles`` (the instruction and the ALU instructions around
  it), may ``depend`` on the thread's previous result and may ``produce`` one.

For speed the program is stored as columns, one entry per instruction
(``wi_*``), and the lanes of the memory instructions as rows per unit
(:class:`Rows`): instruction ``wi`` carries rows ``row_lo[wi]..row_hi[wi]-1``
of ``rows_of(unit)``. :meth:`Program.instruction` and :meth:`Program.warp` give
the typed view.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from functools import cached_property

import numpy as np

from gpusim.opplan import OPS

COMPUTE = -1          # the unit index of a compute instruction


@dataclass(frozen=True)
class Compute:
    """ALU instructions holding the SM's issue port."""

    cycles: int


@dataclass(frozen=True)
class MemoryOp:
    """One warp instruction of a memory operation, sent to ``unit``."""

    op: str
    unit: str
    address: np.ndarray = field(repr=False)
    nbytes: np.ndarray = field(repr=False)
    thread: np.ndarray = field(repr=False)
    issue_cycles: int = 0
    depends: bool = False
    produces: bool = False

    @property
    def lanes(self) -> int:
        return len(self.address)


@dataclass
class PassProgram:
    """The warps of one pass: warp ``w`` (global number) runs instructions ``wi_start[w - first_warp]`` up to
    the next warp's start."""

    index: int
    name: str
    kind: str
    wi_start: np.ndarray           # per warp, plus a final end
    lanes: int                     # threads of the pass
    first_warp: int = 0            # global number of the pass's first warp
    warp_triangles: np.ndarray | None = None   # fixed-function rasterizer: triangles rasterized before each
                                               # warp's fragments are all out (its last triangle + 1)
    triangles: int = 0             # triangles the fixed-function front end takes in the pass
    warp_quads: np.ndarray | None = None       # 2x2 quads rasterized before each warp's fragments are all out
    quads: int = 0                 # quads the fixed-function rasterizer emits in the pass
    operations: int = 0            # operations lowered (after any sampling)
    operations_total: int = 0      # operations of the pass in the plan

    @property
    def warps(self) -> int:
        return len(self.wi_start) - 1

    @property
    def instructions(self) -> int:
        return int(self.wi_start[-1] - self.wi_start[0]) if self.warps else 0


class Rows:
    """The lanes of one unit's instructions, instruction by instruction (each instruction's lanes in lane
    order).

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
    """Warp instructions of a whole run, in issue order per warp, and the rows (lanes) they carry."""

    passes: list[PassProgram]
    units: tuple[str, ...]         # unit names; ``wi_unit`` indexes them (COMPUTE: none)
    # per instruction
    row_lo: np.ndarray
    row_hi: np.ndarray
    wi_op: np.ndarray              # OPS code; -1 for compute
    wi_unit: np.ndarray
    wi_cycles: np.ndarray          # issue-port cycles
    wi_dep: np.ndarray
    wi_produces: np.ndarray
    wi_warp: np.ndarray            # global warp number
    wi_pass: np.ndarray
    wi_group: np.ndarray           # the plan group the instruction comes from (-1: compute)
    wi_k: np.ndarray               # its iteration inside the group's loop
    row_sets: dict[str, Rows]      # unit name -> its rows
    frag_pixel: np.ndarray = field(repr=False, default=None)   # pixel of each fragment thread
    # A sampled program (gpusim.hw.sample) stands for a whole run on a GPU cut down to some of its SMs; the
    # shared units keep their instances and latencies. ``occupancy``: per shared unit ("memory": the memory
    # partitions' levels, "atomic", "rop"), a (passes, instances) array: the run's load on each instance in each
    # pass over the sample's (gpusim.hw.unit.occupancy), and ``own_load`` the sample's own load there (their
    # product less it is the rest of the GPU's: gpusim.hw.background). ``hold_scale``: per atomic row, the run's
    # operations on its word in its pass over the sample's (a word's chain as long as in the run).
    # ``front_end_cycles``: cycles per triangle of the whole GPU's front end (a list: per pass, a thinned
    # sample's). ``l2_outcomes``: the run's L2
    # outcome of each of its requests, which the sample's requests take (gpusim.hw.memory.warming).
    # ``thinning``: per pass, the share of the work of the frame a thinned sample stands for (gpusim.hw.sample:
    # its shared units' and front end's busy cycles over it are the run's). ``reached``: per shared unit (the
    # keys of ``occupancy``) and pass, the share of the run's load on the instances the sample reaches
    # (gpusim.hw.lower.reached_share: the run's busy cycles are the reached instances' over it). None: a whole
    # run.
    occupancy: dict[str, np.ndarray] | None = field(repr=False, default=None)
    own_load: dict[str, np.ndarray] | None = field(repr=False, default=None)
    hold_scale: np.ndarray | None = field(repr=False, default=None)
    front_end_cycles: float | list[float] | None = None
    l2_outcomes: object | None = field(repr=False, default=None)
    thinning: np.ndarray | None = field(repr=False, default=None)
    reached: dict[str, np.ndarray] | None = field(repr=False, default=None)

    @property
    def instructions(self) -> int:
        return len(self.wi_op)

    @property
    def operations(self) -> int:
        return sum(len(r) for r in self.row_sets.values())

    @property
    def warps(self) -> int:
        return sum(p.warps for p in self.passes)

    def operation_names(self) -> set[str]:
        """The operations the program's instructions issue."""
        codes = np.unique(self.wi_op)
        return {OPS[c] for c in codes.tolist() if c >= 0}

    def rows_of(self, unit: str) -> Rows:
        return self.row_sets.get(unit) or Rows([])

    @cached_property
    def row_bounds(self) -> tuple[list, list]:
        """``row_lo`` and ``row_hi`` as lists (units index them per instruction)."""
        return self.row_lo.tolist(), self.row_hi.tolist()

    def rows(self, wi: int) -> slice:
        """Rows of instruction ``wi`` in ``rows_of(its unit)``."""
        return slice(int(self.row_lo[wi]), int(self.row_hi[wi]))

    def storage(self, unit: str) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Instructions of ``unit`` in row-storage order, their lane counts, and each row's instruction."""
        code = self.units.index(unit) if unit in self.units else -2
        wis = np.flatnonzero(self.wi_unit == code)
        wis = wis[np.argsort(self.row_lo[wis], kind="stable")]
        counts = self.row_hi[wis] - self.row_lo[wis]
        return wis, counts, np.repeat(wis, counts)

    def instruction(self, wi: int) -> Compute | MemoryOp:
        """Instruction ``wi``, typed."""
        u = int(self.wi_unit[wi])
        if u == COMPUTE:
            return Compute(int(self.wi_cycles[wi]))
        rows, r = self.rows_of(self.units[u]), self.rows(wi)
        return MemoryOp(OPS[int(self.wi_op[wi])], self.units[u], rows.address[r], rows.nbytes[r], rows.thread[r],
                        int(self.wi_cycles[wi]), bool(self.wi_dep[wi]), bool(self.wi_produces[wi]))

    def warp(self, w: int) -> list[Compute | MemoryOp]:
        """The thread program of global warp ``w``, typed."""
        lo, hi = np.searchsorted(self.wi_warp, [w, w + 1])
        return [self.instruction(wi) for wi in range(int(lo), int(hi))]
