"""The event model: SIMT cores replaying warp instructions through the units (simpy).

One simpy Environment per run owns all state. Each SM runs up to
``core.warps_per_sm`` resident warps; warps go to SMs round robin in
submission order and a finished warp's slot takes the SM's next warp. A warp
issues its instructions in program order through the SM's issue port (each
instruction and the ``core.instructions_per_op`` ALU instructions around it
hold the port ``core.issue_cycles`` each); an instruction that depends on the
thread's previous result waits for it, and other warps of the SM issue
meanwhile (latency hiding). Units are timestamp servers (gpusim.hw.units):
serving a request is arithmetic on the unit's free time, so an instruction
costs one simpy event unless it must wait for another warp (a reorder buffer,
the scoreboard).

Geometry passes of the graphics pipeline get their fragments from a
fixed-function rasterizer (``raster.triangles_per_cycle``): a warp starts once
the triangles of its fragments are rasterized, and the pass lasts at least as
long as rasterizing every triangle (each depth-peeling pass pays it again). A
software rasterizer (the ``triangle`` mapping) instead issues
``raster.setup_instructions`` per triangle in its thread.

Passes are barriers: a pass ends when its last operation has completed
(stores landed, the ROPs drained). A ``flush`` pass (the k-buffer's batching
heuristic) drains the pipeline (``core.pipeline_latency``) and runs a
full-screen quad of ALU-only fragments.

Units no instruction reaches are not built. A run that makes no progress for
``runner.no_progress_cycles`` fails naming the unit and queue it is stuck on;
``runner.max_cycles`` bounds the run.
"""

from __future__ import annotations

from collections import deque

import numpy as np
import simpy

from gpusim.errors import GpusimError
from gpusim.hw.atomic import AtomicUnits
from gpusim.hw.lower import ATOMIC, MEM, ROP, SCOREBOARD, Program
from gpusim.hw.memory import Partitions
from gpusim.hw.rop import RopUnits
from gpusim.hw.scoreboard import Scoreboard
from gpusim.schemes.opstream import OPS


class NoProgress(GpusimError):
    """The event model stopped making progress (a diagnosis names the unit and queue)."""


