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

import numpy as np

from gpusim.hw.lower import SCOREBOARD, Program, scoreboard_cell
from gpusim.hw.units import Signal, Unit, UnitStat


class Scoreboard(Unit):
    name = "scoreboard"
    COUNTERS = {"stalls": operator.add, "max_held": max, "requests": operator.add}   # merged across processes

    def __init__(self, gpu, program: Program, width: int, fire, at):
        super().__init__(1)
        self.fire, self.at = fire, at           # wake waiting warps now; run a callable at a later cycle
        self.entries = gpu.scoreboard.entries
        self.held: dict[int, object] = {}       # cell -> Signal of its release (None until someone waits)
        self.room: deque = deque()              # warps waiting for room in a full scoreboard, in order
        self.stalls = 0
        self.max_held = 0
        self.table = {}
        rows = program.rows_of(SCOREBOARD)
        for wi in np.flatnonzero(program.wi_class == SCOREBOARD).tolist():
            r = program.rows(wi)
            self.table[wi] = scoreboard_cell(program.frag_pixel[rows.thread[r]], width, gpu.scoreboard.granularity).tolist()

    def acquire(self, wi: int):
        """The warp's cells if it may dispatch now, else a Signal to wait on and retry."""
        cells = self.table[wi]
        held = self.held
        for c in cells:
            if c in held:
                self.stalls += 1
                ev = held[c]
                if ev is None:
                    ev = held[c] = Signal()
                self._wake_next()
                return ev
        if len(held) + len(cells) > self.entries:
            self.stalls += 1
            ev = Signal()
            self.room.append(ev)
            return ev
        for c in cells:
            held[c] = None
        self.requests[0] += len(cells)
        self.max_held = max(self.max_held, len(held))
        self._wake_next()
        return cells

    def _wake_next(self) -> None:
        """Let the next warp waiting for room retry (one at a time: no stampede)."""
        if self.room and len(self.held) < self.entries:
            self.fire(self.room.popleft())

    def release(self, cells: list[int], at: int) -> None:
        """Free ``cells`` at cycle ``at`` (the warp's last operation completes)."""
        def done():
            for c in cells:
                ev = self.held.pop(c)
                if ev is not None:
                    self.fire(ev)
            self._wake_next()
        self.at(at, done)

    def blocked(self) -> list[str]:
        waiting = sum(1 for ev in self.held.values() if ev is not None) + len(self.room)
        if waiting:
            return [f"scoreboard: {len(self.held)}/{self.entries} cells held; warps wait on {waiting} of them"]
        return []

    def stats(self, total_cycles):
        return [UnitStat(self.name, "dispatches", self.requests[0], "fragments", "fragments dispatched"),
                UnitStat(self.name, "stalls", self.stalls, "attempts", "dispatch attempts held back"),
                UnitStat(self.name, "max_held", self.max_held, "cells", "most cells in flight at once")]

    def summary(self, total_cycles):
        return {"instances": 1, "requests": self.requests[0], "stalls": self.stalls, "max_held": self.max_held,
                "entries": self.entries, "busy_cycles": 0.0, "utilisation_mean": self.max_held / self.entries,
                "utilisation_max": self.max_held / self.entries}
