"""Scoreboard at fragment dispatch (k-buffer proposal 1, seed 004 section 3.1.1).

A coarse image of the fragments in flight: cells of ``scoreboard.granularity``
x ``granularity`` pixels. A warp's ``scoreboard`` instruction dispatches it
only when none of its lanes' cells is held by a warp still in flight and the
scoreboard has room for its cells (``scoreboard.entries``); the warp then holds
its cells until its last operation completes. Dispatch packs no two fragments
of one cell into a warp (gpusim.hw.lower), so a warp never waits for itself.
Fragments whose cell is busy wait (the proposal's holding buffer is not
modelled: the warp stalls, which is the proposal's behaviour once that buffer
overflows).
"""

from __future__ import annotations

import operator
from collections import deque
from dataclasses import dataclass

import numpy as np

from gpusim.config import param
from gpusim.hw.unit import Stat, Unit, register_unit
from gpusim.opplan import OPS


@dataclass(frozen=True)
class ScoreboardConfig:
    """Scoreboard at fragment dispatch (k-buffer proposal 1, seed 004 section 3.1.1)."""

    entries: int = param(1024, unit="cells", doc="cells of the coarse in-flight image that can be held", min=1)
    granularity: int = param(1, unit="pixels", doc="cell edge: a cell covers granularity x granularity pixels",
                             min=1)


def scoreboard_cell(pixel: np.ndarray, width: int, granularity: int) -> np.ndarray:
    """Cell of the coarse in-flight image holding each pixel (granularity x granularity pixels)."""
    x, y = pixel % width, pixel // width
    cells_x = -(-width // granularity)
    return (y // granularity) * cells_x + x // granularity


@register_unit
class Scoreboard(Unit):
    name = "scoreboard"
    Config = ScoreboardConfig
    issued = frozenset({"scoreboard"})
    STATS = (Stat("requests", "fragments", "fragments dispatched"),
             Stat("stalls", "attempts", "dispatch attempts held back"),
             Stat("max_held", "cells", "most cells in flight at once"))
    COUNTERS = {"stalls": operator.add, "max_held": max, "requests": operator.add}   # merged across processes
    KEPT = ("instances", "entries")

    def __init__(self, config: ScoreboardConfig, machine):
        super().__init__(1)
        self.env = machine.env
        self.entries = config.entries
        self.held: dict[int, object] = {}       # cell -> event of its release (None until someone waits)
        self.room: deque = deque()              # events of warps waiting for room in a full scoreboard, in order
        self.holding: dict[int, list] = {}      # warp -> the cells it holds
        self.stalls = 0
        self.max_held = 0
        self.pending = 0                        # releases scheduled and not yet done
        prog = machine.program
        self.warp_of = prog.wi_warp.tolist()
        rows = prog.rows_of(self.name)
        self.table = {}
        for wi in np.flatnonzero(prog.wi_op == OPS.index("scoreboard")).tolist():
            r = prog.rows(wi)
            self.table[wi] = scoreboard_cell(prog.frag_pixel[rows.thread[r]], machine.width,
                                             config.granularity).tolist()
        machine.warp_end_hooks.append(self.warp_done)

    def serve(self, wi: int, now: int):
        """``now`` once the warp's cells are taken, else an event to wait for and try again."""
        cells = self.table[wi]
        held = self.held
        for c in cells:
            if c in held:
                self.stalls += 1
                ev = held[c]
                if ev is None:
                    ev = held[c] = self.env.event()
                self._wake_next()
                return ev
        if len(held) + len(cells) > self.entries:
            self.stalls += 1
            ev = self.env.event()
            self.room.append(ev)
            return ev
        for c in cells:
            held[c] = None
        self.requests[0] += len(cells)
        self.max_held = max(self.max_held, len(held))
        self.holding.setdefault(self.warp_of[wi], []).extend(cells)
        self._wake_next()
        return now

    def _wake_next(self) -> None:
        """Let the next warp waiting for room retry (one at a time: no stampede)."""
        if self.room and len(self.held) < self.entries:
            self.room.popleft().succeed()

    def warp_done(self, warp: int, at: int) -> None:
        """Warp ``warp``'s last operation completes at cycle ``at``: its cells free then."""
        cells = self.holding.pop(warp, None)
        if cells is None:
            return

        def release(_event):
            self.pending -= 1
            for c in cells:
                ev = self.held.pop(c)
                if ev is not None:
                    ev.succeed()
            self._wake_next()
        self.pending += 1
        self.env.timeout(max(at - self.env.now, 0)).callbacks.append(release)

    def blocked(self) -> list[str]:
        waiting = sum(1 for ev in self.held.values() if ev is not None) + len(self.room)
        if waiting:
            return [f"scoreboard: {len(self.held)}/{self.entries} cells held; warps wait on {waiting} of them"]
        return []

    def line_trace(self) -> str:
        return f"scoreboard: {len(self.held)}/{self.entries} cells held, {len(self.room)} warps wait for room"

    def values(self, total_cycles: int) -> dict:
        return {"requests": self.requests[0], "stalls": self.stalls, "max_held": self.max_held}

    def summary(self, total_cycles: int) -> dict:
        return {"instances": 1, "requests": self.requests[0], "stalls": self.stalls, "max_held": self.max_held,
                "entries": self.entries, "busy_cycles": 0.0, "utilisation_mean": self.max_held / self.entries,
                "utilisation_max": self.max_held / self.entries}
