"""The full level on a run too large to lower at once: a chunk of passes at a time.

Passes are barriers and each starts on an idle machine (gpusim.hw.machine), so
a pass's cycles and what the units count in it do not depend on the passes
around it (gpusim.hw.parallel relies on the same). A run over
``runner.max_operations`` is therefore lowered and replayed a chunk of
consecutive passes at a time, each chunk on a machine of its own built for it
and dropped after it: memory is bounded by the largest chunk (at most
``runner.max_operations`` operations), not by the run. The figures put
together are those of the whole program: each pass's cycles, the units'
counts (added, or the largest, as each unit says: ``Unit.absorb``) and the RMW
windows (shifted to the run's timeline).

Streaming is for runs whose operations grow with the fragments (a large
frame): a run of more than ``STREAM_OPS_PER_FRAGMENT`` operations per fragment
is refused as before, since its operations grow with fragments times passes
(depth peeling's thousands of passes over a deep stack: it would take tens of
minutes, where the analytic level estimates it in seconds). So are a single
pass over the limit and a run whose units carry state from pass to pass (an
L2's contents).
"""

from __future__ import annotations

import gc
from types import SimpleNamespace

import numpy as np

from gpusim.errors import GpusimError
from gpusim.hw.hazards import rmw_operations, rmw_windows
from gpusim.hw.lower import lower, pass_operations
from gpusim.hw.machine import Machine
from gpusim.hw.memory import MemoryLevel
from gpusim.hw.unit import UNITS

ADVICE = "use --fidelity analytic, which estimates the run without lowering, or a smaller trace"
STREAM_OPS_PER_FRAGMENT = 64     # the most operations per fragment (on average) of a run the full level streams


def plan_chunks(work, gpu) -> list[tuple[int, int]] | None:
    """None when the whole run lowers at once (at most ``runner.max_operations`` operations); else the
    ranges of passes to lower and replay one after the other, each within the limit. Refuses what cannot
    be streamed (see the module docstring)."""
    limit = gpu.runner.max_operations
    plan = work.plan
    total = plan.total_ops()
    if total <= limit:
        return None
    fragments = len(work.frag_pixel)
    if total > STREAM_OPS_PER_FRAGMENT * fragments:
        raise GpusimError(f"the run would lower {total:,} operations, over runner.max_operations = {limit:,} (the "
                          f"event model needs about 80 bytes per operation), and {total / max(1, fragments):,.0f} "
                          f"per fragment, too many to replay a chunk of passes at a time (at most "
                          f"{STREAM_OPS_PER_FRAGMENT}); {ADVICE}")
    per_pass = pass_operations(plan)
    over = np.flatnonzero(per_pass > limit)
    if len(over):
        p = int(over[0])
        raise GpusimError(f"pass {p} ('{plan.passes[p].name}') would lower {int(per_pass[p]):,} operations, over "
                          f"runner.max_operations = {limit:,} (the event model needs about 80 bytes per operation "
                          f"and lowers at least a pass at once); {ADVICE}")
    ranges: list[tuple[int, int]] = []
    start, held = 0, 0
    for p, n in enumerate(per_pass.tolist()):
        if held + n > limit:
            ranges.append((start, p))
            start, held = p, 0
        held += n
    ranges.append((start, len(per_pass)))
    return ranges


def carried_state(work, gpu) -> GpusimError:
    """The refusal of a run over ``runner.max_operations`` whose units carry state from pass to pass (an L2),
    which no level can replay a chunk of passes at a time."""
    return GpusimError(f"the run would lower {work.plan.total_ops():,} operations, over runner.max_operations = "
                       f"{gpu.runner.max_operations:,}, and its units carry state from pass to pass (an L2), so it "
                       f"cannot be replayed a chunk of passes at a time; {ADVICE}")


class _ChunkBar:
    """A progress bar as one chunk's machine sees it: its own warps, counted on the run's bar."""

    def __init__(self, bar, warps: int):
        self.bar, self.base, self.total = bar, bar.n, warps

    @property
    def n(self) -> int:
        return self.bar.n - self.base

    def update(self, k: int) -> None:
        self.bar.update(k)

    def reset(self, total=None) -> None:
        pass


