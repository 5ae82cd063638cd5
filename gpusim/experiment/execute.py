"""One task of a sweep: a scheme's functional model on one trace, then each of its timed runs.

A :class:`Task` holds every run that shares a trace, a scheme and a parameter
set: the functional model (image, footprint, accesses, image error) runs once
and each run adds its timing level on its GPU. :func:`execute` returns one
:class:`Outcome` per run, never raises for a run's own failure (the run is
recorded as failed with a one-line error), and touches no file: the caller
writes outcomes, so a task runs the same in this process, a local worker
process or a dask worker on another machine.
"""

from __future__ import annotations

import gc
import math
import os
import time
import traceback
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from gpusim.errors import GpusimError
from gpusim.hw.gpu import GpuConfig
from gpusim.schemes.common.reorder import submitted_primitives


@dataclass(frozen=True)
class TaskRun:
    run_id: str
    fidelity: str                            # "none" or a timing level
    gpu: GpuConfig | None                    # None for levels without a GPU


@dataclass(frozen=True)
class Task:
    trace_path: str
    scheme: str
    params: dict
    runs: tuple[TaskRun, ...]
    where: str = "experiment"


@dataclass
class Outcome:
    """What one run produced: its row's figures, its long-form stats, its record and its images."""

    run_id: str
    status: str                              # "ok" or "failed"
    error: str = ""
    figures: dict[str, Any] = field(default_factory=dict)
    stats: list[dict] = field(default_factory=list)
    record: dict | None = None
    images: dict[str, np.ndarray] = field(default_factory=dict)    # name -> uint8 (H, W, 3), top row first


def one_line(exc: BaseException) -> str:
    """A run's error as one line: a user-facing problem as it is, anything else marked as a bug."""
    if isinstance(exc, GpusimError):
        text = str(exc)
    elif isinstance(exc, MemoryError):
        text = ("out of memory: the run needs more memory than this machine has; use a smaller size, "
                "a lower fidelity level or fewer workers")
    else:
        where = traceback.extract_tb(exc.__traceback__)[-1] if exc.__traceback__ else None
        at = f" at {os.path.basename(where.filename)}:{where.lineno}" if where else ""
        text = f"internal error {type(exc).__name__}{at}: {exc} (a bug in gpusim; report it with the run's config)"
    return " ".join(text.split())


def reference_path(trace_path: str | os.PathLike) -> Path:
    """Where the exact reference composite of a trace saved by a sweep lies (float64 .npy beside it)."""
    return Path(trace_path).with_suffix(".reference.npy")


def rgb8(image: np.ndarray) -> np.ndarray:
    """An (H, W, 3) float image in [0, 1] with row 0 at the bottom, as 8-bit rows top first (PNG order)."""
    return (np.clip(np.asarray(image, dtype=np.float64)[::-1], 0.0, 1.0) * 255.0 + 0.5).astype(np.uint8)


def _number(value: Any) -> float | None:
    if isinstance(value, bool):
        return float(value)
    if isinstance(value, (int, float, np.integer, np.floating)):
        return float(value)
    return None


def functional_figures(record: dict) -> dict[str, Any]:
    """The row's figures that the functional model decides."""
    err = record["error"]
    figures = {
        "fragments": record["fragments"], "pixels": record["pixels"],
        "wall_seconds_functional": record["wall_seconds"],
        "footprint_bytes": record["footprint_bytes"].get("total", 0),
        "footprint_used_bytes": record["footprint_used_bytes"].get("total", 0),
        "accesses": int(sum(sum(ops.values()) for ops in record["accesses"].values())),
        "geometry_passes": record["geometry_passes"], "passes": len(record["passes"]),
        "dropped_fragments": record["dropped_fragments"], "overflowed_pixels": record["overflowed_pixels"],
        "rmse": err["rmse"], "psnr": err["psnr"], "differing_pixels": err["differing_pixels"],
        "differing_share": err["differing_share"], "max_abs": err["max_abs"],
    }
    for name, stat in record["stats"].items():
        value = _number(stat["value"])
        if value is not None:
            figures[f"stat.{name}"] = value
    return figures


def timing_figures(timing: dict) -> dict[str, Any]:
    figures = {"cycles": timing["cycles"], "microseconds": timing.get("microseconds", math.nan),
               "wall_seconds_timing": timing["wall_seconds"]}
    if timing.get("rmw_hazards") is not None:
        figures["hazards"] = timing["rmw_hazards"]
        figures["hazard_pixels"] = timing.get("rmw_hazard_pixels", math.nan)
    for key in ("cycles_ci95_low", "cycles_ci95_high", "cycle_error_estimate"):     # the sampled level's
        if key in timing:
            figures[key] = timing[key]
    if "rmw_image_error" in timing:
        figures["rmse_timed"] = timing["rmw_image_error"]["rmse"]
        figures["differing_pixels_timed"] = timing["rmw_image_error"]["differing_pixels"]
    return figures


