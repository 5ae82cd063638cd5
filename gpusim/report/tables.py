"""What a report computes from an experiment's tables (pandas only; nothing here draws).

Every function reads the results table (one row per run) or the long stats
table and returns a frame; :mod:`gpusim.report.figures` draws them and
:mod:`gpusim.report.experiment` writes them into index.md.
"""

from __future__ import annotations

import math

import numpy as np
import pandas as pd

from gpusim.experiment.store import FIGURE_COLUMNS, LEAD_COLUMNS, LEVEL_COLUMNS

#: fidelity levels from the most to the least faithful; figures use the first one present
LEVEL_ORDER = ("full", "sampled", "analytic", "thesis")
#: the levels whose cycle error is measured against ``full``
APPROXIMATE_LEVELS = ("analytic", "sampled")


def axis_columns(results: pd.DataFrame) -> tuple[list[str], list[str], list[str]]:
    """(scheme parameter columns, gpu-set columns, scene-set columns) of a results table."""
    fixed = set(LEAD_COLUMNS) | set(FIGURE_COLUMNS) | set(LEVEL_COLUMNS)
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
    scene_label = [" ".join([row["scene"], *[f"{c.removeprefix('scene.')}={_value(row[c])}" for c in vary_scene
                                             if not pd.isna(row[c])]]) for _, row in out.iterrows()]
    out["setting"] = [f"{label} {machine}" for label, machine in zip(scene_label, out["machine"])]
    out["scene_label"] = scene_label
    out["functional"] = [f"{label} {config}" for label, config in zip(scene_label, out["config"])]
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


#: the targets of the approximate levels against ``full``, over a corpus: (level, measure, bound,
#: direction); speed-ups count the cases of at least FAST_CASE_FRAGMENTS fragments only
FIDELITY_TARGETS = (("sampled", "median abs. cycle error", 0.02, "<="), ("sampled", "max abs. cycle error", 0.05, "<="),
                    ("sampled", "median speed-up over full", 10.0, ">="),
                    ("sampled", "full cycles inside the 95% interval", 0.95, ">="),
                    ("analytic", "max abs. cycle error", 0.10, "<="),
                    ("analytic", "median speed-up over full", 50.0, ">="))
FAST_CASE_FRAGMENTS = 1_000_000
#: the largest |cycle error| a case may have to meet its level's error target (the max targets above)
CASE_ERROR_BOUND = {"sampled": 0.05, "analytic": 0.10}
#: a unit class whose busy cycles in a sampled run that misses are off the full run's by more than this (a
#: share) is named among what the miss came from, the largest first, at most :data:`MISS_UNITS` of them
UNIT_SHIFT, MISS_UNITS = 0.05, 2
ERROR_COLUMNS = ["run", "setting", "config", "scheme", "fidelity", "fragments", "cycles", "full_cycles",
                 "cycle_error", "wall_seconds", "full_wall_seconds", "speedup", "ci_low", "ci_high", "error_estimate",
                 "inside", "hazards", "full_hazards", "full_run"]