def unit_order(gpu) -> list[str]:
    """Units in the order a machine lists them: registration order, the memory levels in path order."""
    order: list[str] = []
    for name, cls in UNITS.items():
        if issubclass(cls, MemoryLevel):
            order += [level for level in gpu.memory.levels if level not in order]
        else:
            order.append(name)
    return order


class StreamedRun:
    """The figures of a run replayed a program of consecutive passes at a time, each on a machine of its own
    built for it and dropped after it: each pass's cycles, the units' counts, instructions, operations and the
    RMW operations on the run's timeline. :func:`run_streamed` feeds it the full level's chunks; the sampled
    level (gpusim.hw.sample) a replicate's sample of each chunk."""

    def __init__(self, work, limit_cycles: int, sampled: bool = False):
        """``sampled``: the run is a sample of the sampled level's. A full run's machine, about 80 bytes per
        operation, is freed (a full collection) before the next chunk's is built; a sample's is small, and the
        collection, a pass over every object of the process, cost the level 4-6% of its wall time, so its
        machines are left to the collector's own passes. A sample's RMW windows are its own threads'
        (:meth:`windows`)."""
        self.work, self.limit, self.sampled = work, limit_cycles, sampled
        self.passes: list[tuple] = []             # (name, kind, cycles, warps) of each pass so far
        self.holders: dict[str, object] = {}      # unit name -> the run's counts (detached units, absorbed)
        self.instructions = self.operations = 0
        self.rmw: list = []                       # each chunk's RMW reads and writes: (pass, thread, cycle)

    def replay(self, gpu, program, first: int, progress=None) -> None:
        """Replay ``program`` (the run's passes from ``first`` on) on a machine of ``gpu`` and add its figures;
        ``progress``: the run's bar (tqdm-like)."""
        bar = _ChunkBar(progress, program.warps) if progress is not None else None
        machine = Machine(gpu, program, self.work.width, bar)
        if machine.carries_state():
            raise carried_state(self.work, gpu)
        start = chunk_start = sum(p[2] for p in self.passes)
        machine.run()
        for pp, c in zip(program.passes, machine.pass_cycles):
            self.passes.append((pp.name, pp.kind, c, pp.warps))
            if start + c > self.limit:
                raise GpusimError(f"the run passed runner.max_cycles = {self.limit:,} cycles before finishing "
                                  f"(pass {first + pp.index} of {len(self.work.plan.passes)}); raise --gpu-set "
                                  f"runner.max_cycles=N or use a smaller trace")
            start += c
        self.instructions += program.instructions
        self.operations += program.operations
        for name, u in machine.units.items():
            if name in self.holders:
                self.holders[name].absorb(u.detached())
            else:
                self.holders[name] = u.detached()
        ops = rmw_operations(program, machine)
        if ops is not None:                   # on the run's passes and timeline
            self.rmw.append([(p + first, thread, at + chunk_start) for p, thread, at in ops])
        del machine, u
        if not self.sampled:
            gc.collect()                      # the units and the machine refer to each other

    def units(self, gpu) -> dict:
        """The units holding the run's counts, in machine order."""
        order = unit_order(gpu)
        return {name: self.holders[name] for name in sorted(self.holders, key=order.index)}

    def windows(self):
        """The RMW windows (gpusim.hw.hazards.rmw_windows) of the run (a sample's: of its own threads), or None
        without RMW operations."""
        if not self.rmw:
            return None
        reads, writes = ([np.concatenate(col) for col in zip(*(chunk[k] for chunk in self.rmw))] for k in (0, 1))
        return rmw_windows(reads, writes, len(self.work.frag_pixel), self.sampled)


def run_streamed(work, gpu, chunks: list[tuple[int, int]], progress=None):
    """Replay the ``chunks`` of ``work`` (ranges of passes) one after the other: their figures put together."""
    run = StreamedRun(work, gpu.runner.max_cycles)
    for first, end in chunks:
        run.replay(gpu, lower(work, gpu, passes=(first, end)), first, progress)
    return run


def unit_records(units: dict, total: int) -> tuple[dict, list]:
    """``units`` summaries and stats rows, as a machine with those units gives them."""
    shell = SimpleNamespace(units=units)
    return Machine.unit_summaries(shell, total), Machine.unit_stats(shell, total)


