"""What every hardware unit shares: the unit interface, its registry, declared stats, sub-cycle time.

A unit is one class (see the worked example in gpusim.hw):

* ``name``: its registry name, which is also its TOML section in a GPU config;
* ``Config``: its config dataclass (typed fields declared with
  :func:`gpusim.config.param`: unit, bounds, description);
* ``issued``: the operations (gpusim.opplan.OPS) the SIMT core issues to it;
  ``reached``: operations that reach it through another unit (the L2 behind
  the coalescer, the blender behind the ROP). A unit is built only when the
  program holds one of these;
* ``STATS``: its declared stats (:class:`Stat`: name, unit of measure,
  description), each reported per instance;
* ``__init__(config, machine)``: build from its section and the program
  (``machine.program``), vectorised;
* ``serve(wi, now)``: serve warp instruction ``wi`` issued at cycle ``now``:
  the cycle its result is back at the core, or a simpy event the warp waits
  for before it issues the instruction again (a full reorder buffer);
* ``idle_at()``: the cycle it has finished everything it was given;
* ``values(total_cycles)``: each declared stat's value (a list per instance).

Time is integer cycles. A unit whose throughput is not a whole number of
cycles per operation (13.67 bytes per cycle) keeps its occupancy in integer
sub-cycles (``FP`` per cycle), so long runs accumulate no rounding: a request
is served from ``max(arrival, free)`` for ``ceil(work * FP / rate)``
sub-cycles, and the times handed back to the core are whole cycles (rounded
up).
"""

from __future__ import annotations

import math
import operator
from dataclasses import dataclass
from typing import ClassVar

import numpy as np

from gpusim.jit import compiled_once

FP = 1 << 16          # sub-cycles per cycle


def fp_cost(work: float, rate: float) -> int:
    """Sub-cycles to serve ``work`` units at ``rate`` units per cycle (at least one sub-cycle)."""
    return max(1, math.ceil(work * FP / rate))


def fp_costs(work, rate: float):
    """:func:`fp_cost` of an array of whole work amounts (int64); a table lookup when they are small."""
    work = np.asarray(work)
    top = int(work.max()) if work.size else 0
    if work.size > 4 * top and work.dtype.kind in "iu":
        return fp_costs(np.arange(top + 1, dtype=np.float64), rate)[work]
    return np.maximum(1, np.ceil(work * FP / rate)).astype(np.int64)