def _stat(unit: str, stat: str, value: Any, value_unit: str, description: str, labels: str = "") -> dict | None:
    number = _number(value)
    if number is None:
        return None
    return {"unit": unit, "stat": stat, "labels": labels, "value": number, "value_unit": value_unit,
            "description": description}


def functional_stat_rows(record: dict) -> list[dict]:
    """The functional model's stats in long form: (unit, stat, labels, value, value_unit, description).

    ``unit`` is who counts it: ``scheme`` (its structures, accesses and own stats) or ``metrics`` (image
    error); :func:`trace_stat_rows` adds ``trace`` (the input's own counts) and :func:`timing_stat_rows`
    ``machine`` (cycles, passes, hazards) and the hardware units (``dram``, ``atomic``, ``rop``, ...).
    ``labels`` are ``key=value`` pairs joined by commas (``structure=depth_array,operation=load``). Wall times
    are left out: they are not results of the model.
    """
    rows = []
    for name, size in record["footprint_bytes"].items():
        if name != "total":
            rows.append(_stat("scheme", "footprint_bytes", size, "bytes", "bytes the structure allocates",
                              f"structure={name}"))
            rows.append(_stat("scheme", "footprint_used_bytes", record["footprint_used_bytes"].get(name, 0),
                              "bytes", "bytes of the structure holding scene data after capture",
                              f"structure={name}"))
    for name, ops in record["accesses"].items():
        for op, count in ops.items():
            rows.append(_stat("scheme", "accesses", count, "accesses", "memory operations over all passes",
                              f"structure={name},operation={op}"))
    rows.append(_stat("scheme", "dropped_fragments", record["dropped_fragments"], "fragments",
                      "fragments the scheme failed to keep"))
    for name, stat in record["stats"].items():
        rows.append(_stat("scheme", name, stat["value"], stat["unit"], stat["doc"]))
    for name in ("rmse", "psnr", "differing_pixels", "differing_share", "max_abs"):
        rows.append(_stat("metrics", name, record["error"][name], {"psnr": "dB", "differing_pixels": "pixels"}
                          .get(name, "1"), "image error against the exact reference"))
    return [r for r in rows if r is not None]


def trace_stat_rows(trace) -> list[dict]:
    """The trace's own counts in long form (unit ``trace``): the triangles its scene submitted, as the timing
    model charges them (:func:`~gpusim.schemes.common.reorder.submitted_primitives`: the trace's metadata, or the
    highest primitive id + 1 for a trace that does not say, such as a CSV import)."""
    return [_stat("trace", "primitives_submitted", submitted_primitives(trace), "triangles",
                  "triangles the scene sent to the rasterizer (after any subdivision)")]


#: the sampled level's wall-time parts (``sample.wall_seconds`` in its record)
WALL_PARTS = {"run": "the whole run: its operations counted, its traffic sampled, its L2 warmed (a smaller sample "
                     "does not shorten it)",
              "programs": "lowering the samples (the replicates and checks; summed over their processes)",
              "events": "replaying the samples in the event model (summed over their processes)",
              "other": "the rest: the estimate, its interval and the record"}


