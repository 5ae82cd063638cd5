"""An experiment's output directory: per-run files, the results tables, resume.

Layout of ``DIR``::

    results.parquet, results.csv   one row per run (axes, status, error, figures)
    stats.parquet                  every declared stat in long form
    resolved.toml                  the experiment as run (overlays and --set applied)
    traces/<scene>-<sha>.npz       each trace, its exact reference (.reference.npy) and its image (.png)
    runs/<run>/                    config.toml, record.json, image.png (+ image-timed.png), outcome.json

Every file is written atomically. ``runs/<run>/outcome.json`` is written last,
so a run counts as finished exactly when it exists with status ``ok``; a later
sweep into the same directory reuses those runs and recomputes the rest.
"""

from __future__ import annotations

import json
import math
import os
from pathlib import Path
from typing import Any, Iterable

import numpy as np
import pandas as pd

from gpusim.atomic_io import atomic_output, write_text_atomic
from gpusim.errors import GpusimError
from gpusim.experiment.execute import Outcome, reference_path
from gpusim.replay import jsonable

#: the row's columns before the parameter, override and figure columns
LEAD_COLUMNS = ("run", "status", "error", "index", "scene", "width", "height", "trace", "gpu", "fidelity",
                "scheme", "variant")
#: the figures every row has (NaN where a run has none), in this order; scheme stats follow as ``stat.NAME``
FIGURE_COLUMNS = ("cycles", "microseconds", "wall_seconds_functional", "wall_seconds_timing", "footprint_bytes",
                  "footprint_used_bytes", "accesses", "geometry_passes", "passes", "dropped_fragments",
                  "overflowed_pixels", "hazards", "hazard_pixels", "rmse", "psnr", "differing_pixels",
                  "differing_share", "max_abs", "rmse_timed", "differing_pixels_timed", "fragments", "pixels")
#: figures only some levels give (the sampled level's confidence interval and error estimate): among the
#: figures, after ``microseconds``, in tables that have them
LEVEL_COLUMNS = ("cycles_ci95_low", "cycles_ci95_high", "cycle_error_estimate")
#: columns that hold wall times (the only ones allowed to differ between two runs of one experiment)
WALL_COLUMNS = ("wall_seconds_functional", "wall_seconds_timing")
STATS_COLUMNS = ("run", "unit", "stat", "labels", "value", "value_unit", "description")


def _json_default(value: Any):
    if isinstance(value, np.integer):
        return int(value)
    if isinstance(value, np.floating):
        return float(value)
    if isinstance(value, np.ndarray):
        return value.tolist()
    return str(value)


def _toml_ready(value: Any) -> Any:
    """TOML has no null and no NaN table keys: drop None, keep everything else."""
    if isinstance(value, dict):
        return {str(k): _toml_ready(v) for k, v in value.items() if v is not None}
    if isinstance(value, (list, tuple)):
        return [_toml_ready(v) for v in value if v is not None]
    if isinstance(value, (np.integer, np.floating)):
        return value.item()
    return value


def toml_text(data: dict, header: str = "") -> str:
    import tomli_w
    return header + tomli_w.dumps(_toml_ready(data))