def cycles(fp: int) -> int:
    """Whole cycles covering ``fp`` sub-cycles."""
    return -(-fp // FP)


def _shift(d: int) -> int:
    """log2 of ``d`` where it is a power of two, else -1."""
    return d.bit_length() - 1 if d & (d - 1) == 0 else -1


def div(a, d: int):
    """``a // d`` for non-negative integer arrays (a shift when ``d`` is a power of two)."""
    shift = _shift(d)
    return a >> shift if shift >= 0 else a // d


def mod(a, d: int):
    """``a % d`` for non-negative integer arrays (a mask when ``d`` is a power of two)."""
    return a & (d - 1) if d & (d - 1) == 0 else a % d


def interleave(address, granularity: int, instances: int):
    """The instance serving each byte address when addresses are interleaved across ``instances`` in
    blocks of ``granularity`` bytes: partitions, ROP units. The one address-to-unit map of the model.

    Block ``b`` goes to ``(b + b // n + b // n**2 + b // n**3) mod n`` (``n`` instances): consecutive blocks
    go round the instances, and each further run of ``n`` blocks starts one instance on (the sum of ``b``'s
    base-``n`` digits, the last three folded in). A stride of a multiple of ``n`` blocks, such as a render
    target's rows (128 pixels of 16 bytes are 8 blocks of 256), then spreads over every instance instead of
    landing a screen column on each; GPUs hash their partition bits for the same reason. For a fixed
    ``b // n`` the map is a permutation of the ``n`` instances, so :func:`within_instance` numbers each
    instance's share one to one."""
    if instances == 1:
        return mod(div(address, granularity), 1)
    address = np.asarray(address)
    if address.ndim != 1 or len(address) <= _CHUNK:
        return _interleave(address, granularity, instances)
    out = np.empty(len(address), np.result_type(address.dtype, np.int64))
    kernel = compiled_once(_KERNEL, _interleave_into) if address.dtype.kind in "iu" else None
    if kernel is not None:                           # one pass, no temporaries: the same integers
        kernel(address, granularity, instances, _shift(granularity), _shift(instances), out)
        return out
    for lo in range(0, len(address), _CHUNK):       # temporaries the allocator reuses (and the cache holds)
        out[lo:lo + _CHUNK] = _interleave(address[lo:lo + _CHUNK], granularity, instances)
    return out


_CHUNK = 1 << 18
_KERNEL: list = []     # [the compiled _interleave_into, or None], made on first use


def _interleave_into(address, granularity, instances, g_shift, n_shift, out):
    """:func:`_interleave` of each of ``address`` (non-negative integers) into ``out``, compiled (shifts and
    masks for powers of two, ``g_shift``/``n_shift`` >= 0, as :func:`div` and :func:`mod` take them)."""
    mask = instances - 1
    for i in range(len(address)):
        a = address[i]
        b = a >> g_shift if g_shift >= 0 else a // granularity
        if n_shift >= 0:
            q = b >> n_shift
            q2 = q >> n_shift
            out[i] = (b + q + q2 + (q2 >> n_shift)) & mask
        else:
            q = b // instances
            q2 = q // instances
            out[i] = (b + q + q2 + q2 // instances) % instances


def _interleave(address, granularity: int, instances: int):
    b = div(address, granularity)
    q = div(b, instances)
    q2 = div(q, instances)
    return mod(b + q + q2 + div(q2, instances), instances)


def within_instance(address, granularity: int, instances: int):
    """Each byte address as an offset in its instance's own share of the address space (the interleaving bits of
    :func:`interleave` taken out): an L2 slice indexes its sets by the lines of its partition's share, so that
    the partition's lines reach every set."""
    return div(address, granularity * instances) * granularity + mod(address, granularity)


def occupancy(cost_fp: np.ndarray, pass_of: np.ndarray, instance: np.ndarray, program, name: str) -> np.ndarray:
    """How long requests of ``cost_fp`` sub-cycles in passes ``pass_of`` hold their ``instance`` of shared unit
    ``name`` (a key of ``Program.occupancy``): as long as they are served in a whole run; in a sampled program
    that times the run's load on the instance in the pass over the sample's (the rest of the GPU's traffic,
    which reaches the instance as the sample's does), so each instance is as busy as in the run."""
    factor = program.occupancy.get(name) if program.occupancy else None
    if factor is None:
        return cost_fp
    return np.ceil(cost_fp * factor[pass_of, instance]).astype(np.int64)


def run_held(held: np.ndarray, pass_of: np.ndarray, program, name: str) -> np.ndarray:
    """The run's busy sub-cycles that requests holding shared unit ``name`` (a key of ``Program.occupancy``)
    ``held`` sub-cycles in passes ``pass_of`` stand for in a sampled ``program`` (:func:`occupancy`): ``held``
    over, per pass, the share of the run's load there on the instances the sample reaches
    (``Program.reached``) and, in a thinned sample, which stands for the GPU on a frame thinned to a share
    ``theta`` of each pass's work (``Program.thinning``), over ``theta``. Whole sub-cycles, so that the sums
    do not depend on the order they are added in (a run replayed a chunk of passes at a time)."""
    return np.rint(held / run_divisor(program, name)[pass_of])


def run_divisor(program, name: str) -> np.ndarray:
    """Per pass, what :func:`run_held` divides a sampled ``program``'s held sub-cycles on unit ``name`` by."""
    out = np.ones(len(program.passes))
    if program.thinning is not None:
        out = out * program.thinning
    if program.reached is not None and name in program.reached:
        out = out * program.reached[name]
    return np.maximum(out, 1e-12)


def address_ids(addr: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Each address as a small integer id, and the operations per distinct address.

    Dense (offset from the lowest address, the low bits no address uses shifted
    out: byte addresses of 4-byte words become word numbers) when the addresses
    lie close together; otherwise ranks among the distinct addresses (a sort).
    """
    if not len(addr):
        return np.zeros(0, np.int64), np.zeros(0, np.int64)
    ids = addr - int(addr.min())
    common = int(np.bitwise_or.reduce(ids))
    if common:
        ids = ids >> ((common & -common).bit_length() - 1)
    if int(ids.max()) <= 16 * len(ids):
        ops = np.bincount(ids)
        return ids, ops[ops > 0]
    uniq, ids = np.unique(addr, return_inverse=True)
    return ids, np.bincount(ids, minlength=len(uniq))


@dataclass(frozen=True)
class Stat:
    """A stat declared on a unit (gem5 style): its name, unit of measure and description. Instances are
    labels of a value, never part of the name."""

    name: str
    unit: str
    doc: str
    per_instance: bool = True


def occupancy_stats(busy: str, requests_unit: str, requests: str) -> tuple[Stat, Stat, Stat]:
    """The stats every timed unit declares: busy cycles, requests and utilisation (busy / run cycles) per
    instance, with the unit's own descriptions."""
    return (Stat("busy_cycles", "cycles", busy), Stat("requests", requests_unit, requests),
            Stat("utilisation", "1", "busy cycles / run cycles"))


BUSY, REQUESTS, UTILISATION = occupancy_stats("cycles the instance was serving", "requests", "requests served")


class Unit:
    """Base of the hardware units: per-instance busy sub-cycles and request counts (see the module
    docstring for the interface)."""

    name: ClassVar[str] = "unit"
    Config: ClassVar[type | None] = None
    issued: ClassVar[frozenset] = frozenset()
    reached: ClassVar[frozenset] = frozenset()
    STATS: ClassVar[tuple[Stat, ...]] = (BUSY, REQUESTS, UTILISATION)
    #: counters a run changes, merged across the processes of a parallel run (name -> how)
    COUNTERS: ClassVar[dict] = {}
    #: per-instance counts, added up over the machines of a run replayed a chunk of passes at a time
    #: (gpusim.hw.stream); ``KEPT``: the other attributes the unit's stats read
    TOTALS: ClassVar[tuple[str, ...]] = ("busy_fp", "requests")
    KEPT: ClassVar[tuple[str, ...]] = ("instances",)
    #: the unit above this one in the unit tree (``memory`` for a memory level), for its stats' path
    parent: ClassVar[str] = ""

    @classmethod
    def path(cls) -> str:
        """Where the unit sits in the unit tree: ``core``, ``memory.dram``, ``rop.blender``."""
        return f"{cls.parent}.{cls.name}" if cls.parent else cls.name

    def __init__(self, instances: int):
        if instances < 1:
            raise ValueError(f"{self.name}: instances must be >= 1")
        self.instances = instances
        self.busy_fp = [0] * instances
        self.requests = [0] * instances

    @classmethod
    def needed(cls, program, gpu) -> bool:
        """Whether a machine running ``program`` on ``gpu`` builds this unit: by default, when the program
        issues an operation the unit takes or is reached by."""
        return bool((cls.issued | cls.reached) & program.operation_names())

    def detached(self) -> "Unit":
        """A copy holding only what the unit's stats read (``KEPT``, ``TOTALS``, ``COUNTERS``), without the
        machine and program behind it (gpusim.hw.stream keeps it after dropping them)."""
        out = object.__new__(type(self))
        out.__dict__.update({a: getattr(self, a) for a in dict.fromkeys((*self.KEPT, *self.TOTALS, *self.COUNTERS))})
        if self.run_busy_fp is not None:
            out.run_busy_fp = list(self.run_busy_fp)
        return out

    def absorb(self, other: "Unit") -> None:
        """Add what ``other`` counted (this unit, on the machine that replayed other passes of the run):
        ``TOTALS`` added, ``COUNTERS`` merged as they say; a sampled program's :attr:`run_busy_fp` added, the
        busy sub-cycles standing for it where a machine had none (its sample kept the whole load)."""
        if self.run_busy_fp is not None or other.run_busy_fp is not None:
            self.run_busy_fp = [x + y for x, y in zip(self.busy_fp if self.run_busy_fp is None else self.run_busy_fp,
                                                      other.busy_fp if other.run_busy_fp is None
                                                      else other.run_busy_fp)]
        for a in dict.fromkeys((*self.TOTALS, *self.COUNTERS)):
            how = self.COUNTERS.get(a, operator.add)
            mine, theirs = getattr(self, a), getattr(other, a)
            setattr(self, a, [how(x, y) for x, y in zip(mine, theirs)] if isinstance(mine, list)
                    else how(mine, theirs))

    # the interface the core and the machine use
    def serve(self, wi: int, now: int):
        raise NotImplementedError

    def idle_at(self) -> int:
        return 0

    def blocked(self) -> list[str]:
        """What the unit is stuck on (the no-progress diagnosis)."""
        return []

    def values(self, total_cycles: int) -> dict[str, list | float]:
        """Each declared stat's value: a list per instance, or one value."""
        busy = [b / FP for b in self.busy_fp]
        return {"busy_cycles": busy, "requests": list(self.requests),
                "utilisation": [b / total_cycles if total_cycles else 0.0 for b in busy]}

    #: a sampled program (``Program.occupancy``): per instance, the sub-cycles its requests hold it, the other
    #: requests that came with them included (the run's busy cycles, estimated); None for a whole run
    run_busy_fp: list | None = None

    def summary(self, total_cycles: int) -> dict:
        """The unit over all its instances (``replay --json``'s ``timing.units``); a sampled program's shared
        unit adds ``run_busy_cycles`` (:attr:`run_busy_fp`)."""
        busy = [b / FP for b in self.busy_fp]
        util = [b / total_cycles if total_cycles else 0.0 for b in busy]
        out = {"instances": self.instances, "requests": int(sum(self.requests)),
               "busy_cycles": float(sum(busy)), "utilisation_mean": float(sum(util) / len(util)),
               "utilisation_max": float(max(util))}
        if self.run_busy_fp is not None:
            out["run_busy_cycles"] = float(sum(self.run_busy_fp)) / FP
        return out

    def line_trace(self) -> str:
        """One line of the unit's state for debugging (PyMTL style): the cycle each of its first instances is
        free (``runner.trace_every`` prints it as a run goes)."""
        free = getattr(self, "free", None)
        if free is None:
            return f"{self.name}: -"
        return f"{self.name}: free " + " ".join(f"[{i}]{cycles(f)}" for i, f in enumerate(free[:8]))


#: name -> unit class (registration order); filled by @register_unit as the unit modules are imported
UNITS: dict[str, type[Unit]] = {}
#: TOML section -> config dataclass: every unit's, plus the sections no unit owns (runner, sample)
SECTIONS: dict[str, type] = {}


def register_section(name: str, config: type) -> None:
    """Declare a GPU-config section (a TOML table) built into ``config``."""
    if name in SECTIONS and SECTIONS[name] is not config:
        raise ValueError(f"GPU config section {name!r} registered twice")
    SECTIONS[name] = config


def register_unit(cls: type[Unit]) -> type[Unit]:
    """Class decorator: register a unit under ``cls.name``, with its config section."""
    if cls.name in UNITS and UNITS[cls.name] is not cls:
        raise ValueError(f"unit {cls.name!r} registered twice")
    if cls.Config is None:
        raise ValueError(f"unit {cls.name!r} declares no Config")
    UNITS[cls.name] = cls
    register_section(cls.name, cls.Config)
    return cls


def unregister_unit(name: str) -> None:
    """Remove a unit and its section (a test's toy unit)."""
    UNITS.pop(name, None)
    SECTIONS.pop(name, None)


def unit_class(name: str) -> type[Unit]:
    """The unit registered as ``name``; unknown names fail listing the valid ones."""
    if name not in UNITS:
        raise KeyError(f"unknown unit {name!r} (valid: {', '.join(UNITS)})")
    return UNITS[name]


def entry_unit(op: str) -> str:
    """The unit the SIMT core issues operation ``op`` to."""
    for name, cls in UNITS.items():
        if op in cls.issued:
            return name
    raise KeyError(f"no registered unit takes operation {op!r} from the core")
