"""What a report computes from an experiment's tables (pandas only; nothing here draws).

Every function reads the results table (one row per run) or the long stats
table and returns a frame; :mod:`gpusim.report.figures` draws them and
:mod:`gpusim.report.experiment` writes them into index.md.
"""

from __future__ import annotations

import math

import numpy as np
import pandas as pd

from gpusim.experiment.store import FIGURE_COLUMNS, LEAD_COLUMNS

#: fidelity levels from the most to the least faithful; figures use the first one present
LEVEL_ORDER = ("full", "sampled", "analytic", "thesis")
#: the levels whose cycle error is measured against ``full``
APPROXIMATE_LEVELS = ("analytic", "sampled")


def axis_columns(results: pd.DataFrame) -> tuple[list[str], list[str], list[str]]:
    """(scheme parameter columns, gpu-set columns, scene-set columns) of a results table."""
    fixed = set(LEAD_COLUMNS) | set(FIGURE_COLUMNS)
    rest = [c for c in results if c not in fixed and not c.startswith("stat.")]
    scene_set = [c for c in rest if c.startswith("scene.")]
    params = [c for c in rest if c not in scene_set and ("." not in c or c.startswith("param."))]
    gpu_set = [c for c in rest if c not in scene_set and c not in params]
    return params, gpu_set, scene_set


def _value(v) -> str:
    if isinstance(v, float) and v.is_integer():
        return str(int(v))
    return str(v)


def _varying(frame: pd.DataFrame, columns: list[str]) -> list[str]:
    return [c for c in columns if frame[c].dropna().astype(str).nunique() > 1]


def with_labels(results: pd.DataFrame) -> pd.DataFrame:
    """The results with ``config`` (the scheme table and the parameters that vary within it, e.g.
    ``kbuffer k=4``), ``machine`` (the GPU and the gpu-set values that vary) and ``setting`` (scene,
    scene-set values and machine) columns added."""
    params, gpu_set, scene_set = axis_columns(results)
    out = results.copy()
    configs = pd.Series("", index=out.index, dtype=object)
    for variant, rows in out.groupby("variant", sort=False):
        vary = _varying(rows, params)
        for i, row in rows.iterrows():
            extra = " ".join(f"{c.removeprefix('param.')}={_value(row[c])}" for c in vary if not pd.isna(row[c]))
            configs[i] = f"{variant} {extra}".strip()
    out["config"] = configs
    vary_gpu = _varying(out, gpu_set)
    many_gpus = out["gpu"].nunique() > 1
    out["machine"] = [" ".join(([row["gpu"]] if many_gpus or not vary_gpu else [])
                               + [f"{c}={_value(row[c])}" for c in vary_gpu]) or row["gpu"]
                      for _, row in out.iterrows()]
    vary_scene = _varying(out, scene_set)
    out["setting"] = [" ".join([row["scene"], *[f"{c.removeprefix('scene.')}={_value(row[c])}" for c in vary_scene],
                                row["machine"]]) for _, row in out.iterrows()]
    out["scene_label"] = [" ".join([row["scene"], *[f"{c.removeprefix('scene.')}={_value(row[c])}"
                                                     for c in vary_scene]]) for _, row in out.iterrows()]
    out["functional"] = [" ".join([row["scene"], *[f"{c.removeprefix('scene.')}={_value(row[c])}"
                                                    for c in vary_scene], row["config"]])
                         for _, row in out.iterrows()]
    return out


def best_level(results: pd.DataFrame, timed_only: bool = True) -> str | None:
    """The most faithful level with a finished run (thesis only when it is the only one)."""
    ok = results[results["status"] == "ok"]
    present = set(ok["fidelity"])
    for level in LEVEL_ORDER:
        if level in present and (level != "thesis" or present <= {"thesis", "none"}):
            return level
    return None if timed_only else ("none" if "none" in present else None)


def pareto(points: pd.DataFrame, x: str, y: str) -> pd.DataFrame:
    """The points no other point beats on both ``x`` and ``y`` (smaller is better), by ascending ``x``."""
    ordered = points.dropna(subset=[x, y]).sort_values([x, y], kind="stable")
    keep, best = [], math.inf
    for i, row in ordered.iterrows():
        if row[y] < best:
            keep.append(i)
            best = row[y]
    return ordered.loc[keep]


