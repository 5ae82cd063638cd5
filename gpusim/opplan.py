"""The OpPlan: the memory operations a scheme issues, the seam between schemes and hardware.

This is the one module both sides import: gpusim.schemes builds an
:class:`OpPlan`, gpusim.hw lowers it to timed instructions, and neither imports
the other. A scheme describes its operations as an :class:`OpPlan`: a list of
:class:`OpGroup` s, each "every thread in this set issues ``count`` operations
``op`` on ``structure`` at these byte offsets", added in program order. The
plan gives the access counts per structure and operation without expanding
anything (so a functional run stays fast), and :meth:`OpPlan.expand` turns it
into an :class:`OpStream`, one row per operation, only when a consumer (the
timing model, a test) asks for it. Counts and stream come from the same groups,
so they cannot disagree.

A group's threads are an array of ids or a :class:`ThreadRange` (0..n-1, never
materialised). Every consumer expands a group the same way:
:meth:`OpGroup.expand_ops` gives each operation's thread index and sequence
number, :meth:`OpGroup.thread_ids` the thread ids, :meth:`OpGroup.pass_of` the
pass of each operation.

Rows are ordered by pass, then thread, then program order inside the thread.
A thread is a fragment (geometry passes, numbered in submission order after
any reordering the scheme applies), a pixel (full-screen passes: the pixel id
``y * width + x``), a memory entry (clear passes) or, in a ``buffer`` pass
(a hardware unit streaming a fragment buffer, as the R-buffer's recirculation),
the stored fragment (its trace index). Addresses are bytes in
one flat space; each structure starts at a 4 KiB-aligned base.

Operations (``OPS``):

=========== ====================================================================
load        read of ``bytes`` bytes (texture fetch or global load)
store       write of ``bytes`` bytes
atomic_min  atomic minimum on a 32-bit word (returns the old value)
atomic_max  atomic maximum on a 32-bit word
atomic_inc  atomic increment of a 32-bit counter (returns the old value)
atomic_exch atomic exchange of a 32-bit word (returns the old value)
rmw_read    the read half of an unsynchronised read-modify-write (k-buffer
            through textures: hazards arise between it and the rmw_write)
rmw_write   the write half of an unsynchronised read-modify-write
blend       a fixed-function ROP read-modify-write of a framebuffer value,
            committed in submission order by the ROP (never a hazard)
depth_test  a ROP depth test: read, compare and conditional write of a depth
stencil     a ROP stencil test and update of one sample's stencil value
program_blend
            a programmable-blender invocation at the ROP (k-buffer proposal 2,
            seed 004 section 3.1.2): reads and writes ``bytes`` of the pixel's
            entries, committed in submission order like ``blend``
scoreboard  fragment dispatch through the scoreboard (k-buffer proposal 1,
            seed 004 section 3.1.1): the thread waits until no fragment of its
            pixel's cell is in flight and holds the cell until its last
            operation completes; no memory traffic (``bytes`` 0)
=========== ====================================================================

ALU work between operations (a register sort, compositing) is a ``compute``
group (:meth:`OpPlan.compute`): each thread's instruction count, timed on the
SM and left out of access counts and the OpStream.

A pass marked ``software`` runs as a compute kernel (FreePipe's software
pipeline); the timing model may then map one thread to each triangle.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Callable

import numpy as np
import pandas as pd

from gpusim.errors import GpusimError
from gpusim.shaders import SHADINGS

OPS = ("load", "store", "atomic_min", "atomic_max", "atomic_inc", "atomic_exch",
       "rmw_read", "rmw_write", "blend", "depth_test", "stencil", "program_blend", "scoreboard")
COMPUTE_OP = "compute"     # a group of ALU work, no memory operation (OpPlan.compute)
PASS_KINDS = ("clear", "geometry", "fullscreen", "flush", "buffer")
THREAD_KINDS = ("fragment", "pixel", "entry", "none")
BASE_ALIGN = 4096          # bytes
DEFAULT_MAX_OPS = 200_000_000


@dataclass(frozen=True)
class Pass:
    """One pass of a scheme: ``kind`` in PASS_KINDS, ``threads`` in THREAD_KINDS.

    ``software``: the pass is a compute kernel (a software rasterizer), not the
    graphics pipeline. ``primitives``: primitives a geometry pass submits
    (None: the whole scene; a batch of the k-buffer's heuristic submits its own).
    ``shading``: what a geometry pass of fragment threads needs of the scene's
    fragment shader (gpusim.shaders): the fragment's ``colour``, its ``alpha``
    alone, or ``none`` (a depth-only pass); other passes run no fragment shader.
    """

    name: str
    kind: str
    threads: str
    software: bool = False
    primitives: int | None = None
    shading: str = "colour"

    def __post_init__(self):
        if self.kind not in PASS_KINDS or self.threads not in THREAD_KINDS or self.shading not in SHADINGS:
            raise ValueError(f"bad pass {self}")

    @property
    def shades(self) -> bool:
        """Whether the pass runs the scene's fragment shader on its threads (a geometry pass of fragments)."""
        return self.kind == "geometry" and self.threads == "fragment" and self.shading != "none"


def expand_counts(who: np.ndarray, count: np.ndarray, s0: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """``(i, seq)`` of ``count[j]`` operations of each thread ``who[j]``, in thread then program order, numbered
    from ``s0`` within each thread. Where every thread has as many (a loop of fixed length, the usual case), one
    broadcast fill each: several times faster than the two ragged repeats."""
    n = len(who)
    if n and int(count.min()) == int(count.max()):
        k = int(count[0])
        i = np.empty((n, k), np.int64)
        i[:] = np.asarray(who, np.int64)[:, None]
        seq = np.empty((n, k), np.int64)
        seq[:] = np.arange(s0, s0 + k, dtype=np.int64)
        return i.ravel(), seq.ravel()
    i = np.repeat(who, count)
    seq = np.arange(len(i), dtype=np.int64)
    seq -= np.repeat(np.cumsum(count) - count - s0, count)
    return i, seq


@dataclass
class OpGroup:
    """``count[i]`` operations of one kind by thread ``thread[i]``; offsets from ``offset(i, seq)``."""

    pass_index: int | np.ndarray      # one pass, or the pass of each thread
    op: str
    structure: str
    thread: np.ndarray
    count: np.ndarray
    offset: Callable[[np.ndarray, np.ndarray], np.ndarray]
    bytes: int | Callable[[np.ndarray, np.ndarray], np.ndarray]   # per op (i, seq) when sizes vary
    dep: bool
    pass_fn: Callable[[np.ndarray, np.ndarray], np.ndarray] | None = None   # pass of each op (i, seq)
    seq_pass: np.ndarray | None = None    # pass of a thread's op ``seq``, the same for every thread (ascending)
    instructions: np.ndarray | None = None   # a ``compute`` group: each thread's ALU instructions

    @property
    def is_compute(self) -> bool:
        return self.op == COMPUTE_OP

    @property
    def total(self) -> int:
        return int(self.count.sum())

    def expand_ops(self) -> tuple[np.ndarray, np.ndarray]:
        """``(i, seq)`` of every operation, in thread then program order.

        ``i`` is the index into ``thread`` of the operation's thread; ``seq`` its
        number among that thread's operations of this group (0, 1, ...). When
        every count is 1, ``i`` is ``arange(n)`` and ``seq`` a broadcast zero
        (no allocation).
        """
        n = len(self.thread)
        count = self.count
        i = np.arange(n, dtype=np.int64)
        if n and int(count.min()) == 1 and int(count.max()) == 1:
            return i, np.broadcast_to(np.zeros(1, np.int64), (n,))
        return expand_counts(i, count)

    def thread_ids(self) -> np.ndarray:
        """The thread ids as an array (``arange`` for a :class:`ThreadRange`)."""
        if isinstance(self.thread, ThreadRange):
            return np.arange(len(self.thread), dtype=np.int64)
        return self.thread

    def pass_of(self, i: np.ndarray, seq: np.ndarray) -> np.ndarray | int:
        """The pass of each operation ``(i, seq)`` (from :meth:`expand_ops`).

        ``seq_pass[seq]`` or ``pass_fn(i, seq)`` when the group has one, else the scalar ``pass_index``,
        else the pass of each operation's thread, ``pass_index[i]``.
        """
        if self.seq_pass is not None:
            return self.seq_pass[seq]
        if self.pass_fn is not None:
            return self.pass_fn(i, seq)
        if np.isscalar(self.pass_index):
            return self.pass_index
        return self.pass_index[i]


@dataclass
class OpPlan:
    """The operations of one scheme run, grouped (see the module docstring)."""

    passes: list[Pass]
    structures: list[str]
    groups: list[OpGroup] = field(default_factory=list)

    def add(self, pass_index, op: str, structure: str, thread: np.ndarray, count,
            offset: Callable[[np.ndarray, np.ndarray], np.ndarray], nbytes,
            dep: bool = False, pass_fn=None, seq_pass=None) -> None:
        """Append a group in program order (after the groups already added for these threads).

        ``nbytes`` is the size of every operation, or ``nbytes(i, seq)`` where
        sizes vary (a compressed fragment).
        ``pass_fn(i, seq)`` gives the pass of each operation when one thread's
        operations of this group span several passes (``pass_index`` is then ignored).
        ``seq_pass[s]`` says the same when op ``s`` of every thread goes to one pass, a strictly ascending
        array: consumers then take a pass at a time without expanding the group (depth peeling's passes
        over every fragment).
        """
        if op not in OPS:
            raise ValueError(f"unknown operation {op!r}")
        if structure not in self.structures:
            raise ValueError(f"operation on unallocated structure {structure!r}")
        pass_index, thread = self._threads(pass_index, thread)
        count = np.broadcast_to(np.asarray(count, dtype=np.int64), (len(thread),))
        if len(thread) and int(count.sum()) > 0:
            if seq_pass is not None:
                seq_pass = self._seq_pass(seq_pass, count)
            self.groups.append(OpGroup(pass_index, op, structure, thread, count, offset, nbytes, dep, pass_fn,
                                       seq_pass))

    def _threads(self, pass_index, thread):
        """A group's pass index (one, or one per thread) and threads (an array, or n for 0..n-1, made only on
        expansion), checked against the plan's passes."""
        if isinstance(thread, (int, np.integer)):
            thread = ThreadRange(int(thread))
        else:
            thread = np.asarray(thread, dtype=np.int64)
        if not np.isscalar(pass_index):
            pass_index = np.broadcast_to(np.asarray(pass_index, dtype=np.int64), (len(thread),))
        if len(thread) and not (0 <= np.min(pass_index) and np.max(pass_index) < len(self.passes)):
            raise ValueError(f"pass index out of range 0..{len(self.passes) - 1}")
        return pass_index, thread

    def compute(self, pass_index, thread, instructions, dep: bool = True, count=1, seq_pass=None) -> None:
        """Append ALU work in program order: thread ``thread[i]`` runs ``instructions[i]`` instructions (a
        register sort, compositing). ``dep``: the work uses the result of the thread's previous operation (it
        waits for it). No memory operation: access counts and the OpStream leave it out; the timing model
        issues it on the SM (a warp runs as long as its busiest lane).

        ``count`` and ``seq_pass`` as for :meth:`add`: thread ``i`` runs the work once in each of the passes
        ``seq_pass[:count[i]]`` (one group for depth peeling's work in every pass, so the plan grows with the
        threads plus the passes, not their product)."""
        pass_index, thread = self._threads(pass_index, thread)
        n = len(thread)
        instructions = np.broadcast_to(np.asarray(instructions, dtype=np.int64), (n,))
        count = np.broadcast_to(np.asarray(count, dtype=np.int64), (n,))
        if n and int(instructions.min()) < 0:
            raise ValueError("instructions must be >= 0")
        if n and int(instructions.max()) > 0 and int(count.sum()) > 0:
            if seq_pass is not None:
                seq_pass = self._seq_pass(seq_pass, count)
            self.groups.append(OpGroup(pass_index, COMPUTE_OP, "", thread, count,
                                       lambda i, s: np.zeros(len(i), np.int64), 0, dep, seq_pass=seq_pass,
                                       instructions=instructions))

    @staticmethod
    def _seq_pass(seq_pass, count: np.ndarray) -> np.ndarray:
        seq_pass = np.asarray(seq_pass, np.int64)
        if len(seq_pass) < int(count.max()) or (np.diff(seq_pass) <= 0).any():
            raise ValueError("seq_pass must give a strictly ascending pass for every op of a thread")
        return seq_pass

    @property
    def memory_groups(self) -> list[OpGroup]:
        """The groups of memory operations (every group but ALU work)."""
        return [g for g in self.groups if not g.is_compute]

    def total_ops(self) -> int:
        return sum(g.total for g in self.memory_groups)

    def accesses(self, kinds: set[str] | None = None) -> dict[str, dict[str, int]]:
        """Operation counts per structure and operation (no expansion).

        ``kinds`` keeps the groups whose pass is of one of those kinds (a group
        spanning several passes with ``pass_fn`` is counted under the kind of
        its ``pass_index``; the passes it spans share that kind).
        """
        out: dict[str, dict[str, int]] = {}
        for g in self.memory_groups:
            if kinds is not None and not self._kinds_of(g) <= kinds:
                if self._kinds_of(g) & kinds:
                    raise ValueError("a group spans passes of several kinds; count it by expansion")
                continue
            ops = out.setdefault(g.structure, {})
            ops[g.op] = ops.get(g.op, 0) + g.total
        return out

    def _kinds_of(self, g: OpGroup) -> set[str]:
        if g.seq_pass is not None:
            index = set(g.seq_pass[:int(g.count.max())].tolist())
        else:
            index = {int(g.pass_index)} if np.isscalar(g.pass_index) else set(np.unique(g.pass_index).tolist())
        return {self.passes[i].kind for i in index}

    def expand(self, bases: dict[str, int], max_ops: int = DEFAULT_MAX_OPS) -> "OpStream":
        """One row per operation, ordered by (pass, thread, program order)."""
        total = self.total_ops()
        if total > max_ops:
            raise GpusimError(f"the OpStream would hold {total:,} operations (~{total * 24 / 2**30:.1f} GiB), "
                              f"over the limit of {max_ops:,}; use a smaller trace")
        cols: dict[str, list] = {k: [] for k in ("pass_index", "thread", "op", "structure", "address",
                                                  "bytes", "dep")}
        for g in self.memory_groups:
            n = g.total
            i, seq = g.expand_ops()
            offset = np.asarray(g.offset(i, seq), dtype=np.uint64)
            cols["pass_index"].append(np.broadcast_to(np.asarray(g.pass_of(i, seq), dtype=np.uint32), (n,)))
            cols["thread"].append(g.thread_ids()[i])
            cols["op"].append(np.full(n, OPS.index(g.op), np.uint8))
            cols["structure"].append(np.full(n, self.structures.index(g.structure), np.uint8))
            cols["address"].append(offset + np.uint64(bases[g.structure]))
            cols["bytes"].append(np.asarray(g.bytes(i, seq), np.uint32) if callable(g.bytes)
                                 else np.full(n, g.bytes, np.uint32))
            cols["dep"].append(np.full(n, g.dep, bool))
        arrays = {k: (np.concatenate(v) if v else np.zeros(0, dtype=_EMPTY_DTYPES[k]))
                  for k, v in cols.items()}
        order = np.lexsort((arrays["thread"], arrays["pass_index"]))   # stable: keeps program order
        arrays = {k: v[order] for k, v in arrays.items()}
        return OpStream(**arrays, passes=list(self.passes), structures=list(self.structures),
                        bases=dict(bases))


class ThreadRange:
    """Threads 0..n-1 without materialising them (a clear pass over millions of entries)."""

    def __init__(self, n: int):
        self.n = n

    def __len__(self) -> int:
        return self.n


_EMPTY_DTYPES = {"pass_index": np.uint32, "thread": np.int64, "op": np.uint8, "structure": np.uint8,
                 "address": np.uint64, "bytes": np.uint32, "dep": bool}


@dataclass(eq=False)
class OpStream:
    """Columnar memory operations (see the module docstring).

    ``op`` and ``structure`` are codes into ``OPS`` and ``structures``;
    ``dep`` is True where the operation needs the result of the thread's previous
    operation (an atomic chain, a store at an address an atomic returned).
    """

    pass_index: np.ndarray
    thread: np.ndarray
    op: np.ndarray
    structure: np.ndarray
    address: np.ndarray
    bytes: np.ndarray
    dep: np.ndarray
    passes: list[Pass]
    structures: list[str]
    bases: dict[str, int]

    def __len__(self) -> int:
        return int(len(self.op))

    def counts(self) -> dict[str, dict[str, int]]:
        """Operation counts per structure and operation, counted from the rows."""
        out: dict[str, dict[str, int]] = {}
        if len(self) == 0:
            return out
        code = self.structure.astype(np.int64) * len(OPS) + self.op
        for c, n in zip(*np.unique(code, return_counts=True)):
            out.setdefault(self.structures[c // len(OPS)], {})[OPS[c % len(OPS)]] = int(n)
        return out

    def to_frame(self) -> pd.DataFrame:
        """A pandas view with categorical pass, op and structure names."""
        return pd.DataFrame({
            "pass": pd.Categorical.from_codes(self.pass_index.astype(np.int64), [p.name for p in self.passes]),
            "thread": self.thread,
            "op": pd.Categorical.from_codes(self.op.astype(np.int64), list(OPS)),
            "structure": pd.Categorical.from_codes(self.structure.astype(np.int64), self.structures),
            "address": self.address, "bytes": self.bytes, "dep": self.dep})


def layout_bases(structures: list[str], sizes: dict[str, int]) -> dict[str, int]:
    """Base byte address of each structure, in order, each aligned to BASE_ALIGN."""
    bases, at = {}, 0
    for name in structures:
        bases[name] = at
        at += -(-max(int(sizes[name]), 1) // BASE_ALIGN) * BASE_ALIGN
    return bases
