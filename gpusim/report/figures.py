"""The figures of an experiment report (matplotlib's object API: no pyplot, no global state).

Each function takes frames from :mod:`gpusim.report.tables` and writes one PNG
atomically, kept under :data:`MAX_PNG_BYTES` (the resolution is lowered until
it fits). Every axis names its unit; every title names the fidelity level that
made its numbers.
"""

from __future__ import annotations

import io
import math
from pathlib import Path

import numpy as np
import pandas as pd
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure
from matplotlib.transforms import Bbox

from gpusim.atomic_io import atomic_output
from gpusim.report.tables import pareto

MAX_PNG_BYTES = 200_000
_DPIS = (100, 80, 64, 50, 40)


def save(fig: Figure, path: Path) -> Path:
    """Write ``fig`` as a PNG under MAX_PNG_BYTES (at the highest resolution of _DPIS that fits)."""
    FigureCanvasAgg(fig)
    data = b""
    for dpi in _DPIS:
        buffer = io.BytesIO()
        fig.savefig(buffer, format="png", dpi=dpi)
        data = buffer.getvalue()
        if len(data) <= MAX_PNG_BYTES:
            break
    with atomic_output(path) as handle:
        handle.write(data)
    return path


def _colours(names: list[str]) -> dict[str, tuple]:
    from matplotlib import colormaps
    cmap = colormaps["tab20"]
    return {n: cmap(i % 20) for i, n in enumerate(names)}


def error_vs_cycles(points: pd.DataFrame, level: str, title: str, path: Path) -> Path:
    """Image error (RMSE; share of differing pixels) against simulated cycles, one point per configuration,
    the Pareto front drawn and its points labelled."""
    fig = Figure(figsize=(11, 5.2))
    colours = _colours(list(dict.fromkeys(points["scheme"])))
    axes_labels = []
    for ax, column, label in zip(fig.subplots(1, 2), ("rmse", "differing_share"),
                                 ("RMSE against the exact reference (RGB in [0, 1])",
                                  "pixels differing by more than 1/255 (% of screen)")):
        scale = 100.0 if column == "differing_share" else 1.0
        for scheme, rows in points.groupby("scheme", sort=False):
            ax.scatter(rows["cycles"], rows[column] * scale, s=28, color=colours[scheme], label=scheme,
                       edgecolors="black", linewidths=0.4, zorder=3)
        front = pareto(points, "cycles", column)
        labels = [(x, y, text, True) for x, y, text in zip(front["cycles"], front[column] * scale, front["config"])]
        labels += [(x, y, text, False) for x, y, text in zip(points["cycles"], points[column] * scale,
                                                              points["config"]) if text not in set(front["config"])]
        if len(front):
            xs, ys = front["cycles"].to_numpy(), front[column].to_numpy() * scale
            ax.step(xs, ys, where="post", color="black", linewidth=1.0, alpha=0.7, zorder=2, label="Pareto front")
        ax.set_xscale("log")
        axes_labels.append((ax, labels))
        ax.set_xlabel("cycles (thesis model)" if level == "thesis"
                      else f"simulated cycles ({level} level, shader clock)")
        ax.set_ylabel(label)
        ax.grid(True, which="both", alpha=0.25)
    fig.suptitle(title, fontsize=10)
    _legend_below(fig, 8)
    for ax, items in axes_labels:
        _place_labels(fig, ax, items)
    return save(fig, path)


def _legend_below(fig: Figure, columns: int) -> None:
    """The first axes' legend in ``columns`` columns under the axes, then the layout fitted above it."""
    handles, labels = fig.axes[0].get_legend_handles_labels()
    fig.legend(handles, labels, fontsize=7, loc="lower center", ncol=min(columns, len(labels)), frameon=False)
    fig.tight_layout(rect=(0, 0.04 + 0.035 * math.ceil(len(labels) / columns), 1, 1))