def fidelity_errors(labelled: pd.DataFrame) -> pd.DataFrame:
    """One row per finished analytic or sampled run that has a finished ``full`` run of the same setting
    and configuration: its cycles, the full level's, the relative cycle error, and both wall times.
    ``labelled`` is the results table with :func:`with_labels`' columns."""
    ok = labelled[labelled["status"] == "ok"]
    full = ok[ok["fidelity"] == "full"].set_index(["setting", "config"])
    rows = []
    for _, row in ok[ok["fidelity"].isin(APPROXIMATE_LEVELS)].iterrows():
        key = (row["setting"], row["config"])
        if key not in full.index:
            continue
        ref = full.loc[key]
        if isinstance(ref, pd.DataFrame):
            ref = ref.iloc[0]
        if not ref["cycles"] > 0:
            continue
        rows.append({"setting": row["setting"], "config": row["config"], "scheme": row["scheme"],
                     "fidelity": row["fidelity"], "cycles": row["cycles"], "full_cycles": ref["cycles"],
                     "cycle_error": row["cycles"] / ref["cycles"] - 1.0,
                     "wall_seconds": row["wall_seconds_timing"], "full_wall_seconds": ref["wall_seconds_timing"],
                     "speedup": ref["wall_seconds_timing"] / row["wall_seconds_timing"]
                     if row["wall_seconds_timing"] > 0 else math.nan})
    return pd.DataFrame(rows, columns=["setting", "config", "scheme", "fidelity", "cycles", "full_cycles",
                                       "cycle_error", "wall_seconds", "full_wall_seconds", "speedup"])


def fidelity_summary(errors: pd.DataFrame) -> pd.DataFrame:
    """Per level: runs compared, median and largest |cycle error|, median speed-up over full."""
    rows = []
    for level, rows_ in errors.groupby("fidelity", sort=False):
        err = rows_["cycle_error"].abs()
        rows.append({"fidelity": level, "runs": len(rows_), "median_abs_error": float(err.median()),
                     "max_abs_error": float(err.max()), "median_speedup": float(rows_["speedup"].median())})
    return pd.DataFrame(rows, columns=["fidelity", "runs", "median_abs_error", "max_abs_error", "median_speedup"])


def one_per_functional(labelled: pd.DataFrame) -> pd.DataFrame:
    """One finished run per scene and configuration (footprint, accesses and image do not depend on the
    GPU or level): the first in grid order. ``labelled`` is the results table with :func:`with_labels`' columns."""
    ok = labelled[labelled["status"] == "ok"]
    return ok.drop_duplicates("functional", keep="first")


def structure_table(stats: pd.DataFrame, runs: pd.DataFrame, stat: str) -> pd.DataFrame:
    """``stat`` (footprint_bytes or accesses) per run and label, pivoted: one row per run of ``runs``
    (indexed by its ``functional`` label), one column per structure (and operation)."""
    sel = stats[(stats["unit"] == "scheme") & (stats["stat"] == stat) & stats["run"].isin(runs["run"])]
    if sel.empty:
        return pd.DataFrame()
    names = sel["labels"].str.replace("structure=", "", regex=False).str.replace(",operation=", ".", regex=False)
    table = sel.assign(part=names).pivot_table(index="run", columns="part", values="value", aggfunc="sum",
                                                sort=False)
    label = runs.set_index("run")["functional"]
    table.index = [label[r] for r in table.index]
    return table


def unit_utilisation(stats: pd.DataFrame, runs: pd.DataFrame) -> pd.DataFrame:
    """Mean utilisation (busy cycles / run cycles, 0-1) of each hardware unit class in each run of
    ``runs`` (indexed by its ``config``), from the per-instance stats (full, sampled) or the per-unit
    estimates (analytic)."""
    hw = stats[stats["run"].isin(runs["run"]) & ~stats["unit"].isin(["scheme", "metrics", "machine"])]
    sel = hw[hw["stat"].isin(["utilisation", "utilisation_mean"])]
    if sel.empty:
        return pd.DataFrame()
    table = sel.pivot_table(index="run", columns="unit", values="value", aggfunc="mean", sort=False)
    table = table.reindex([r for r in runs["run"] if r in table.index])
    label = runs.set_index("run")["config"]
    table.index = [label[r] for r in table.index]
    return table


def fmt(value, kind: str = "") -> str:
    """A table cell: bytes as KiB/MiB, shares as %, integers with separators, NaN as a dash."""
    if value is None or (isinstance(value, float) and math.isnan(value)) or value is pd.NA:
        return "-"
    if isinstance(value, (int, float, np.integer, np.floating)):
        v = float(value)
        if math.isinf(v):
            return "inf" if v > 0 else "-inf"
        if kind == "bytes":
            return f"{v / 2**20:,.2f} MiB" if v >= 2**20 else f"{v / 1024:,.1f} KiB" if v >= 1024 else f"{v:,.0f} B"
        if kind == "share":
            return f"{100 * v:.3g}%"
        if kind == "pct":
            return f"{100 * v:+.1f}%"
        if kind == "x":
            return f"{v:.2f}x"
        if v.is_integer() and abs(v) < 1e15:
            return f"{int(v):,}"
        return f"{v:.3g}" if abs(v) < 100 else f"{v:,.0f}"
    return str(value)


def markdown(frame: pd.DataFrame, kinds: dict[str, str] | None = None, index: bool = False) -> str:
    """A GitHub markdown table of ``frame`` (cells formatted with :func:`fmt`)."""
    kinds = kinds or {}
    data = frame.reset_index().rename(columns={"index": "", "functional": "configuration"}) if index else frame
    head = [str(c) for c in data.columns]
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for _, row in data.iterrows():
        lines.append("| " + " | ".join(fmt(row[c], kinds.get(str(c), "")).replace("|", "/") for c in data.columns)
                     + " |")
    return "\n".join(lines)