def flush_cycles(gpu, warps: int) -> int:
    """A flush: drain the pipeline, then a full-screen quad of ``warps`` ALU-only warps."""
    per_sm = -(-warps // gpu.core.sms)
    return gpu.core.pipeline_latency + per_sm * gpu.core.issue_cycles * (1 + gpu.core.instructions_per_op)


class Machine:
    """A GPU built for one program: only the units its instructions reach."""

    def __init__(self, gpu, program: Program, width: int):
        self.gpu, self.prog = gpu, program
        self.env = simpy.Environment()
        classes = program.classes()
        self.partitions = Partitions(gpu, program) if MEM in classes else None
        self.atomics = AtomicUnits(gpu, program) if ATOMIC in classes else None
        self.rop = RopUnits(gpu, program, self.env) if ROP in classes else None
        self.scoreboard = Scoreboard(gpu, program, width, self.env) if SCOREBOARD in classes else None
        self.sm_free = [0] * gpu.core.sms
        self.issue_cost = gpu.core.issue_cycles * (1 + gpu.core.instructions_per_op)
        self.progress = 0
        self.waiting: dict[int, str] = {}
        self.pass_cycles: list[int] = []
        self.finished = False
        self._done = 0
        # plain lists: the hot loop indexes them per instruction
        self._cls = program.wi_class.tolist()
        self._dep = program.wi_dep.tolist()
        self._prod = program.wi_produces.tolist()

    # ------------------------------------------------------------------ build
    def built_units(self) -> list[str]:
        names = []
        if self.partitions is not None:
            names += [u.name for u in (self.partitions.l2, self.partitions.dram) if u is not None]
        names += [u.name for u in (self.atomics, self.rop, self.scoreboard) if u is not None]
        return names

    def units(self):
        out = list(self.partitions.units()) if self.partitions is not None else []
        return out + [u for u in (self.atomics, self.rop, self.scoreboard) if u is not None]

    # ------------------------------------------------------------------- run
    def run(self) -> int:
        """Simulate every pass; the total cycles."""
        env, r = self.env, self.gpu.runner
        main = env.process(self._passes())
        env.process(self._watchdog())
        env.run(until=env.any_of([main, env.timeout(r.max_cycles)]))    # NoProgress propagates
        if not self.finished:
            raise GpusimError(f"the run passed runner.max_cycles = {r.max_cycles:,} cycles before finishing "
                              f"(pass {len(self.pass_cycles)} of {len(self.prog.passes)}); raise "
                              f"--gpu-set runner.max_cycles=N or use a smaller trace")
        return int(env.now)

    def _passes(self):
        env = self.env
        for p in self.prog.passes:
            start = env.now
            if p.kind == "flush":
                yield env.timeout(flush_cycles(self.gpu, p.flush_warps))
            elif p.warps:
                self._done = start
                procs = []
                sms = self.gpu.core.sms
                for sm in range(min(sms, p.warps)):
                    queue = deque(range(sm, p.warps, sms))
                    for _ in range(min(self.gpu.core.warps_per_sm, len(queue))):
                        procs.append(env.process(self._slot(p, sm, queue)))
                yield env.all_of(procs)
                end = max(self._done, self.rop.drain if self.rop is not None else 0, start + p.min_cycles)
                if end > env.now:
                    yield env.timeout(end - env.now)
            self.pass_cycles.append(int(env.now - start))
        self.finished = True

    def _slot(self, p, sm, queue):
        start = self.env.now
        while queue:
            w = queue.popleft()
            if p.warp_ready is not None and start + int(p.warp_ready[w]) > self.env.now:
                yield self.env.timeout(start + int(p.warp_ready[w]) - self.env.now)   # rasterizer not there yet
            if p.setup_cycles:             # software triangle setup holds the SM's issue port
                self.sm_free[sm] = max(self.sm_free[sm], self.env.now) + p.setup_cycles
            yield from self._warp(p, int(p.wi_start[w]), int(p.wi_start[w + 1]), sm, w)

    def _warp(self, p, wi0, wi1, sm, w):
        env, cost = self.env, self.issue_cost
        cls_of, dep_of, prod_of = self._cls, self._dep, self._prod
        sm_free = self.sm_free
        value_ready = floor = done_max = env.now
        cells = None
        for wi in range(wi0, wi1):
            now = env.now
            ready = floor if floor > now else now
            if dep_of[wi] and value_ready > ready:
                ready = value_ready
            if ready > now:
                yield env.timeout(ready - now)
                now = ready
            t = sm_free[sm]
            if t < now:
                t = now
            sm_free[sm] = t + cost
            if t > now:
                yield env.timeout(t - now)
            self.progress += 1
            cls = cls_of[wi]
            if cls == MEM:
                done = self.partitions.access(wi, t)
            elif cls == ATOMIC:
                done = self.atomics.access(wi, t)
            elif cls == ROP:
                floor, done = yield from self._until_answered(
                    lambda: self.rop.access(wi, t, prod_of[wi]), w,
                    lambda: f"warp {w} of pass '{p.name}' on SM {sm}, instruction {wi} ({self._what(wi)})")
            else:                                   # SCOREBOARD
                cells = yield from self._until_answered(
                    lambda: self.scoreboard.acquire(wi), w,
                    lambda: f"warp {w} of pass '{p.name}' on SM {sm} at the scoreboard")
                done = floor = env.now
            if prod_of[wi]:
                value_ready = done
            if done > done_max:
                done_max = done
        if done_max > self._done:
            self._done = done_max
        if cells is not None:
            self.scoreboard.release(cells, done_max)

    def _until_answered(self, ask, w: int, where):
        """``ask()`` until it answers rather than handing back an event to wait on (a unit's queue)."""
        while True:
            res = ask()
            if not isinstance(res, simpy.Event):
                return res
            self.waiting[w] = where()
            yield res
            del self.waiting[w]
            self.progress += 1

    def _what(self, wi: int) -> str:
        r = self.prog.rows(wi)
        return f"{OPS[int(self.prog.wi_op[wi])]} x{r.stop - r.start}"

    def _watchdog(self):
        limit = self.gpu.runner.no_progress_cycles
        last = -1
        while not self.finished:
            yield self.env.timeout(limit)
            if self.finished:
                return
            if self.progress == last:
                raise NoProgress(self.diagnosis(limit))
            last = self.progress

    def diagnosis(self, limit: int) -> str:
        stuck = []
        for u in (self.rop, self.scoreboard):
            if u is not None:
                stuck += u.blocked()
        warps = list(self.waiting.values())
        where = "; ".join(stuck) or "no unit reports a queue"
        first = f"; first waiting: {warps[0]}" if warps else ""
        return (f"no progress for {limit:,} cycles at cycle {int(self.env.now):,} "
                f"(pass {len(self.pass_cycles)}): {where}; {len(warps)} warp(s) waiting{first}. "
                f"This is a deadlock in the modelled machine: check the GPU config (e.g. rop.reorder_entries, "
                f"scoreboard.entries) or raise runner.no_progress_cycles if the run is only slow")

    # ----------------------------------------------------------------- stats
    def unit_summaries(self, total: int) -> dict:
        out = {}
        for u in self.units():
            out[u.name] = u.summary(total)
        core_busy = self.prog.instructions * self.issue_cost
        out["core"] = {"instances": self.gpu.core.sms, "requests": int(self.prog.instructions),
                       "busy_cycles": float(core_busy),
                       "utilisation_mean": core_busy / (total * self.gpu.core.sms) if total else 0.0,
                       "utilisation_max": (float(max(np.bincount(self.prog.wi_warp % self.gpu.core.sms)))
                                           * self.issue_cost / total) if total and self.prog.instructions else 0.0}
        return out

    def unit_stats(self, total: int) -> list[dict]:
        return [s.row() for u in self.units() for s in u.stats(total)]

    def line_trace(self) -> str:
        parts = [f"t={int(self.env.now)} progress={self.progress} waiting={len(self.waiting)}"]
        if self.partitions is not None:
            parts.append(self.partitions.line_trace())
        parts += [u.line_trace() for u in (self.atomics, self.rop, self.scoreboard) if u is not None]
        return " | ".join(parts)