def fidelity_errors(labelled: pd.DataFrame) -> pd.DataFrame:
    """One row per finished analytic or sampled run that has a finished ``full`` run of the same setting
    and configuration: its cycles, the full level's, the relative cycle error, both wall times, and for a
    sampled run its 95% interval and whether the full level's cycles lie inside it; both runs' hazards.
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
        low, high = (row.get(c, math.nan) for c in ("cycles_ci95_low", "cycles_ci95_high"))
        rows.append({"run": row["run"], "setting": row["setting"], "config": row["config"], "scheme": row["scheme"],
                     "fidelity": row["fidelity"], "fragments": row["fragments"], "cycles": row["cycles"],
                     "full_cycles": ref["cycles"], "cycle_error": row["cycles"] / ref["cycles"] - 1.0,
                     "wall_seconds": row["wall_seconds_timing"], "full_wall_seconds": ref["wall_seconds_timing"],
                     "speedup": ref["wall_seconds_timing"] / row["wall_seconds_timing"]
                     if row["wall_seconds_timing"] > 0 else math.nan,
                     "ci_low": low, "ci_high": high, "error_estimate": row.get("cycle_error_estimate", math.nan),
                     "inside": (low <= ref["cycles"] <= high) if not pd.isna(low) else math.nan,
                     "hazards": row["hazards"], "full_hazards": ref["hazards"], "full_run": ref["run"]})
    return pd.DataFrame(rows, columns=ERROR_COLUMNS)


def fidelity_summary(errors: pd.DataFrame) -> pd.DataFrame:
    """Per level: runs compared, median and largest |cycle error|, median speed-up over full."""
    rows = []
    for level, rows_ in errors.groupby("fidelity", sort=False):
        err = rows_["cycle_error"].abs()
        rows.append({"fidelity": level, "runs": len(rows_), "median_abs_error": float(err.median()),
                     "max_abs_error": float(err.max()), "median_speedup": float(rows_["speedup"].median())})
    return pd.DataFrame(rows, columns=["fidelity", "runs", "median_abs_error", "max_abs_error", "median_speedup"])


def error_percentiles(errors: pd.DataFrame, column: str, by: list[str]) -> pd.DataFrame:
    """Per group of ``by``: the runs with a finite ``column`` (a relative error) and the median, 90th
    percentile and largest of its absolute value."""
    rows = []
    finite = errors[np.isfinite(errors[column].astype(float))]
    for key, part in finite.groupby(by, sort=False):
        err = part[column].abs().astype(float)
        rows.append(dict(zip(by, key if isinstance(key, tuple) else (key,)))
                    | {"runs": len(part), "median": float(err.median()), "p90": float(err.quantile(0.9)),
                       "max": float(err.max())})
    return pd.DataFrame(rows, columns=[*by, "runs", "median", "p90", "max"])


def fast_cases(errors: pd.DataFrame) -> pd.DataFrame:
    """The compared runs of at least :data:`FAST_CASE_FRAGMENTS` fragments: the speed figures' cases."""
    return errors[errors["fragments"] >= FAST_CASE_FRAGMENTS]


def sampled_wall_parts(errors: pd.DataFrame, stats: pd.DataFrame) -> pd.DataFrame:
    """Per sampled case of :func:`fast_cases` whose record splits its wall time (``sample.wall_seconds``): the
    full and sampled wall times, each part's share of the sampled level's (the whole run, the samples' lowering,
    their events, the rest), and the speed-up the level would have with its samples free (the full level's
    wall time over the run's part and the rest): what a smaller or faster sample can still buy; and the share of
    their cost the samples may keep for the case to reach the level's speed-up target (:data:`FIDELITY_TARGETS`),
    0 where the run's part alone misses it, 1 or more where the case meets it already."""
    runs = fast_cases(errors)
    runs = runs[runs["fidelity"] == "sampled"]
    sel = stats[(stats["unit"] == "sample") & (stats["stat"] == "wall_seconds")]
    if runs.empty or sel.empty:
        return pd.DataFrame()
    parts = sel.assign(part=sel["labels"].str.extract(r"part=(\w+)")[0]).pivot_table(
        index="run", columns="part", values="value", aggfunc="sum")
    rows = []
    for _, e in runs.iterrows():
        if e["run"] not in parts.index:
            continue
        p = parts.loc[e["run"]].fillna(0.0)
        wall = e["wall_seconds"]
        rest = p.get("other", 0.0) + max(0.0, wall - p.sum())     # the record's rest and what no part holds
        fixed = p.get("run", 0.0) + rest
        rows.append({"config": e["config"], "full_wall_seconds": e["full_wall_seconds"], "wall_seconds": wall,
                     "speedup": e["speedup"], "run_share": p.get("run", 0.0) / wall,
                     "programs_share": p.get("programs", 0.0) / wall, "events_share": p.get("events", 0.0) / wall,
                     "other_share": rest / wall,
                     "speedup_samples_free": e["full_wall_seconds"] / fixed if fixed > 0 else math.nan,
                     "samples_budget": _samples_budget(e["full_wall_seconds"], fixed,
                                                       p.get("programs", 0.0) + p.get("events", 0.0))})
    return pd.DataFrame(rows)


