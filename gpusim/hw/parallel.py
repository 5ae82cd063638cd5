"""Passes in parallel: shares of a program's passes replayed in forked processes.

Passes are barriers, and a pass ends only when every unit is idle again
(gpusim.hw.machine), so a pass's cycles do not depend on when it starts: the
passes can be split into shares, each share replayed in its own process on a
copy of the freshly built machine (``fork``: nothing is pickled on the way
in), and the results put back in pass order. The figures are identical to a
serial run: each pass's cycles, the counters the units keep (merged), and the
RMW start times (shifted from the share's timeline to the whole run's).

``runner.workers`` sets the processes: 1 is serial; N >= 2 uses up to N
whenever two passes have work; 0 (the default) uses one per available CPU
when the program is large enough to gain (``MIN_INSTRUCTIONS``) and no single
pass holds nearly all of it. A run with an L2 stays serial (the cache's
contents carry from pass to pass: ``Machine.carries_state``), as does one on a platform without
``fork`` or in a process running other (non-daemon) threads. If a share fails (a
deadlock, the max-cycles guard), the whole run is redone serially, so errors
read exactly as in a serial run.
"""

from __future__ import annotations

import multiprocessing
import os
import threading

import numpy as np

from gpusim.hw.program import COMPUTE

from gpusim.hw.unit import FP

MIN_INSTRUCTIONS = 50_000     # memory warp instructions below which auto mode stays serial (a fork costs ~10-50 ms)
MAX_SHARE = 0.85              # auto mode stays serial when one pass holds this share of the instructions


def available_cpus() -> int:
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:                 # not on Linux
        return os.cpu_count() or 1


def _other_threads() -> bool:
    """Threads a fork could catch holding a lock (daemon helpers such as tqdm's monitor sleep; they are
    left out)."""
    return any(t is not threading.main_thread() and not t.daemon for t in threading.enumerate())


def plan_shares(machine) -> list[list[int]]:
    """Pass indices per process (one list: serial). Largest passes first, each to the least loaded share."""
    prog, workers = machine.program, machine.gpu.runner.workers
    auto = workers == 0
    if auto:
        workers = available_cpus()
    # memory instructions: what the event model spends its time on (ALU work costs no event)
    weight = [int(np.count_nonzero(prog.wi_unit[int(p.wi_start[0]):int(p.wi_start[-1])] != COMPUTE)) if p.warps
              else 0 for p in prog.passes]
    busy = [i for i, w in enumerate(weight) if w]
    everything = [list(range(len(prog.passes)))]
    if workers < 2 or len(busy) < 2 or machine.carries_state():
        return everything
    if "fork" not in multiprocessing.get_all_start_methods() or _other_threads():
        return everything
    total = sum(weight)
    if auto and (total < MIN_INSTRUCTIONS or max(weight) > MAX_SHARE * total):
        return everything
    shares: list[list[int]] = [[] for _ in range(min(workers, len(busy)))]
    load = [0] * len(shares)
    for i in sorted(busy, key=lambda i: -weight[i]):
        k = load.index(min(load))
        shares[k].append(i)
        load[k] += weight[i]
    idle = [i for i, w in enumerate(weight) if not w]     # flushes and empty passes: cheap, any share
    shares[load.index(min(load))] += idle
    return [sorted(s) for s in shares]


def fork_workers(workers: int, jobs: int, work_each: float, least: float) -> int:
    """Processes for ``jobs`` independent jobs of about ``work_each`` each under ``runner.workers`` =
    ``workers`` (0: one per available CPU when ``work_each`` is at least ``least``, where a fork's cost is
    small beside a job's): 1 (serial) where forking cannot or should not be done."""
    auto = workers == 0
    if auto:
        workers = available_cpus() if work_each >= least else 1
    if min(workers, jobs) < 2 or "fork" not in multiprocessing.get_all_start_methods() or _other_threads():
        return 1
    return min(workers, jobs)


def fork_map(fn, items: list, workers: int) -> list | None:
    """``[fn(item) for item in items]`` in ``workers`` forked processes (item ``i`` in process ``i % workers``:
    nothing is pickled on the way in, the results on the way out); None when a process failed or died, for
    the caller to redo the work serially (so that errors read exactly as in a serial run)."""
    shares = [list(range(k, len(items), workers)) for k in range(workers)]
    got = _forked(_map_child, [(fn, [items[i] for i in share]) for share in shares])
    if any(g is None for g in got):
        return None
    out: list = [None] * len(items)
    for share, results in zip(shares, got):
        for i, r in zip(share, results):
            out[i] = r
    return out


def _forked(target, args: list[tuple]) -> list:
    """``target(*a, conn)`` in a forked process per ``a`` of ``args``: what each sent on ``conn``, in order (None
    for a process that died without a word: killed, out of memory)."""
    ctx = multiprocessing.get_context("fork")
    procs = []
    try:
        for a in args:
            recv, send = ctx.Pipe(duplex=False)
            proc = ctx.Process(target=target, args=(*a, send), daemon=True)
            proc.start()
            send.close()
            procs.append((proc, recv))
        got = []
        for proc, recv in procs:
            try:
                got.append(recv.recv())
            except EOFError:
                got.append(None)
    finally:
        for proc, recv in procs:
            recv.close()
            proc.join()
    return got


def _map_child(fn, items: list, conn) -> None:
    try:
        conn.send([fn(item) for item in items])
    except BaseException:                  # the parent redoes the work serially, where the error reads as it is
        conn.send(None)
    finally:
        conn.close()


def _child(machine, share: list[int], conn) -> None:
    try:
        machine.progress = None            # the parent's bar: counted there once the shares are back
        timeline = machine.run_share(share)
        coalescer = machine.units.get("coalescer")
        rmw = coalescer.rmw_start_arrays() if coalescer is not None and coalescer.rmw_starts is not None else None
        conn.send(("ok", timeline, machine.counters(), rmw))
    except BaseException as e:             # reported to the parent, which reruns serially
        conn.send(("failed", f"{type(e).__name__}: {e}", None, None))
    finally:
        conn.close()


def run_shares(machine, shares: list[list[int]]) -> bool:
    """Replay ``shares`` in parallel into ``machine`` (left untouched on failure); whether it succeeded."""
    got = [("failed", "worker exited", None, None) if g is None else g
           for g in _forked(_child, [(machine, share) for share in shares])]
    if any(g[0] != "ok" for g in got):
        return False
    _merge(machine, shares, got)
    return True


def _merge(machine, shares, got) -> None:
    n = len(machine.program.passes)
    local_start, cycles = [0] * n, [0] * n
    for share, (_, timeline, _, _) in zip(shares, got):
        for i, (start, c) in zip(share, timeline):
            local_start[i], cycles[i] = start, c
    start = np.r_[0, np.cumsum(cycles)].astype(np.int64)
    for i in range(n):                     # the guard, as a serial run would have met it
        machine.guard_max(int(start[i + 1]), i)
    for _, _, counters, _ in got:
        machine.merge_counters(counters)
    coalescer = machine.units.get("coalescer")
    if coalescer is not None and coalescer.rmw_starts is not None:
        shift = (start[:-1] - np.asarray(local_start, np.int64)) * FP          # sub-cycles, per pass
        for _, _, _, (wis, starts) in got:      # (untouched partitions' entries shift too; they are never read)
            coalescer.rmw_merged.append((wis, starts + shift[machine.program.wi_pass[wis]][:, None]))
    machine.pass_cycles = cycles
    machine.finish_at(int(start[-1]))
