"""Paper comparisons: the numbers a source paper publishes beside the ones gpusim measures.

A comparison module (one per seed paper, registered in :data:`gpusim.papers.PAPERS`)
turns an experiment's results table into a :class:`Comparison`: rows of "the
paper's number, ours, the ratio, one sentence on the difference", plus sections
(tables and charts as data) that the report draws. The paper's numbers are
constants copied from the paper; ours are always read from the results table,
never adjusted. A number the experiment did not run (a smaller CI-size overlay,
a method gpusim does not model) stays in the table with ``ours`` explaining why.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any, Callable

import pandas as pd

NOT_MODELLED = "not modelled"


class Missing(LookupError):
    """The results hold no finished run for a comparison's figure."""


@dataclass
class PaperRow:
    """One line of the "Paper vs gpusim" table."""

    source: str                  # where in the paper: "Table 4-1, Frame60", "Fig. 4-4", "§5.1"
    quantity: str                # what is compared, with its unit
    paper: float | str           # the paper's number (or a stated relation such as "> 1")
    ours: float | str            # ours, or why there is none ("not modelled", "not run at this size")
    note: str = ""               # one sentence: what our model leaves out, or what the paper leaves unstated
    kind: str = ""               # how to print the numbers: "", "share", "x", "bytes"
    met: bool | None = None      # whether the row meets its reproduction target (:func:`mark`); None: no target

    @property
    def verdict(self) -> str:
        """For a stated relation (paper "> 1", "< 1"): whether ours satisfies it; for a row with a target and no
        ratio (a summary, an order): "met" or "missed"; "" otherwise."""
        if isinstance(self.paper, str) and isinstance(self.ours, (int, float)) and self.paper[:1] in "<>":
            bound = float(self.paper[1:])
            holds = self.ours > bound if self.paper[0] == ">" else self.ours < bound
            return "holds" if holds else "does not hold"
        if self.met is not None and self.ratio != self.ratio:
            return "met" if self.met else "missed"
        return ""

    @property
    def ratio(self) -> float:
        if isinstance(self.paper, (int, float)) and isinstance(self.ours, (int, float)) and self.paper:
            return float(self.ours) / float(self.paper)
        return math.nan


@dataclass
class Section:
    """A titled part of a paper report: text, a table, and a chart of grouped bars (as data)."""

    title: str
    text: str = ""
    table: pd.DataFrame | None = None
    table_kinds: dict[str, str] = field(default_factory=dict)
    chart: pd.DataFrame | None = None          # long form: columns x, group, value
    chart_ylabel: str = ""
    chart_log: bool = False


@dataclass
class Comparison:
    title: str
    rows: list[PaperRow] = field(default_factory=list)
    sections: list[Section] = field(default_factory=list)
    summary: str = ""


@dataclass(frozen=True)
class Target:
    """How near the paper's number ours must come (the project's reproduction targets): within a ``factor``
    either way, within a ``relative`` share of the paper's number, or within ``points`` (shares: 0.1 is 10
    points)."""

    factor: float = 0.0
    relative: float = 0.0
    points: float = 0.0

    def holds(self, ours: float, paper: float) -> bool:
        if self.factor:
            return ours > 0 and paper > 0 and max(ours / paper, paper / ours) <= self.factor
        if self.relative:
            return paper != 0 and abs(ours / paper - 1) <= self.relative
        return abs(ours - paper) <= self.points

    def __str__(self) -> str:
        if self.factor:
            return f"within {self.factor:g}x"
        if self.relative:
            return f"within {self.relative:.0%}"
        return f"within {100 * self.points:g} points"


WITHIN_1_5X = Target(factor=1.5)


def mark(row: PaperRow, target: Target) -> PaperRow:
    """``row`` with ``met`` set and its note opened by the mark, when both numbers are there."""
    if isinstance(row.ours, (int, float)) and isinstance(row.paper, (int, float)):
        row.met = target.holds(float(row.ours), float(row.paper))
        mark_text = f"{target} of the paper: met" if row.met else f"misses: not {target} of the paper"
        row.note = f"{mark_text}; {row.note}" if row.note else mark_text
    return row