def _place_labels(fig: Figure, ax, items: list[tuple]) -> None:
    """Label points without overlap: the Pareto front's first (always drawn, at the first free offset), then the
    others in grey where a free offset exists (a label that finds none is left out: its colour still says which
    scheme the point is, and the tables list every run)."""
    renderer = FigureCanvasAgg(fig).get_renderer()
    points = ax.transData.transform(np.array([(x, y) for x, y, _, _ in items], dtype=float)) if items else []
    taken = [Bbox.from_bounds(px - 3, py - 3, 6, 6) for px, py in points]
    offsets = ((4, 4), (4, -10), (-4, 4), (-4, -10), (4, 14), (4, -20))
    for (x, y, text, on_front) in items:
        placed = None
        for dx, dy in offsets:
            note = ax.annotate(text, (x, y), textcoords="offset points", xytext=(dx, dy),
                               fontsize=7 if on_front else 5.5, color="black" if on_front else "0.4",
                               ha="left" if dx > 0 else "right")
            box = note.get_window_extent(renderer)
            if not any(box.overlaps(t) for t in taken) and ax.bbox.contains(box.x1, box.y1) \
                    and ax.bbox.contains(box.x0, box.y0):
                placed = note
                break
            note.remove()
        if placed is None and on_front:
            placed = ax.annotate(text, (x, y), textcoords="offset points", xytext=(4, 4), fontsize=7)
        if placed is not None:
            taken.append(placed.get_window_extent(renderer))


def fidelity_vs_wall(errors: pd.DataFrame, full_walls: pd.Series, title: str, path: Path) -> Path:
    """Each approximate level's cycle error against the full level, against its wall time (one point per
    run); the full level's own wall times are drawn at zero error for reference."""
    fig = Figure(figsize=(8, 4.6))
    ax = fig.subplots()
    markers = {"analytic": ("o", "tab:blue"), "sampled": ("s", "tab:orange")}
    for level, rows in errors.groupby("fidelity", sort=False):
        marker, colour = markers.get(level, ("^", "tab:green"))
        ax.scatter(rows["wall_seconds"], 100.0 * rows["cycle_error"], marker=marker, color=colour, s=30,
                   edgecolors="black", linewidths=0.4, label=f"{level} ({len(rows)} runs)", zorder=3)
    ax.scatter(full_walls, np.zeros(len(full_walls)), marker="|", color="black", s=80,
               label=f"full ({len(full_walls)} runs: the reference)", zorder=2)
    ax.axhline(0.0, color="black", linewidth=0.6)
    ax.set_xscale("log")
    ax.set_xlabel("wall time of the timing model (s, this machine)")
    ax.set_ylabel("cycle error against the full level (%)")
    ax.grid(True, which="both", alpha=0.25)
    ax.legend(fontsize=8)
    ax.set_title(title, fontsize=10)
    fig.tight_layout()
    return save(fig, path)


def stacked_bars(table: pd.DataFrame, xlabel: str, title: str, path: Path, scale: float = 1.0,
                 log: bool = False) -> Path:
    """Horizontal bars, one per row of ``table``, stacked by its columns (e.g. footprint by structure)."""
    table = table.fillna(0.0)
    fig = Figure(figsize=(9, 1.2 + 0.32 * len(table)))
    ax = fig.subplots()
    left = np.zeros(len(table))
    colours = _colours(list(table.columns))
    labels = list(table.index)
    for column in table.columns:
        values = table[column].to_numpy(dtype=float) / scale
        ax.barh(labels, values, left=left, color=colours[column], label=str(column), edgecolor="white",
                linewidth=0.3)
        left += values
    if log:
        ax.set_xscale("log")
    ax.invert_yaxis()
    ax.set_xlabel(xlabel)
    ax.tick_params(axis="y", labelsize=7)
    ax.legend(fontsize=6, ncol=3, loc="lower right")
    ax.set_title(title, fontsize=10)
    ax.grid(True, axis="x", alpha=0.25)
    fig.tight_layout()
    return save(fig, path)


def cycles_and_units(cycles: pd.Series, utilisation: pd.DataFrame, level: str, title: str, path: Path) -> Path:
    """Cycles per configuration (bars, log scale) beside where they go: each hardware unit's mean
    utilisation (busy cycles / run cycles) as a heat map."""
    rows = list(cycles.index)
    fig = Figure(figsize=(11, 1.4 + 0.32 * len(rows)))
    left, right = fig.subplots(1, 2, gridspec_kw={"width_ratios": [1.1, 1]})
    left.barh(rows, cycles.to_numpy(dtype=float), color="tab:blue")
    left.set_xscale("log")
    left.invert_yaxis()
    left.set_xlabel(f"simulated cycles ({level} level)")
    left.tick_params(axis="y", labelsize=7)
    left.grid(True, axis="x", which="both", alpha=0.25)
    if not utilisation.empty:
        util = utilisation.reindex(rows)
        im = right.imshow(100.0 * util.to_numpy(dtype=float), aspect="auto", cmap="viridis", vmin=0, vmax=100)
        right.set_xticks(range(len(util.columns)), [str(c) for c in util.columns], rotation=45, fontsize=7)
        right.set_yticks(range(len(rows)), [""] * len(rows))
        for (i, j), v in np.ndenumerate(util.to_numpy(dtype=float)):
            if not math.isnan(v):
                right.text(j, i, f"{100 * v:.0f}", ha="center", va="center", fontsize=6,
                           color="white" if v < 0.6 else "black")
        fig.colorbar(im, ax=right, label="mean utilisation (% of run cycles)")
        right.set_title("where the cycles go: unit utilisation", fontsize=9)
    else:
        right.set_axis_off()
    fig.suptitle(title, fontsize=10)
    fig.tight_layout()
    return save(fig, path)


