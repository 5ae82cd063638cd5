"""What every hardware unit shares: fixed-point occupancy, per-unit stats, a one-line trace.

Time is integer cycles. A unit with a throughput that is not a whole number of
cycles per operation (13.67 bytes per cycle) keeps its occupancy in integer
sub-cycles (``FP`` per cycle), so long runs accumulate no rounding: a request
is served from ``max(arrival, free)`` for ``ceil(work * FP / rate)``
sub-cycles, and the times handed back to the event model are whole cycles
(rounded up).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

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


@dataclass(frozen=True)
class UnitStat:
    """One stat of one unit instance (gem5 style: registered on the unit, with a unit and a description)."""

    unit: str            # unit path, e.g. "dram"
    stat: str
    value: float
    unit_of_measure: str
    doc: str
    instance: int | None = None     # a label, never part of the name

    def row(self) -> dict:
        return {"unit": self.unit, "instance": self.instance, "stat": self.stat, "value": self.value,
                "unit_of_measure": self.unit_of_measure, "doc": self.doc}


class Unit:
    """Base of the hardware units: a name, per-instance busy sub-cycles and request counts."""

    name = "unit"

    def __init__(self, instances: int):
        self.instances = instances
        self.busy_fp = [0] * instances
        self.requests = [0] * instances

    def stats(self, total_cycles: int) -> list[UnitStat]:
        rows = []
        for i in range(self.instances):
            busy = self.busy_fp[i] / FP
            rows += [UnitStat(self.name, "busy_cycles", busy, "cycles", "cycles the instance was serving", i),
                     UnitStat(self.name, "requests", self.requests[i], "requests", "requests served", i),
                     UnitStat(self.name, "utilisation", busy / total_cycles if total_cycles else 0.0, "1",
                              "busy cycles / run cycles", i)]
        return rows

    def summary(self, total_cycles: int) -> dict:
        busy = [b / FP for b in self.busy_fp]
        util = [b / total_cycles if total_cycles else 0.0 for b in busy]
        return {"instances": self.instances, "requests": int(sum(self.requests)),
                "busy_cycles": float(sum(busy)), "utilisation_mean": float(sum(util) / len(util)),
                "utilisation_max": float(max(util))}

    def line_trace(self) -> str:
        """One line of state for debugging (PyMTL style)."""
        return f"{self.name}: " + " ".join(f"[{i}] busy={self.busy_fp[i] // FP} req={self.requests[i]}"
                                           for i in range(min(self.instances, 8)))


class Signal:
    """Warps waiting on a unit's condition (a free reorder-buffer entry, a committed result, a released
    scoreboard cell); the unit hands them back to the machine with ``Machine.fire`` at the current cycle."""

    __slots__ = ("waiters",)

    def __init__(self):
        self.waiters: list = []


def div(a, d: int):
    """``a // d`` for non-negative integer arrays (a shift when ``d`` is a power of two)."""
    return a >> (d.bit_length() - 1) if d & (d - 1) == 0 else a // d


def mod(a, d: int):
    """``a % d`` for non-negative integer arrays (a mask when ``d`` is a power of two)."""
    return a & (d - 1) if d & (d - 1) == 0 else a % d


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

