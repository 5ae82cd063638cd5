"""Running an experiment: traces, run ids, resume, tasks on an executor, the results tables.

:func:`run_experiment` builds each scene's trace once, names every grid point
by its id (resolved config + trace content), reuses the runs a previous sweep
into the same directory finished, sends the rest to an executor as tasks (one
functional model run per trace, scheme and parameter set; all its timed runs
with it), writes each run's files as its task returns and the tables after
every task (each file atomically), and returns a :class:`Summary`.
"""

from __future__ import annotations

import hashlib
import os
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from gpusim import interrupt
from gpusim.errors import GpusimError
from gpusim.experiment.execute import Outcome, Task, TaskRun
from gpusim.experiment.executors import make_executor, probe
from gpusim.experiment.grid import GPU_LEVELS, RunSpec, expand, resolved_run, run_id
from gpusim.experiment.spec import Experiment
from gpusim.experiment.store import FIGURE_COLUMNS, LEAD_COLUMNS, LEVEL_COLUMNS, ResultsStore
from gpusim.hw.gpu import with_section
from gpusim.shaders import trace_fragment_shader


@dataclass
class Summary:
    """What a sweep did."""

    out: Path
    runs: int = 0
    ok: int = 0
    failed: int = 0
    skipped: int = 0
    reused: int = 0
    computed: int = 0
    skip_reasons: dict[str, int] = field(default_factory=dict)
    failures: list[tuple[str, str]] = field(default_factory=list)     # (run description, error)


def trace_sha256(trace) -> str:
    """The hash of a trace's content: its arrays, screen and background, and its scene's fragment shader where
    it declares one, which every scheme's timing runs (not its other metadata or its file name)."""
    h = hashlib.sha256()
    h.update(f"{trace.width}x{trace.height};{list(trace.background)}".encode())
    shader = trace_fragment_shader(trace.meta).name
    if shader != "none":
        h.update(f";fragment_shader={shader}".encode())
    for name in ("x", "y", "z", "rgba", "prim", "opaque"):
        array = np.ascontiguousarray(getattr(trace, name))
        if array.size:
            h.update(memoryview(array).cast("B"))
    return h.hexdigest()


def build_trace(source):
    """The trace of a grid source: the trace file, or the scene rasterized with its overrides."""
    if source.kind == "trace":
        from gpusim.trace_io import load_trace
        return load_trace(source.spec)
    from gpusim.scene import load_scene, trace_scene
    scene, base = load_scene(source.spec, list(source.overrides))
    return trace_scene(scene, base, where=source.spec, progress=False)


def default_workers() -> int:
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except AttributeError:                   # pragma: no cover - platforms without affinity
        return max(1, os.cpu_count() or 1)


def check_workers(workers: int | None) -> None:
    """Refuse a number of local worker processes below 1 or above the CPUs this process may use: each
    worker holds its traces and a model in memory, so more than the CPUs only exhausts memory."""
    if workers is None:
        return
    if workers < 1:
        raise GpusimError(f"--workers {workers}: give at least 1 (1 runs in this process)")
    cpus = default_workers()
    if workers > cpus:
        cpu_s = "CPU is" if cpus == 1 else "CPUs are"
        raise GpusimError(f"--workers {workers}: only {cpus} {cpu_s} available here, so give 1..{cpus} "
                          "(or leave it out: one per CPU); for more, run on a cluster with --cluster ADDRESS")


def describe_run(run: RunSpec) -> str:
    params = ",".join(f"{k}={v}" for k, v in run.params.items())
    sets = "".join(f" {k}={v}" for k, v in run.gpu_set)
    return f"{run.source.label} {run.gpu}{sets} {run.fidelity} {run.label}({params})"


def _row(run: RunSpec, rid: str, outcome: Outcome | None, trace_info: dict) -> dict:
    """A run's row: ``skipped`` (with the reason) for a combination its scheme cannot run, ``pending`` for a
    run this sweep has not finished (yet: an interrupted sweep's table), else its outcome."""
    reserved = set(LEAD_COLUMNS) | set(FIGURE_COLUMNS) | set(LEVEL_COLUMNS)
    status = "skipped" if run.skip else outcome.status if outcome else "pending"
    row = {"run": rid, "status": status, "error": run.skip or (outcome.error if outcome else ""),
           "index": run.index, "scene": run.source.label,
           "width": trace_info["width"], "height": trace_info["height"], "trace": trace_info["path"],
           "gpu": run.gpu, "fidelity": run.fidelity, "scheme": run.scheme, "variant": run.label}
    for k, v in run.params.items():
        row[f"param.{k}" if k in reserved else k] = v
    for k, v in run.gpu_set:
        row[k] = v
    for k, v in run.source.scene_set:
        row[f"scene.{k}"] = v
    if outcome is not None:
        row |= outcome.figures
    return row