def image_grid(reference: np.ndarray, images: list[tuple[str, np.ndarray, float]], title: str, path: Path,
               max_steps: int = 32) -> Path:
    """The exact reference, then each image above its difference map (largest channel difference from the
    reference in 8-bit steps, clipped at ``max_steps``), titled with its differing pixels as the results table
    counts them (from the float images). Images are 8-bit rows, top row first."""
    cols = min(6, len(images) + 1)
    pairs = -(-(len(images) + 1) // cols)
    cell = 1.9 * reference.shape[0] / reference.shape[1] + 0.3       # inches: the image and its title
    fig = Figure(figsize=(1.9 * cols + 1.2, 2 * cell * pairs + 0.5), layout="constrained")
    axes = np.atleast_2d(fig.subplots(2 * pairs, cols))
    for ax in axes.flat:
        ax.set_axis_off()
    entries = [("exact reference", reference, 0)] + images
    im = None
    for n, (name, image, differing) in enumerate(entries):
        r, c = divmod(n, cols)
        axes[2 * r, c].imshow(image, interpolation="nearest")
        axes[2 * r, c].set_title(name, fontsize=7)
        if n:
            diff = np.abs(image.astype(np.int16) - reference.astype(np.int16)).max(axis=2)
            im = axes[2 * r + 1, c].imshow(np.minimum(diff, max_steps), cmap="inferno", vmin=0, vmax=max_steps,
                                           interpolation="nearest")
            axes[2 * r + 1, c].set_title(f"{differing:,.0f} px differ", fontsize=6)
    if im is not None:
        fig.colorbar(im, ax=list(axes[1::2].flat), fraction=0.02,
                     label=f"|image - reference| (8-bit steps, max channel, clipped at {max_steps})")
    fig.suptitle(title, fontsize=10)
    return save(fig, path)


def grouped_bars(chart: pd.DataFrame, ylabel: str, title: str, path: Path, log: bool = False) -> Path:
    """Bars of ``value`` per ``x``, one bar per ``group`` side by side (a paper figure's layout)."""
    xs = list(dict.fromkeys(chart["x"]))
    groups = list(dict.fromkeys(chart["group"]))
    table = chart.pivot_table(index="x", columns="group", values="value", sort=False).reindex(index=xs,
                                                                                              columns=groups)
    fig = Figure(figsize=(min(13.0, max(7.0, 0.2 * len(xs) * len(groups) + 2)), 4.8))
    ax = fig.subplots()
    width = 0.8 / len(groups)
    colours = _colours(groups)
    for i, group in enumerate(groups):
        ax.bar(np.arange(len(xs)) + (i - (len(groups) - 1) / 2) * width, table[group].to_numpy(dtype=float),
               width, label=group, color=colours[group], edgecolor="white", linewidth=0.3)
    ax.set_xticks(range(len(xs)), xs, fontsize=8)
    ax.set_ylabel(ylabel)
    if log:
        ax.set_yscale("log")
    ax.grid(True, axis="y", alpha=0.25)
    ax.set_title(title, fontsize=10)
    handles, labels = ax.get_legend_handles_labels()
    fig.legend(handles, labels, fontsize=7, ncol=min(6, len(groups)), loc="lower center", frameon=False)
    fig.tight_layout(rect=(0, 0.03 + 0.04 * -(-len(groups) // 6), 1, 1))
    return save(fig, path)



#: the panels of a sweep figure: (column, y label, y scale)
SWEEP_PANELS = (("rmse", "RMSE against the exact reference (RGB in [0, 1])", "symlog"),
                ("cycles_per_fragment", "simulated cycles per fragment", "log"),
                ("wall_us_per_fragment", "simulator wall time per fragment (µs, this machine)", "log"))


def _stand_ins(points: pd.DataFrame, level: str) -> tuple[np.ndarray, str]:
    """(which rows of ``points`` ran at another level than ``level``, a title note saying they are hollow)."""
    other = (points["fidelity"] != level).to_numpy()
    levels = ", ".join(dict.fromkeys(points.loc[other, "fidelity"]))
    return other, (f"; hollow marks: {levels}, where {level} did not finish" if other.any() else "")


def sweep(points: pd.DataFrame, x: str, xlabel: str, level: str, title: str, path: Path) -> Path:
    """Image error, simulated cycles per fragment and the simulator's wall time per fragment against a swept
    scene key ``x``, one line per configuration (``points``: one row per configuration and value, with
    :func:`gpusim.report.tables.per_fragment`'s columns and ``fidelity``; a run at another level than
    ``level`` is a hollow mark). A numeric ``x`` spanning a decade or more is drawn on a log axis; any other
    is drawn in the order of its values."""
    values = list(dict.fromkeys(points[x]))
    numeric = all(isinstance(v, (int, float, np.integer, np.floating)) for v in values)
    position = (lambda v: v) if numeric else {v: i for i, v in enumerate(values)}.get
    configs = list(dict.fromkeys(points["config"]))
    colours = _colours(configs)
    markers = "osD^v<>pP*Xh"
    stand_in, note = _stand_ins(points, level)
    fig = Figure(figsize=(13, 4.8))
    for ax, (column, label, scale) in zip(fig.subplots(1, 3), SWEEP_PANELS):
        for i, config in enumerate(configs):
            mine = (points["config"] == config).to_numpy()
            rows = points[mine]
            xs = np.array([position(v) for v in rows[x]], dtype=float)
            ys = rows[column].to_numpy(dtype=float)
            order = np.argsort(xs, kind="stable")
            ax.plot(xs[order], ys[order], marker=markers[i % len(markers)], markersize=4, linewidth=1.0,
                    color=colours[config], label=config)
            hollow = stand_in[mine]
            ax.scatter(xs[hollow], ys[hollow], s=30, marker=markers[i % len(markers)], facecolors="white",
                       edgecolors=colours[config], linewidths=1.2, zorder=4)
        if scale == "symlog":
            ax.set_yscale("symlog", linthresh=1e-3)
            ax.set_ylim(bottom=0)
        elif scale != "log" or (points[column].to_numpy(dtype=float) > 0).any():
            ax.set_yscale(scale)                 # a log axis needs a positive value (a tiny sweep may time 0)
        if numeric and min(values) > 0 and max(values) >= 10 * min(values):
            ax.set_xscale("log")
            ax.set_xticks(values, [f"{v:g}" for v in values])
            ax.minorticks_off()
        elif not numeric:
            ax.set_xticks(range(len(values)), [str(v) for v in values], fontsize=8)
        ax.set_xlabel(xlabel)
        ax.set_ylabel(label, fontsize=8)
        ax.grid(True, which="both", alpha=0.25)
    fig.suptitle(f"{title} (cycles: {level} level{note})", fontsize=10)
    _legend_below(fig, 7)
    return save(fig, path)


def error_vs_cycles_all(points: pd.DataFrame, level: str, title: str, path: Path) -> Path:
    """Image error (RMSE) against simulated cycles and against cycles per fragment over every scene of
    ``points`` (one point per run, with :func:`gpusim.report.tables.per_fragment`'s columns), one colour per
    configuration."""
    fig = Figure(figsize=(12, 5.2))
    configs = list(dict.fromkeys(points["config"]))
    colours = _colours(configs)
    markers = "osD^v<>pP*Xh"
    unit = "thesis model" if level == "thesis" else f"{level} level, shader clock"
    stand_in, note = _stand_ins(points, level)
    for ax, column, xlabel in zip(fig.subplots(1, 2), ("cycles", "cycles_per_fragment"),
                                  (f"simulated cycles ({unit})", f"simulated cycles per fragment ({unit})")):
        for i, config in enumerate(configs):
            mine = (points["config"] == config).to_numpy()
            rows = points[mine]
            ax.scatter(rows[column], rows["rmse"], s=22, color=colours[config], marker=markers[i % len(markers)],
                       edgecolors="black", linewidths=0.3, label=config, zorder=3)
            hollow = stand_in[mine]
            ax.scatter(rows[column][hollow], rows["rmse"][hollow], s=22, marker=markers[i % len(markers)],
                       facecolors="white", edgecolors=colours[config], linewidths=1.0, zorder=4)
        ax.set_xscale("log")
        ax.set_yscale("symlog", linthresh=1e-3)
        ax.set_ylim(bottom=0)
        ax.set_xlabel(xlabel)
        ax.set_ylabel("RMSE against the exact reference (RGB in [0, 1])")
        ax.grid(True, which="both", alpha=0.25)
    fig.suptitle(title + note, fontsize=10)
    _legend_below(fig, 7)
    return save(fig, path)