def timing_stat_rows(timing: dict) -> list[dict]:
    """A timing level's stats in long form (see :func:`functional_stat_rows`)."""
    rows = [_stat("machine", "cycles", timing["cycles"], "cycles", f"run time ({timing['fidelity']})")]
    for i, p in enumerate(timing.get("passes", [])):
        labels = f"pass={p['name']},index={i},kind={p['kind']}" + (f",bound={p['bound']}" if "bound" in p else "")
        rows.append(_stat("machine", "pass_cycles", p["cycles"], "cycles", "cycles of one pass", labels))
    if timing.get("rmw_hazards") is not None:
        rows.append(_stat("machine", "rmw_hazards", timing["rmw_hazards"], "fragments",
                          "fragments that read an obsolete value (RMW hazard)"))
    for s in timing.get("unit_stats", []):
        rows.append(_stat(s["unit"], s["stat"], s["value"], s["unit_of_measure"], s["doc"], s["labels"]))
    if not timing.get("unit_stats"):            # a level without declared stats (analytic estimates)
        for unit, summary in timing.get("units", {}).items():
            for stat, value in summary.items():
                rows.append(_stat(unit, stat, value, "cycles" if stat.endswith("cycles") else "1",
                                  f"{stat} of the {unit} units ({timing['fidelity']} estimate)"))
    sample = timing.get("sample", {})
    for key, value_unit, doc in (("replicates", "samples", "replicate samples"),
                                 ("sms", "SMs", "SMs each replicate simulates"),
                                 ("share", "1", "share of the work each replicate keeps (and of the GPU's SMs, unless thinned)"),
                                 ("tiles", "tiles", "screen tiles with fragments"),
                                 ("tiles_per_replicate", "tiles", "screen tiles each replicate samples")):
        if key in sample:                       # the sampled level's sample
            rows.append(_stat("sample", key, sample[key], value_unit, doc))
    for part, seconds in sample.get("wall_seconds", {}).items():       # where its wall time went
        rows.append(_stat("sample", "wall_seconds", seconds, "s", f"the level's wall time spent on {WALL_PARTS[part]}",
                          f"part={part}"))
    check = sample.get("scale_check")
    if check:                                   # and its scale check
        rows.append(_stat("sample", "scale_check_sms", check["sms"], "SMs",
                          "SMs of the scale check (replicates 0 and 1's samples together)"))
        rows.append(_stat("sample", "scale_bias", check["bias_estimate"], "cycles",
                          "the replicates' machine-size bias the scale check gives (in the 95% interval)"))
    work = sample.get("work_check")
    if work:                                    # thinned replicates and their work checks
        rows.append(_stat("sample", "thin", sample["thin"], "1",
                          "share of its SMs' work a thinned replicate keeps (sample.thin, raised to keep enough tiles)"))
        rows.append(_stat("sample", "work_checks", len(work["pairs"]), "samples",
                          "work checks (a pair of replicates' samples together on the same SMs) the slopes come from"))
        rows.append(_stat("sample", "slope_std_error", work["slope_std_error"], "cycles",
                          "standard error the work checks' slope adds to a replicate's extrapolated cycles"))
    for key in ("memory_cycles", "compute_cycles"):
        if key in timing:
            rows.append(_stat("machine", key, timing[key], "cycles", f"thesis model: {key.replace('_', ' ')}"))
    return [r for r in rows if r is not None]


def execute(task: Task, trace=None, reference=None) -> list[Outcome]:
    """Run ``task`` on ``trace`` and its exact ``reference`` composite (read from ``task.trace_path`` and the
    reference saved beside it when not given); one outcome per run, in order."""
    from gpusim.jit import start
    from gpusim.metrics import composite_exact
    from gpusim.replay import run_functional, run_timing
    from gpusim.trace_io import load_trace

    start()                                  # numba's start-up, once per process: in no run's wall time
    try:
        trace = trace if trace is not None else load_trace(task.trace_path)
        if reference is None:
            saved = reference_path(task.trace_path)
            reference = np.load(saved) if saved.is_file() else composite_exact(trace)
        result, record, _ = run_functional(trace, task.scheme, task.params, reference,
                                           where=f"{task.where}: schemes")
    except Exception as exc:                 # noqa: BLE001 - every run of the task fails with this line
        return [Outcome(r.run_id, "failed", one_line(exc)) for r in task.runs]
    image = rgb8(result.image)
    base, base_stats = functional_figures(record), functional_stat_rows(record) + trace_stat_rows(trace)
    outcomes = []
    for run in task.runs:
        rec = dict(record)
        figures, stats = dict(base), list(base_stats)
        images = {"image": image}
        if run.fidelity != "none":
            start = time.perf_counter()
            try:
                timing, gpu_config, timed = run_timing(result, trace, run.fidelity, run.gpu, reference)
            except Exception as exc:         # noqa: BLE001 - recorded as this run's failure
                outcomes.append(Outcome(run.run_id, "failed", one_line(exc),
                                        figures | {"wall_seconds_timing": time.perf_counter() - start}))
                continue
            finally:
                # the event model's processes, events and units refer to each other: reference cycles that
                # hold the run's arrays (a failed run's too) until a full collection, which Python seldom
                # makes; without this a sweep in one process (or one worker) grows by a run's memory per run
                gc.collect()
            rec["timing"] = timing
            if gpu_config is not None:
                rec["gpu_config"] = gpu_config
            figures |= timing_figures(timing)
            stats += timing_stat_rows(timing)
            if timed is not None:
                images["image-timed"] = rgb8(timed)
        outcomes.append(Outcome(run.run_id, "ok", "", figures, stats, rec, images))
    return outcomes