class ResultsStore:
    """Reads and writes one experiment directory."""

    def __init__(self, root: str | Path):
        self.root = Path(root)

    def run_dir(self, run_id: str) -> Path:
        return self.root / "runs" / run_id

    def prepare(self) -> None:
        """Create the directory; one line naming the problem when it cannot hold the results."""
        if self.root.exists() and not self.root.is_dir():
            raise GpusimError(f"-o {self.root}: is a file, not a directory; choose a directory for the results")
        try:
            (self.root / "runs").mkdir(parents=True, exist_ok=True)
        except OSError as exc:
            raise GpusimError(f"-o {self.root}: cannot create it ({exc.strerror}); choose a directory you can "
                              "write") from None
        if not os.access(self.root, os.W_OK | os.X_OK):
            raise GpusimError(f"-o {self.root}: not writable; choose a directory you can write")

    def remove_stale_temporaries(self) -> int:
        """Temporary files an interrupted sweep left behind (never the targets: those are complete)."""
        count = 0
        if self.root.is_dir():
            for tmp in self.root.rglob(".*.tmp"):
                tmp.unlink(missing_ok=True)
                count += 1
        return count

    def finished(self, run_ids: Iterable[str]) -> dict[str, Outcome]:
        """Outcomes of earlier runs with these ids that finished with status ok."""
        done = {}
        for run_id in run_ids:
            path = self.run_dir(run_id) / "outcome.json"
            if not path.is_file():
                continue
            try:
                data = json.loads(path.read_text())
            except (OSError, ValueError):
                continue                     # unreadable: compute the run again
            if data.get("status") == "ok" and data.get("run") == run_id:
                done[run_id] = Outcome(run_id, "ok", "", data["figures"], data["stats"])
        return done

    def save_trace(self, trace, label: str, sha: str) -> tuple[Path, np.ndarray]:
        """The trace, its exact reference composite (``.reference.npy``, float64) and the reference as a PNG
        under traces/, each once per content; returns the trace's path and the reference. Tasks read the
        reference instead of compositing it again."""
        from gpusim.trace_io import save_trace
        path = self.root / "traces" / f"{label}-{sha[:12]}.npz"
        if not path.is_file():
            save_trace(trace, path)
        ref_path, png = reference_path(path), path.with_suffix(".png")
        if ref_path.is_file() and png.is_file():
            return path, np.load(ref_path)
        from gpusim.experiment.execute import rgb8
        from gpusim.metrics import composite_exact
        from gpusim.report.images import save_rgb8_png
        reference = composite_exact(trace)
        with atomic_output(ref_path) as handle:
            np.save(handle, reference)
        save_rgb8_png(rgb8(reference), png)
        return path, reference

    def save_outcome(self, outcome: Outcome, config: dict) -> None:
        """Write a run's files; its outcome.json last, so a run is finished only once all are there."""
        folder = self.run_dir(outcome.run_id)
        write_text_atomic(folder / "config.toml", toml_text(config, f"# run {outcome.run_id}: the resolved "
                                                                    "config this run's id hashes\n"))
        if outcome.record is not None:
            write_text_atomic(folder / "record.json",
                              json.dumps(jsonable(outcome.record), indent=1, default=_json_default) + "\n")
        if outcome.images:
            from gpusim.report.images import save_rgb8_png
            for name, image in outcome.images.items():
                save_rgb8_png(image, folder / f"{name}.png")
        write_text_atomic(folder / "outcome.json",
                          json.dumps({"run": outcome.run_id, "status": outcome.status, "error": outcome.error,
                                      "figures": outcome.figures, "stats": outcome.stats},
                                     default=_json_default) + "\n")

    def write_tables(self, rows: list[dict], stats: list[dict], resolved: dict | None = None) -> None:
        """results.parquet/.csv and stats.parquet (and resolved.toml), each atomically."""
        table = results_frame(rows)
        with atomic_output(self.root / "results.parquet") as handle:
            table.to_parquet(handle, index=False)
        with atomic_output(self.root / "results.csv", "w") as handle:
            table.to_csv(handle, index=False)
        long = pd.DataFrame(stats, columns=list(STATS_COLUMNS))
        long["value"] = long["value"].astype("float64")
        with atomic_output(self.root / "stats.parquet") as handle:
            long.to_parquet(handle, index=False)
        if resolved is not None:
            write_text_atomic(self.root / "resolved.toml",
                              toml_text(resolved, "# the experiment as run: includes and --set applied\n"))


def results_frame(rows: list[dict]) -> pd.DataFrame:
    """The results table in its column order: lead columns, axes, figures, scheme stats."""
    frame = pd.DataFrame(rows)
    for c in frame.columns:                  # whole numbers stay whole (pandas makes them float beside NaN)
        raw = [row.get(c) for row in rows]
        present = [v for v in raw if v is not None and not (isinstance(v, float) and math.isnan(v))]
        if present and all(isinstance(v, (int, np.integer)) and not isinstance(v, bool) for v in present):
            frame[c] = pd.array([None if v is None or (isinstance(v, float) and math.isnan(v)) else int(v)
                                 for v in raw], dtype="Int64")
    lead = [c for c in LEAD_COLUMNS if c in frame]
    figures = [*FIGURE_COLUMNS[:2], *(c for c in LEVEL_COLUMNS if c in frame), *FIGURE_COLUMNS[2:]]
    stats = sorted(c for c in frame if c.startswith("stat."))
    axes = [c for c in frame if c not in lead and c not in figures and c not in stats]
    for c in figures:
        if c not in frame:
            frame[c] = math.nan
    frame = frame[lead + axes + figures + stats]
    for c in axes + figures + stats:
        frame[c] = _uniform(frame[c])
    return frame.sort_values("index", kind="stable").reset_index(drop=True)


def _uniform(column: pd.Series) -> pd.Series:
    """A column Parquet can hold: numbers stay numbers; mixed kinds become text (missing stays missing)."""
    if isinstance(column.dtype, pd.Int64Dtype):
        return column
    kinds = {type(v) for v in column if v is not None and not (isinstance(v, float) and math.isnan(v))}
    if not kinds or kinds <= {int, float, np.int64, np.float64}:
        return pd.to_numeric(column, errors="coerce") if kinds else column.astype("float64")
    if kinds <= {bool, np.bool_}:
        return column.astype("boolean")
    if kinds <= {str}:
        return column.astype("string")
    return column.map(lambda v: None if v is None or (isinstance(v, float) and math.isnan(v)) else str(v)
                      ).astype("string")
