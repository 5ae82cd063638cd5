"""The event model: SIMT cores replaying warp instructions through the units.

A discrete-event machine with its own event queue: a heap of (cycle, order of
scheduling, what happens), processed in time order, ties in the order they
were scheduled. One Machine per run owns all state (the clock, the queue, the
units). Units are timestamp servers (gpusim.hw.units): serving a request is
arithmetic on the unit's free time, done at the cycle the request issues, so
requests reach every unit in time order and an instruction costs one queue
entry unless it must wait for another warp (a reorder buffer, the scoreboard),
which the unit signals (``Signal``) when it clears.

Each SM runs up to ``core.warps_per_sm`` resident warps; warps go to SMs round
robin in submission order and a finished warp's slot takes the SM's next warp.
A warp issues its instructions in program order through the SM's issue port
(each instruction and the ``core.instructions_per_op`` ALU instructions around
it hold the port ``core.issue_cycles`` each; warps take the port in the order
they ask for it); an instruction that depends on the thread's previous result
waits for it, and other warps of the SM issue meanwhile (latency hiding).

Geometry passes of the graphics pipeline get their fragments from a
fixed-function rasterizer (``raster.triangles_per_cycle``): a warp starts once
the triangles of its fragments are rasterized, and the pass lasts at least as
long as rasterizing every triangle it submits (each depth-peeling pass pays the
whole scene again; a batch of the k-buffer's heuristic only its own). A
software rasterizer (the ``triangle`` mapping) instead issues
``raster.setup_instructions`` per triangle in its thread.

Passes are barriers: a pass ends when its last operation has completed
(stores landed, the ROPs drained). A ``flush`` pass (the k-buffer's batching
heuristic) drains the pipeline (``core.pipeline_latency``) and runs a
full-screen quad of ALU-only fragments.

Units no instruction reaches are not built. A run that makes no progress for
``runner.no_progress_cycles`` (a deadlock: warps wait on each other and
nothing is left to happen) fails naming the unit and queue it is stuck on;
``runner.max_cycles`` bounds the run.
"""

from __future__ import annotations

import gc
import math
from collections import deque
from functools import cached_property
from heapq import heappop, heappush
from itertools import count

import numpy as np

from gpusim.errors import GpusimError
from gpusim.hw.atomic import AtomicUnits
from gpusim.hw.lower import ATOMIC, MEM, ROP, SCOREBOARD, Program
from gpusim.hw.memory import Partitions
from gpusim.hw.parallel import plan_shares, run_shares
from gpusim.hw.rop import RopUnits
from gpusim.hw.scoreboard import Scoreboard
from gpusim.hw.units import Signal
from gpusim.opplan import OPS


class NoProgress(GpusimError):
    """The event model stopped making progress (a diagnosis names the unit and queue)."""