def _samples_budget(full: float, fixed: float, samples: float) -> float:
    """The share of their cost ``samples`` (seconds) may keep for a sampled run whose other parts take ``fixed``
    to reach the sampled speed-up target over a full run of ``full`` seconds (0: the other parts alone miss it)."""
    target = next(b for level, measure, b, _ in FIDELITY_TARGETS if level == "sampled" and "speed-up" in measure)
    if samples <= 0:
        return math.nan
    return max(0.0, (full / target - fixed) / samples)


def fidelity_targets(errors: pd.DataFrame) -> pd.DataFrame:
    """Each of :data:`FIDELITY_TARGETS` on ``errors``: the measured value (NaN where no run counts: no such
    level, or for a speed-up no case of :data:`FAST_CASE_FRAGMENTS` fragments), the cases that count, and
    whether it is met; plus per level the share of cases within its :data:`CASE_ERROR_BOUND`."""
    rows = []
    for level, measure, bound, direction in FIDELITY_TARGETS:
        part = errors[errors["fidelity"] == level]
        if "speed-up" in measure:
            part = fast_cases(part)
            value = part["speedup"].median() if len(part) else math.nan
        elif "inside" in measure:
            part = part[part["inside"].notna()]
            value = part["inside"].astype(float).mean() if len(part) else math.nan
        else:
            err = part["cycle_error"].abs()
            value = (err.median() if measure.startswith("median") else err.max()) if len(part) else math.nan
        met = (value <= bound if direction == "<=" else value >= bound) if not math.isnan(value) else None
        rows.append({"level": level, "target": f"{measure} {direction} {_bound(measure, bound)}",
                     "cases": len(part), "measured": value, "met": _met(met)})
    for level, bound in CASE_ERROR_BOUND.items():
        part = errors[errors["fidelity"] == level]
        share = float((part["cycle_error"].abs() <= bound).mean()) if len(part) else math.nan
        rows.append({"level": level, "target": f"cases with abs. cycle error <= {bound:.0%}: >= 90%",
                     "cases": len(part), "measured": share, "met": _met(share >= 0.9 if len(part) else None)})
    return pd.DataFrame(rows, columns=["level", "target", "cases", "measured", "met"])


def _bound(measure: str, bound: float) -> str:
    return f"{bound:g}x" if "speed-up" in measure else f"{bound:.0%}"


def _met(met: bool | None) -> str:
    return "no cases" if met is None else "met" if met else "missed"


def decided_by(stats: pd.DataFrame) -> dict[str, str]:
    """Per run with pass cycles labelled by their bound (the analytic level): the bounds that decided it, with
    their share of its cycles, largest first (``latency 92%, dram 8%``)."""
    sel = stats[(stats["unit"] == "machine") & (stats["stat"] == "pass_cycles")
                & stats["labels"].str.contains("bound=", regex=False)]
    if sel.empty:
        return {}
    bound = sel["labels"].str.extract(r"bound=([^,]+)")[0]
    shares = sel.assign(bound=bound).groupby(["run", "bound"], sort=False)["value"].sum()
    out = {}
    for run, part in shares.groupby(level=0, sort=False):
        part = part.droplevel(0).sort_values(ascending=False)
        total = part.sum()
        out[run] = ", ".join(f"{b} {v / total:.0%}" for b, v in part.items() if v >= 0.05 * total) if total \
            else "empty passes"
    return out