def run_experiment(exp: Experiment, out: str | Path, workers: int | None = None, cluster: str | None = None,
                   quiet: bool = False) -> Summary:
    """Run every grid point of ``exp`` into ``out`` (resuming what an earlier sweep there finished)."""
    say = (lambda *a: None) if quiet else (lambda *a: print(*a, file=sys.stderr, flush=True))
    if not cluster:
        check_workers(workers)
    runs = expand(exp)
    if cluster:
        probe(cluster)                     # an unreachable cluster fails before anything is written
    store = ResultsStore(out)
    summary = Summary(Path(out), runs=len(runs))

    built = {}                                 # every trace first: a bad one fails before anything is written
    for source in dict.fromkeys(r.source for r in runs):
        trace = build_trace(source)
        built[source] = (trace, trace_sha256(trace))
    store.prepare()
    store.remove_stale_temporaries()
    traces, infos = {}, {}
    for source, (trace, sha) in built.items():
        path, reference = store.save_trace(trace, source.label, sha)
        traces[str(path)] = (trace, reference)
        infos[source] = {"sha": sha, "path": str(path), "rel": os.path.relpath(path, out),
                         "width": trace.width, "height": trace.height}
    ids = [run_id(r, infos[r.source]["sha"]) for r in runs]
    if len(set(ids)) != len(ids):
        dup = next(r for r, i in zip(runs, ids) if ids.count(i) > 1)
        raise ValueError(f"two grid points share a run id ({describe_run(dup)})")   # expand() prevents it
    configs = {i: resolved_run(r, infos[r.source]["sha"]) | {"trace": infos[r.source]["rel"]}
               for r, i in zip(runs, ids)}
    active = [(r, i) for r, i in zip(runs, ids) if r.skip is None]
    outcomes: dict[str, Outcome] = store.finished(i for _, i in active)
    summary.reused = len(outcomes)
    for r in runs:
        if r.skip:
            summary.skip_reasons[r.skip] = summary.skip_reasons.get(r.skip, 0) + 1

    groups: dict[tuple, list[tuple[RunSpec, str]]] = {}
    for r, i in active:
        if i not in outcomes:
            groups.setdefault(r.group_key, []).append((r, i))
    n_workers = 1 if not groups else min(workers or default_workers(), len(groups))
    pooled = bool(cluster) or n_workers > 1
    tasks = []
    for members in groups.values():
        first = members[0][0]
        task_runs = []
        for r, i in members:
            gpu = r.gpu_config if r.fidelity in GPU_LEVELS else None
            if gpu is not None and pooled:       # one process per worker: the passes replay serially
                gpu = with_section(gpu, "runner", workers=1)
            task_runs.append(TaskRun(i, r.fidelity, gpu))
        tasks.append(Task(infos[first.source]["path"], first.scheme, first.params, tuple(task_runs), exp.path))
    todo = sum(len(t.runs) for t in tasks)
    where = f"on the cluster at {cluster}" if cluster else (
        f"on {n_workers} worker processes" if n_workers > 1 else "in this process")
    skipped = sum(summary.skip_reasons.values())
    say(f"{exp.name}: {len(runs)} run{'s' * (len(runs) != 1)} ({skipped} skipped), {summary.reused} reused "
        f"from {out}, {todo} to compute {where}")

    def tables():
        rows, stats = [], []
        for r, i in zip(runs, ids):
            o = outcomes.get(i) if r.skip is None else None
            rows.append(_row(r, i, o, infos[r.source] | {"path": infos[r.source]["rel"]}))
            if o is not None:
                stats += [{"run": i} | s for s in o.stats]
        store.write_tables(rows, stats, exp.resolved_data())

    from tqdm import tqdm
    bar = tqdm(total=todo, unit="run", disable=True if quiet else None, file=sys.stderr, dynamic_ncols=True,
               desc=exp.name)
    executor = make_executor(n_workers, cluster, traces) if tasks else None
    failed = 0
    last = 0.0
    try:
        for task, task_outcomes in (executor.run(tasks) if executor else ()):
            for o in task_outcomes:
                store.save_outcome(o, configs[o.run_id])
                outcomes[o.run_id] = o
                failed += o.status == "failed"
            summary.computed += len(task_outcomes)
            bar.update(len(task_outcomes))
            bar.set_postfix(failed=failed, refresh=False)
            interrupt.check()                    # a stop whose KeyboardInterrupt was lost (gpusim.interrupt)
            if time.monotonic() - last > 1.0:
                tables()
                last = time.monotonic()
    finally:
        bar.close()
        if executor is not None:
            executor.close()
        tables()
    interrupt.check()                            # a stop lost in the last task or the tables: no report follows
    for r, i in zip(runs, ids):
        o = outcomes.get(i)
        if r.skip is not None:
            summary.skipped += 1
        elif o is not None and o.status == "ok":
            summary.ok += 1
        elif o is not None:
            summary.failed += 1
            summary.failures.append((describe_run(r), o.error))
    return summary


def describe_summary(summary: Summary) -> list[str]:
    """The closing lines of a sweep: skip reasons (once each), failures, counts."""
    lines = [f"skipped {n} run{'s' * (n != 1)}: {reason}" for reason, n in summary.skip_reasons.items()]
    lines += [f"failed: {what}: {error}" for what, error in summary.failures[:20]]
    if len(summary.failures) > 20:
        lines.append(f"failed: ... {len(summary.failures) - 20} more (see the error column of results.csv)")
    lines.append(f"{summary.ok} ok, {summary.failed} failed, {summary.skipped} skipped of {summary.runs} "
                 f"run{'s' * (summary.runs != 1)} "
                 f"({summary.reused} reused, {summary.computed} computed); results in {summary.out}")
    if summary.failed:
        lines.append(f"{summary.failed} of {summary.runs} run{'s' * (summary.runs != 1)} failed")
    return lines

