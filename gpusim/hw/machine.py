"""The machine: a GPU assembled from the units a program reaches, run pass by pass on simpy.

One :class:`Machine` per run owns a ``simpy.Environment`` (the clock and the
only event queue) and the units built for the program: the SIMT cores always,
every other registered unit only when the program issues an operation that
reaches it (``Unit.needed``), the memory levels in ``memory.levels`` order.

Each pass starts ``driver.pass_us`` after the one before it (the draw call or
kernel launch: gpusim.hw.driver). Passes are barriers: a pass ends when its
last operation has completed and every unit is idle again (stores landed,
the ROPs drained), so the next pass starts on an idle machine and its cycles
do not depend on when it starts. A
``flush`` pass (the k-buffer's batching heuristic) is a draw call that drains
the pipeline (``core.pipeline_latency``): its full-screen quad, colour writes
masked, shades nothing (gpusim.hw.core.flush_cycles).

A watchdog process guards each pass: a run that makes no progress for
``runner.no_progress_cycles`` (a deadlock: warps wait on each other and
nothing is left to happen) fails naming the units and queues it is stuck on;
a stretch without issues while timed work is still scheduled (a sampled
request's long hold) is waiting, not a deadlock. ``runner.max_cycles`` bounds
the run.
"""

from __future__ import annotations

import sys
import weakref
from heapq import heappush

import simpy
from simpy.core import NORMAL
from simpy.events import Event

from gpusim.errors import GpusimError
from gpusim.hw import gpu as _gpu  # noqa: F401  (registers every unit)
from gpusim.hw.collector import collector_paused
from gpusim.hw.driver import pass_overhead_cycles
from gpusim.hw.memory import MemoryLevel
from gpusim.hw.parallel import plan_shares, run_shares
from gpusim.hw.program import Program
from gpusim.hw.unit import UNITS


PROGRESS_CYCLES = 4096      # cycles between progress-bar updates (an event each: a fraction of a percent)


KEY_SHIFT = 40             # an event's queue key: its owner's key above, its creation number below
LAST_KEY = (1 << 62) - 1   # the watchdog's key: after every warp's events of the same cycle


class OrderedEnvironment(simpy.Environment):
    """A simpy environment that takes simultaneous events (same cycle, same priority) in the order of their
    owner's ``key`` (the core sets it to the warp a process runs before the process yields), not in the
    order they were created. A unit's wake-up (a plain event it triggers: a free reorder-buffer entry, a
    scoreboard cell) comes first, and the warps it wakes retry in warp order (gpusim.hw.core). A warp has at
    most one event pending, so the cycles do not depend on the order simultaneous events are created in."""

    key = 0

    def schedule(self, event, priority=NORMAL, delay=0) -> None:
        key = -1 if type(event) is Event else self.key
        heappush(self._queue, (self._now + delay, priority, (key << KEY_SHIFT) + next(self._eid), event))


class NoProgress(GpusimError):
    """The event model stopped making progress (a diagnosis names the unit and queue)."""