def sample_sizes(stats: pd.DataFrame) -> dict[str, str]:
    """Per sampled run: its sample (replicates of how many SMs, tiles per replicate of how many; thinned
    replicates' share of their SMs' work and their work checks) and its scale check's SMs and bias (over the
    run's cycles)."""
    sel = stats[stats["unit"] == "sample"]
    cycles = stats[(stats["unit"] == "machine") & (stats["stat"] == "cycles")]
    cycles = cycles.drop_duplicates("run").set_index("run")["value"]
    out = {}
    for run, part in sel.groupby("run", sort=False):
        v = dict(zip(part["stat"], part["value"]))
        share = (f"thinned to {v['thin']:.0%} of their work, {v.get('work_checks', 0):.0f} work checks" if "thin" in v
                 else f"{v.get('share', 0):.1%} of the GPU")
        out[run] = (f"{v.get('replicates', 0):.0f} x {v.get('sms', 0):.0f} SM ({share}), "
                    f"{v.get('tiles_per_replicate', 0):,.0f} of {v.get('tiles', 0):,.0f} tiles each")
        if "scale_bias" in v and cycles.get(run):
            out[run] += (f"; scale check on {v.get('scale_check_sms', 0):.0f} SM: machine-size bias "
                         f"{v['scale_bias'] / cycles[run]:+.2%}")
    return out


def whole_samples(stats: pd.DataFrame) -> set[str]:
    """The sampled runs that simulated the whole run (a share of 1: too few tiles for a smaller sample)."""
    sel = stats[(stats["unit"] == "sample") & (stats["stat"] == "share")]
    return set(sel.loc[sel["value"] >= 1, "run"])


def fidelity_misses(errors: pd.DataFrame, stats: pd.DataFrame) -> pd.DataFrame:
    """The cases that miss their level's error target (|cycle error| over :data:`CASE_ERROR_BOUND`) or, for a
    sampled run, whose 95% interval leaves out the full level's cycles; with what decided the case: the
    analytic level's bounds; the sampled level's sample, its own error estimate, the units whose busy cycles
    are furthest from the full run's (:data:`UNIT_SHIFT`) and, with an L2, its hit rate and the full run's."""
    bounds, samples = decided_by(stats), sample_sizes(stats)
    busy, hits = unit_errors(errors, stats), l2_hit_rates(stats)
    rows = []
    for _, e in errors.iterrows():
        over = abs(e["cycle_error"]) > CASE_ERROR_BOUND.get(e["fidelity"], math.inf)
        outside = e["inside"] is False or e["inside"] == 0
        if not (over or outside):
            continue
        if e["fidelity"] == "analytic":
            why = bounds.get(e["run"], "-")
        else:
            why = f"{samples.get(e['run'], '-')}; error estimate {fmt(e['error_estimate'], 'share')}"
            shifted = sorted(((u, v) for u, v in busy.get(e["run"], {}).items() if round(abs(v), 3) > UNIT_SHIFT),
                             key=lambda uv: -abs(uv[1]))[:MISS_UNITS]
            if shifted:
                why += "; busy against full: " + ", ".join(f"{u} {v:+.0%}" for u, v in shifted)
            if e["run"] in hits and e["full_run"] in hits:
                why += f"; L2 hits {hits[e['run']]:.1%} (full {hits[e['full_run']]:.1%})"
        rows.append({"fidelity": e["fidelity"], "setting": e["setting"], "config": e["config"],
                     "cycle_error": e["cycle_error"],
                     "missed": " and ".join(m for m, hit in (("error", over), ("interval", outside)) if hit),
                     "decided by": why})
    return pd.DataFrame(rows, columns=["fidelity", "setting", "config", "cycle_error", "missed", "decided by"])


def _unit_sums(stats: pd.DataFrame, stat: str) -> pd.Series:
    """``stat`` per run and unit class (the unit's last name: ``memory.dram`` and ``dram`` alike), summed over
    its instances (the full level's per-instance rows, the others' one row)."""
    sel = stats[stats["stat"] == stat]
    return sel.assign(name=sel["unit"].str.split(".").str[-1]).groupby(["run", "name"], sort=False)["value"].sum()