def flush_cycles(gpu, warps: int) -> int:
    """A flush: drain the pipeline, then a full-screen quad of ``warps`` ALU-only warps."""
    per_sm = -(-warps // gpu.core.sms)
    return gpu.core.pipeline_latency + per_sm * gpu.core.issue_cycles * (1 + gpu.core.instructions_per_op)


# a warp in flight: [next instruction, end, SM, warp, value ready, floor, last completion, cells, phase, queue]
WI, END, SM, WARP, VALUE, FLOOR, DONE, CELLS, PHASE, QUEUE = range(10)
START, READY, ISSUE = 0, 1, 2      # phases: about to start (setup), next instruction to try, issue now


class Machine:
    """A GPU built for one program: only the units its instructions reach."""

    def __init__(self, gpu, program: Program, width: int):
        self.gpu, self.prog = gpu, program
        self.now = 0
        self._queue: list = []
        self._order = count()
        classes = program.classes()
        self.partitions = Partitions(gpu, program) if MEM in classes else None
        self.atomics = AtomicUnits(gpu, program) if ATOMIC in classes else None
        self.rop = RopUnits(gpu, program, self.fire) if ROP in classes else None
        self.scoreboard = Scoreboard(gpu, program, width, self.fire, self.at) if SCOREBOARD in classes else None
        self.sm_free = [0] * gpu.core.sms
        self.issue_cost = gpu.core.issue_cycles * (1 + gpu.core.instructions_per_op)
        self.progress = 0
        self.waiting: dict[int, tuple] = {}        # warp -> (pass, SM, instruction, unit) it waits on
        self.pass_cycles: list[int] = []
        self.current_pass = 0
        self.finished = False

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

    # ------------------------------------------------------------- the queue
    def at(self, cycle: int, what) -> None:
        """Run the callable ``what`` at ``cycle`` (not before now)."""
        heappush(self._queue, (max(cycle, self.now), next(self._order), what))

    def fire(self, signal: Signal) -> None:
        """Hand the warps waiting on ``signal`` back to the queue at the current cycle."""
        for st in signal.waiters:
            del self.waiting[st[WARP]]
            heappush(self._queue, (self.now, next(self._order), st))
        signal.waiters = []

    # ------------------------------------------------------------------- run
    def run(self) -> int:
        """Simulate every pass; the total cycles.

        Python's cyclic garbage collector is paused meanwhile: the event loop
        makes no reference cycles, but its millions of short-lived queue
        entries would trigger a collection every few hundred (about a fifth of
        the run time); it is restored on the way out.
        """
        collecting = gc.isenabled()
        gc.disable()
        try:
            return self._run()
        finally:
            if collecting:
                gc.enable()

    def _run(self) -> int:
        shares = plan_shares(self)
        if len(shares) > 1 and run_shares(self, shares):
            return int(self.now)
        self.pass_cycles = [c for _, c in self.run_share(range(len(self.prog.passes)))]
        self.finished = True
        return int(self.now)

    def run_share(self, indices) -> list[tuple[int, int]]:
        """Simulate the passes ``indices`` (ascending) one after the other from the current cycle; each one's
        (start cycle, cycles). A pass starts on an idle machine, so its cycles do not depend on the passes
        before it: shares of the passes can run in separate processes (gpusim.hw.parallel)."""
        indices = list(indices)
        if self.rop is not None and len(indices) < len(self.prog.passes):
            self.rop.assume_committed(indices)
        out = []
        for i in indices:
            p = self.prog.passes[i]
            self.current_pass = i
            start = self.now
            if p.kind == "flush":
                self.now += flush_cycles(self.gpu, p.flush_warps)
            elif p.warps:
                self._run_pass(p)
            self._guard_max(self.now)
            out.append((int(start), int(self.now - start)))
        return out

    def counters(self) -> dict:
        """What a run changed besides time (merged across the processes of a parallel run)."""
        out = {"progress": self.progress}
        for u in (self.rop, self.scoreboard):
            if u is not None:
                out[u.name] = {a: getattr(u, a) for a in u.COUNTERS}
        return out

    def merge_counters(self, got: dict) -> None:
        self.progress += got["progress"]
        for u in (self.rop, self.scoreboard):
            if u is not None:
                for a, how in u.COUNTERS.items():
                    mine, theirs = getattr(u, a), got[u.name][a]
                    if isinstance(mine, list):
                        setattr(u, a, [how(x, y) for x, y in zip(mine, theirs)])
                    else:
                        setattr(u, a, how(mine, theirs))

    def _guard_max(self, cycle: int, index: int | None = None) -> None:
        limit = self.gpu.runner.max_cycles
        if cycle > limit:
            raise GpusimError(f"the run passed runner.max_cycles = {limit:,} cycles before finishing "
                              f"(pass {self.current_pass if index is None else index} of {len(self.prog.passes)}); "
                              f"raise --gpu-set runner.max_cycles=N or use a smaller trace")

    def _run_pass(self, p) -> None:
        gpu = self.gpu
        start = self.now
        sms, rate = gpu.core.sms, gpu.raster.triangles_per_cycle
        ready = None
        min_end = start
        if p.warp_triangles is not None:      # the fixed-function rasterizer
            ready = (start + np.ceil(p.warp_triangles / rate).astype(np.int64)).tolist()
            min_end = start + math.ceil(p.triangles / rate)
        wi_start = p.wi_start.tolist()
        for sm in range(min(sms, p.warps)):
            waiting = deque(range(sm, p.warps, sms))
            for _ in range(min(gpu.core.warps_per_sm, len(waiting))):
                self._start(waiting, sm, start, wi_start, ready)
        done = self._loop(p, wi_start, ready)
        # a barrier: the pass ends when its last operation has completed and every unit is idle again, so the
        # next pass starts on an idle machine (its cycles do not depend on when it starts)
        end = max(done, min_end, max(self.sm_free),
                  *(u.idle_at() for u in (self.partitions, self.atomics, self.rop) if u is not None))
        self._guard_max(end)
        self.now = end

    def _start(self, waiting: deque, sm: int, t: int, wi_start, ready) -> None:
        """The SM slot takes its next warp at cycle ``t`` (once the rasterizer has its triangles)."""
        w = waiting.popleft()
        if ready is not None and ready[w] > t:
            t = ready[w]
        heappush(self._queue, (t, next(self._order), [wi_start[w], wi_start[w + 1], sm, w, t, t, t, None, START,
                                                     waiting]))

    def _loop(self, p, wi_start, ready) -> int:
        """Process the queue until the pass's warps are done; the cycle its last operation completes."""
        queue, order = self._queue, self._order
        cls_of, dep_of, prod_of = self._instruction_lists
        sm_free, cost, setup = self.sm_free, self.issue_cost, p.setup_cycles
        mem = self.partitions.access if self.partitions is not None else None
        atom = self.atomics.access if self.atomics is not None else None
        rop, sb = self.rop, self.scoreboard
        limit = self.gpu.runner.no_progress_cycles
        max_cycles = self.gpu.runner.max_cycles
        now = self.now
        last_progress = now
        done_all = now
        while queue:
            t, _, st = heappop(queue)
            if t > now:
                if t - last_progress > limit:
                    self.now = last_progress + limit
                    raise NoProgress(self.diagnosis(limit))
                if t > max_cycles:
                    self._guard_max(t)
                now = self.now = t
            if type(st) is not list:          # a unit's timed event (a scoreboard release)
                st()
                continue
            phase = st[PHASE]
            if phase == START:
                if setup:                      # software triangle setup holds the SM's issue port
                    sm = st[SM]
                    sm_free[sm] = (sm_free[sm] if sm_free[sm] > now else now) + setup
                phase = READY
            while True:
                wi = st[WI]
                if phase == READY:
                    if wi == st[END]:          # the warp is done; its slot takes the SM's next warp
                        if st[DONE] > done_all:
                            done_all = st[DONE]
                        if st[CELLS] is not None:
                            sb.release(st[CELLS], st[DONE])
                        if st[QUEUE]:
                            self._start(st[QUEUE], st[SM], now, wi_start, ready)
                        break
                    r = st[FLOOR] if st[FLOOR] > now else now
                    if dep_of[wi] and st[VALUE] > r:
                        r = st[VALUE]
                    if r > now:                # wait for the result it depends on
                        st[PHASE] = READY
                        heappush(queue, (r, next(order), st))
                        break
                    sm = st[SM]
                    ti = sm_free[sm] if sm_free[sm] > now else now
                    sm_free[sm] = ti + cost
                    if ti > now:               # the issue port is taken until ti
                        st[PHASE] = ISSUE
                        heappush(queue, (ti, next(order), st))
                        break
                # issue instruction wi at cycle now
                cls = cls_of[wi]
                if cls == MEM:
                    d = mem(wi, now)
                elif cls == ATOMIC:
                    d = atom(wi, now)
                elif cls == ROP:
                    res = rop.access(wi, now, now, prod_of[wi])
                    if type(res) is Signal:
                        self._wait(st, res, p, wi, "rop")
                        break
                    st[FLOOR], d = res
                else:                          # SCOREBOARD
                    res = sb.acquire(wi)
                    if type(res) is Signal:
                        self._wait(st, res, p, wi, "scoreboard")
                        break
                    st[CELLS] = res
                    d = st[FLOOR] = now
                self.progress += 1
                last_progress = now
                if prod_of[wi]:
                    st[VALUE] = d
                if d > st[DONE]:
                    st[DONE] = d
                st[WI] = wi + 1
                phase = READY
        if self.waiting:                       # warps wait on each other and nothing is left to happen
            self.now = last_progress + limit
            raise NoProgress(self.diagnosis(limit))
        return done_all

    @cached_property
    def _instruction_lists(self) -> tuple[list, list, list]:
        """Each instruction's unit class, whether it waits for a result, whether it produces one (as lists,
        made once: the loop indexes them per instruction)."""
        prog = self.prog
        return prog.wi_class.tolist(), prog.wi_dep.tolist(), prog.wi_produces.tolist()

    def _wait(self, st, signal: Signal, p, wi: int, unit: str) -> None:
        st[PHASE] = ISSUE                      # retry the same instruction when the unit signals
        signal.waiters.append(st)
        self.waiting[st[WARP]] = (p.name, st[SM], wi, unit)

    def _what(self, wi: int) -> str:
        r = self.prog.rows(wi)
        return f"{OPS[int(self.prog.wi_op[wi])]} x{r.stop - r.start}"

    def diagnosis(self, limit: int) -> str:
        stuck = []
        for u in (self.rop, self.scoreboard):
            if u is not None:
                stuck += u.blocked()
        where = "; ".join(stuck) or "no unit reports a queue"
        first = ""
        if self.waiting:
            w, (name, sm, wi, unit) = next(iter(self.waiting.items()))
            first = (f"; first waiting: warp {w} of pass '{name}' on SM {sm}, instruction {wi} "
                     f"({self._what(wi)}) at the {unit}")
        return (f"no progress for {limit:,} cycles at cycle {int(self.now):,} "
                f"(pass {self.current_pass}): {where}; {len(self.waiting)} warp(s) waiting{first}. "
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
        parts = [f"t={int(self.now)} progress={self.progress} waiting={len(self.waiting)} queued={len(self._queue)}"]
        if self.partitions is not None:
            parts.append(self.partitions.line_trace())
        parts += [u.line_trace() for u in (self.atomics, self.rop, self.scoreboard) if u is not None]
        return " | ".join(parts)