class Machine:
    """A GPU built for one program: only the units its instructions reach."""

    def __init__(self, gpu, program: Program, width: int, progress=None):
        self.gpu, self.program, self.width = gpu, program, width
        self.progress = progress                 # a tqdm-like bar counting warps done, or None
        self.env = OrderedEnvironment()
        self.warp_end_hooks: list = []           # called (warp, cycle its last operation completes)
        self.units: dict = {}
        self.pass_cycles: list[int] = []
        self.current_pass = 0
        self._monitors = weakref.WeakSet()      # the watchdog, tracer and progress processes (not the run's work)
        self._assemble()
        self.core = self.units["core"]
        self.serve = [self.units[name].serve for name in program.units]    # per program unit index

    # ------------------------------------------------------------------ build
    def _assemble(self) -> None:
        """Build the needed units: the memory path from its far end inwards (each level gets its ``next``),
        then the units reached through others (the blender), then those the core issues to (the ROP asks
        the blender for its program times)."""
        gpu, prog = self.gpu, self.program
        needed = {name for name, cls in UNITS.items() if name == "core" or cls.needed(prog, gpu)}
        levels = [name for name in gpu.memory.levels if name in needed]
        built = {}
        for name in reversed(levels):
            self.units = built
            built[name] = UNITS[name](getattr(gpu, name), self)
        behind_first = sorted(UNITS.items(), key=lambda item: bool(item[1].issued))   # a blender before its ROP
        for name, cls in behind_first:
            if name in needed and name not in built and not issubclass(cls, MemoryLevel):
                self.units = built
                built[name] = cls(getattr(gpu, name), self)
        order = []                    # registration order, the memory levels in path order
        for name, cls in UNITS.items():
            if issubclass(cls, MemoryLevel):
                order += [level for level in levels if level not in order]
            elif name in built:
                order.append(name)
        self.units = {name: built[name] for name in order}

    def level_after(self, name: str):
        """The built memory level after ``name`` on the memory path (None at its end)."""
        levels = [n for n in self.gpu.memory.levels if n in self.units or n == name]
        i = levels.index(name)
        return self.units.get(levels[i + 1]) if i + 1 < len(levels) else None

    def built_units(self) -> list[str]:
        return list(self.units)

    # ------------------------------------------------------------------- run
    @property
    def now(self) -> int:
        return int(self.env.now)

    def run(self) -> int:
        """Simulate every pass; the total cycles.

        Python's cyclic garbage collector is paused meanwhile: the run makes no
        reference cycles that matter, but its millions of short-lived events
        would trigger a collection every few hundred (a fifth of the run time);
        it is restored on the way out.
        """
        with collector_paused():
            shares = plan_shares(self)
            if len(shares) > 1 and run_shares(self, shares):
                if self.progress is not None:
                    self.progress.reset(total=self.program.warps)
                    self.progress.update(self.program.warps)
                return self.now
            self.pass_cycles = [c for _, c in self.run_share(range(len(self.program.passes)))]
            return self.now

    def run_share(self, indices) -> list[tuple[int, int]]:
        """Simulate the passes ``indices`` (ascending) one after the other from the current cycle; each one's
        (start cycle, cycles). A pass starts on an idle machine, so its cycles do not depend on the passes
        before it: shares of the passes can run in separate processes (gpusim.hw.parallel)."""
        indices = list(indices)
        if len(indices) < len(self.program.passes):
            for u in self.units.values():
                if hasattr(u, "only_passes"):
                    u.only_passes(indices)
        out = []
        overhead = pass_overhead_cycles(self.gpu)
        for i in indices:
            p = self.program.passes[i]
            self.current_pass = i
            start = self.now
            self._advance(start + overhead)          # the driver issues the pass
            if p.kind == "flush":
                self._advance(start + overhead + self.core.flush_cycles())   # after the driver
            elif p.warps:
                self._run_pass(p)
            self.guard_max(self.now)
            out.append((start, self.now - start))
        return out

    def _run_pass(self, p) -> None:
        env, core = self.env, self.core
        start = self.now
        raster = self.units.get("raster")
        ready = raster.warp_ready(p, start) if raster is not None else None
        floor = raster.pass_floor(p, start) if raster is not None else start
        core.done = core.last_progress = start
        slots = core.start_pass(p, ready, self.serve)
        finished = env.all_of(slots)
        self._monitors.add(env.process(self._watchdog(p.index, finished)))
        if self.gpu.runner.trace_every:
            self._monitors.add(env.process(self._tracer(p.index, finished)))
        if self.progress is not None:
            self._monitors.add(env.process(self._report(p.index, finished)))
        env.run(until=finished)
        if self.progress is not None:
            self.progress.update(core.warps_done - self.progress.n)
        # a barrier: the pass ends when its last operation has completed and every unit is idle again
        end = max(core.done, floor, *(u.idle_at() for u in self.units.values()))
        self.guard_max(end)
        self._advance(end)

    def _advance(self, cycle: int) -> None:
        """Process what is left up to ``cycle`` (timed releases), then move the clock there."""
        env = self.env
        while env.peek() <= cycle:
            env.step()
        if cycle > env.now:
            env.run(until=cycle)

    def all_waiting(self) -> None:
        """Every running warp waits on a unit (the core calls this when the last one starts to). If nothing
        is left to happen (no event already triggered, no unit with timed work pending), the first unit that
        can end its stall does (``relieve``); otherwise the run is stuck and the watchdog reports it."""
        if any(entry[-1].triggered for entry in self.core.waiting.values()):
            return
        if any(getattr(u, "pending", 0) for u in self.units.values()):
            return
        for u in self.units.values():
            if hasattr(u, "relieve") and u.relieve():
                return

    def _watchdog(self, index: int, finished):
        """Fail pass ``index`` when no instruction issues for ``runner.no_progress_cycles`` cycles or the clock
        passes ``runner.max_cycles``; done once the pass's warps are."""
        runner, core, env = self.gpu.runner, self.core, self.env
        waited = 0                               # the last check that found timed work still to come
        while True:
            deadline = min(max(core.last_progress, waited) + runner.no_progress_cycles, runner.max_cycles)
            env.key = LAST_KEY                   # after the warps' issues of the same cycle
            yield env.timeout(max(0, deadline - env.now) + 1)
            if finished.triggered or self.current_pass != index:
                return
            self.guard_max(env.now)
            if env.now > max(core.last_progress, waited) + runner.no_progress_cycles:
                if self._work_pending():        # a long timed wait (a sampled request's hold), not a deadlock
                    waited = env.now
                    continue
                raise NoProgress(self.diagnosis(runner.no_progress_cycles, core.last_progress))

    def _work_pending(self) -> bool:
        """Whether an event besides the monitors' (watchdog, tracer, progress bar) is scheduled: timed work of a
        warp or unit still to come, so the run is waiting, not stuck. A sampled request holds its unit for the
        full run's load over the sample's, which can leave no instruction issuing for millions of cycles."""
        monitors = self._monitors
        return any(not any(getattr(cb, "__self__", None) in monitors for cb in (event.callbacks or ()))
                   for *_, event in self.env._queue)

    def _report(self, index: int, finished):
        """Count the warps done on the progress bar every ``PROGRESS_CYCLES`` while pass ``index`` runs."""
        bar, core = self.progress, self.core
        if bar.total != self.program.warps:
            bar.reset(total=self.program.warps)
        while True:
            bar.update(core.warps_done - bar.n)
            if finished.triggered or self.current_pass != index:
                return
            yield self.env.timeout(PROGRESS_CYCLES)

    def _tracer(self, index: int, finished):
        """Print :meth:`line_trace` to stderr every ``runner.trace_every`` cycles while pass ``index`` runs."""
        while not finished.triggered and self.current_pass == index:
            print(self.line_trace(), file=sys.stderr)
            yield self.env.timeout(self.gpu.runner.trace_every)

    def guard_max(self, cycle: int, index: int | None = None) -> None:
        limit = self.gpu.runner.max_cycles
        if cycle > limit:
            raise GpusimError(f"the run passed runner.max_cycles = {limit:,} cycles before finishing "
                              f"(pass {self.current_pass if index is None else index} of "
                              f"{len(self.program.passes)}); raise --gpu-set runner.max_cycles=N or use a "
                              f"smaller trace")

    def diagnosis(self, limit: int, last: int) -> str:
        stuck = [line for u in self.units.values() for line in u.blocked()]
        where = "; ".join(stuck) or "no unit reports a queue"
        waiting = self.core.waiting
        first = ""
        if waiting:
            w, (name, sm, wi, unit, _) = next(iter(waiting.items()))
            ins = self.program.instruction(wi)
            first = (f"; first waiting: warp {w} of pass '{name}' on SM {sm}, instruction {wi} "
                     f"({getattr(ins, 'op', 'compute')} x{getattr(ins, 'lanes', 0)}) at the {unit}")
        return (f"no progress for {limit:,} cycles at cycle {last + limit:,} "
                f"(pass {self.current_pass}): {where}; {len(waiting)} warp(s) waiting{first}. "
                f"This is a deadlock in the modelled machine: check the GPU config (e.g. rop.reorder_entries, "
                f"scoreboard.entries) or raise runner.no_progress_cycles if the run is only slow")

    # ------------------------------------------- counters of parallel runs
    def counters(self) -> dict:
        """What a run changed besides time (merged across the processes of a parallel run)."""
        out = {}
        for name, u in self.units.items():
            if u.COUNTERS:
                out[name] = {a: getattr(u, a) for a in u.COUNTERS}
        return out

    def merge_counters(self, got: dict) -> None:
        for name, u in self.units.items():
            for a, how in u.COUNTERS.items():
                mine, theirs = getattr(u, a), got[name][a]
                if isinstance(mine, list):
                    setattr(u, a, [how(x, y) for x, y in zip(mine, theirs)])
                else:
                    setattr(u, a, how(mine, theirs))

    def carries_state(self) -> bool:
        """Whether a unit keeps state from pass to pass (an L2's contents): then passes replay serially."""
        return any(getattr(u, "carries_state", False) for u in self.units.values())

    # ----------------------------------------------------------------- stats
    def unit_summaries(self, total: int) -> dict:
        return {name: u.summary(total) for name, u in self.units.items()}

    def unit_stats(self, total: int) -> list[dict]:
        """Every declared stat of every built unit, one row per value: unit path, stat, labels, value, unit of
        measure, description."""
        rows = []
        for name, u in self.units.items():
            values = u.values(total)
            path = u.path()
            for s in u.STATS:
                v = values[s.name]
                if isinstance(v, list):
                    rows += [{"unit": path, "stat": s.name, "labels": f"instance={i}", "value": x,
                              "unit_of_measure": s.unit, "doc": s.doc} for i, x in enumerate(v)]
                else:
                    rows.append({"unit": path, "stat": s.name, "labels": "", "value": v, "unit_of_measure": s.unit,
                                 "doc": s.doc})
        return rows

    def line_trace(self) -> str:
        """One line of the machine's state for debugging (PyMTL style)."""
        return " | ".join([f"t={self.now} pass={self.current_pass}"] + [u.line_trace() for u in self.units.values()])


    def finish_at(self, cycle: int) -> None:
        """Move the clock to ``cycle`` (the end of a run replayed in other processes)."""
        self._advance(cycle)