def unit_errors(errors: pd.DataFrame, stats: pd.DataFrame) -> dict[str, dict[str, float]]:
    """Per compared run: per unit class the full run keeps busy, the run's busy cycles against the full run's
    (a relative error; NaN where the run has none)."""
    busy = _unit_sums(stats, "busy_cycles")
    runs = set(busy.index.get_level_values(0))
    out = {}
    for _, e in errors.iterrows():
        if e["full_run"] in runs:
            out[e["run"]] = {unit: busy.get((e["run"], unit), math.nan) / full - 1.0
                             for unit, full in busy.loc[e["full_run"]].items() if full > 0}
    return out


def l2_hit_rates(stats: pd.DataFrame) -> dict[str, float]:
    """Per run with L2 requests: the share of them that hit."""
    hits, misses = _unit_sums(stats, "hits"), _unit_sums(stats, "misses")
    out = {}
    for (run, unit), h in hits.items():
        total = h + misses.get((run, unit), 0.0)
        if unit == "l2" and total > 0:
            out[run] = h / total
    return out


def busy_errors(errors: pd.DataFrame, stats: pd.DataFrame) -> pd.DataFrame:
    """Per compared run and hardware unit class: the level's busy cycles (summed over the unit's instances)
    against the full run's, as a relative error; units the full run keeps busy only."""
    by_run = unit_errors(errors, stats)
    rows = [{"fidelity": e["fidelity"], "scheme": e["scheme"], "unit": unit, "busy_error": err}
            for _, e in errors.iterrows() for unit, err in by_run.get(e["run"], {}).items()]
    return pd.DataFrame(rows, columns=["fidelity", "scheme", "unit", "busy_error"])


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


#: scheme stats that count fragments composited (or whose colour was kept) out of depth order, or merged
#: with another before their order was known (mlab); each stat's own description is in stats.parquet
MISORDER_STATS = ("misordered_pairs", "invalid_samples", "packing_order_inversions", "tie_blends",
                  "colour_collisions", "merges")


def most_faithful(labelled: pd.DataFrame) -> tuple[pd.DataFrame, pd.DataFrame]:
    """(one finished run per setting and configuration at the most faithful level it finished, in grid order;
    those of them below :func:`best_level`'s level). ``labelled`` has :func:`with_labels`' columns."""
    ok = labelled[labelled["status"] == "ok"]
    level = best_level(labelled, timed_only=False)
    rank = {lv: i for i, lv in enumerate((*LEVEL_ORDER, "none"))}
    if level == "thesis":       # thesis cycles only where no GPU level ran: never mixed with a GPU's
        ok = ok[ok["fidelity"].isin(["thesis", "none"])]
    else:
        ok = ok[ok["fidelity"] != "thesis"]
    first = ok.assign(_rank=ok["fidelity"].map(rank)).sort_values(["_rank", "index"], kind="stable")
    runs = first.drop_duplicates(["setting", "config"]).sort_values("index", kind="stable").drop(columns="_rank")
    return runs, runs[runs["fidelity"] != level]


def per_fragment(runs: pd.DataFrame) -> pd.DataFrame:
    """``runs`` with ``depth_complexity`` (fragments per covered pixel), ``cycles_per_fragment`` and
    ``wall_us_per_fragment`` (the functional model's and the timing level's wall time, µs) added."""
    fragments = runs["fragments"].where(runs["fragments"] > 0)
    wall = runs["wall_seconds_functional"].fillna(0.0) + runs["wall_seconds_timing"].fillna(0.0)
    return runs.assign(depth_complexity=fragments / runs["pixels"].where(runs["pixels"] > 0),
                       cycles_per_fragment=runs["cycles"] / fragments,
                       wall_us_per_fragment=1e6 * wall / fragments)