def summary_row(source: str, quantity: str, rows: list[PaperRow], share: float = 1.0, note: str = "") -> PaperRow:
    """How many of ``rows`` with a target meet it ("N of M (P%)"), met when at least ``share`` of them do."""
    marks = [r.met for r in rows if r.met is not None]
    goal = "all" if share == 1 else f"at least {share:.0%}"
    if not marks:
        return PaperRow(source, quantity, goal, "not run in this experiment", note)
    met = sum(marks)
    verdict = "met" if met >= share * len(marks) else "missed"
    return PaperRow(source, quantity, goal, f"{met} of {len(marks)} ({met / len(marks):.0%})",
                    f"target {goal}: {verdict}" + (f"; {note}" if note else ""), met=verdict == "met")


def order_row(source: str, quantity: str, paper: list[str], value: Callable[[str], float],
              note: str = "") -> PaperRow:
    """Whether ``value`` ranks the names high to low as ``paper`` does (both orders printed); "not run in this
    experiment" when the results lack one of them."""
    try:
        ours = {name: value(name) for name in paper}
    except Missing:
        return PaperRow(source, quantity, " > ".join(paper), "not run in this experiment", note)
    mine = sorted(paper, key=lambda name: -ours[name])
    same = mine == list(paper)
    return PaperRow(source, quantity, " > ".join(paper), " > ".join(mine),
                    ("same order: met" if same else "misses: the order differs") + (f"; {note}" if note else ""),
                    met=same)


def ok_runs(results: pd.DataFrame) -> pd.DataFrame:
    return results[results["status"] == "ok"]


def select(results: pd.DataFrame, **filters: Any) -> pd.DataFrame:
    """The finished runs whose columns equal ``filters`` (a missing column matches nothing)."""
    rows = ok_runs(results)
    for column, value in filters.items():
        if column not in rows:
            return rows.iloc[0:0]
        rows = rows[rows[column] == value]
    return rows


def one(results: pd.DataFrame, column: str, **filters: Any) -> float:
    """``column`` of the one finished run matching ``filters``; :class:`Missing` when there is none."""
    rows = select(results, **filters)
    if rows.empty or column not in rows or pd.isna(rows[column].iloc[0]):
        raise Missing(f"no finished run with {filters}")
    return float(rows[column].iloc[0])


def guarded(make_row, source: str, quantity: str, paper, note: str = "", kind: str = "") -> PaperRow:
    """A row whose ``ours`` is ``make_row()``; "not run in this experiment" when the results lack it."""
    try:
        ours = make_row()
    except Missing:
        ours = "not run in this experiment"
    return PaperRow(source, quantity, paper, ours, note, kind)


def mean(values: list[float]) -> float:
    """The mean of the figures a comparison found; :class:`Missing` when it found none."""
    if not values:
        raise Missing("nothing to average")
    return sum(values) / len(values)


def fps(results: pd.DataFrame, **filters: Any) -> float:
    """Frames per second at the GPU's clock of the one full-level run matching ``filters``: 10^6 over its
    microseconds."""
    return 1e6 / one(results, "microseconds", fidelity="full", **filters)


def vertex_source_note(results: pd.DataFrame, experiment: str) -> str:
    """How the runs' draws got their vertices (``raster.vertex_source``, a gpu-set of ``experiment``), as a
    note's tail."""
    sources = set(results["raster.vertex_source"].dropna()) if "raster.vertex_source" in results else set()
    if sources == {"host"}:
        return ("; every draw sends the mesh's indices and vertices from host memory over PCI Express (an "
                f"assumption: the paper does not say; configs/experiments/{experiment}.toml gives the reasons)")
    return "; vertices in device memory"