def scene_sweeps(labelled: pd.DataFrame, key_order: dict[str, list[str]] | None = None) -> list[tuple[str, list[str]]]:
    """Each scene (the ``scene`` column) whose finished runs vary a scene-set column, with the columns it
    varies: in ``key_order[scene]``'s order (scene keys as the experiment lists them; the first is the x axis
    of its figures), then the table's."""
    _, _, scene_set = axis_columns(labelled)
    ok = labelled[labelled["status"] == "ok"]
    out = []
    for scene, rows in ok.groupby("scene", sort=False):
        vary = _varying(rows, scene_set)
        if vary:
            first = [f"scene.{k}" for k in (key_order or {}).get(scene, [])]
            out.append((scene, sorted(vary, key=lambda c: first.index(c) if c in first else len(first))))
    return out


def misordered(runs: pd.DataFrame) -> tuple[pd.Series, pd.Series]:
    """(count, the stats that counted it) per run: the sum of the :data:`MISORDER_STATS` columns it has
    (NaN where its scheme has none of them)."""
    columns = [f"stat.{s}" for s in MISORDER_STATS if f"stat.{s}" in runs]
    if not columns:
        return pd.Series(math.nan, index=runs.index), pd.Series("", index=runs.index, dtype=object)
    values = runs[columns]
    count = values.sum(axis=1, min_count=1)
    names = values.notna().apply(lambda row: ", ".join(c.removeprefix("stat.") for c in row.index[row]), axis=1)
    return count, names


def drop_cases(runs: pd.DataFrame) -> pd.DataFrame:
    """The runs (with :func:`with_labels`' columns) where a scheme drops fragments, composites them out of
    depth order (a :data:`MISORDER_STATS` count, or RMW hazards) or leaves a wrong image: one row each with
    the counts, ordered by scheme table then grid order."""
    count, names = misordered(runs)
    frame = pd.DataFrame({"scene": runs["scene_label"], "config": runs["config"],
                          "dropped": runs["dropped_fragments"], "overflowed px": runs["overflowed_pixels"],
                          "misordered": count, "counted by": names, "hazards": runs["hazards"],
                          "differing px": runs["differing_pixels"], "rmse": runs["rmse"]}, index=runs.index)
    wrong = (frame[["dropped", "misordered", "hazards", "differing px"]].fillna(0) > 0).any(axis=1)
    order = {v: i for i, v in enumerate(dict.fromkeys(runs["variant"]))}
    return frame[wrong].assign(_v=runs["variant"].map(order)).sort_values("_v", kind="stable").drop(columns="_v")


def drop_summary(runs: pd.DataFrame) -> pd.DataFrame:
    """Per scheme configuration over ``runs``: cases run, cases (and fragments) dropped, cases (and counts)
    misordered, cases with hazards, cases with a wrong image, and the largest RMSE with its scene."""
    count, _ = misordered(runs)
    frame = runs.assign(_mis=count)
    rows = []
    for config, r in frame.groupby("config", sort=False):
        worst = r["rmse"].idxmax() if r["rmse"].notna().any() else None
        rows.append({"config": config, "cases": len(r),
                     "dropping cases": int((r["dropped_fragments"].fillna(0) > 0).sum()),
                     "fragments dropped": r["dropped_fragments"].sum(min_count=1),
                     "misordering cases": int((r["_mis"].fillna(0) > 0).sum()),
                     "misordered": r["_mis"].sum(min_count=1),
                     "hazard cases": int((r["hazards"].fillna(0) > 0).sum()),
                     "wrong-image cases": int((r["differing_pixels"].fillna(0) > 0).sum()),
                     "largest rmse": r["rmse"].max(),
                     "on": r.loc[worst, "scene_label"] if worst is not None and r.loc[worst, "rmse"] > 0 else "-"})
    return pd.DataFrame(rows)
