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
from typing import Any

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

    @property
    def verdict(self) -> str:
        """For a stated relation (paper "> 1", "< 1"): whether ours satisfies it; "" otherwise."""
        if isinstance(self.paper, str) and isinstance(self.ours, (int, float)) and self.paper[:1] in "<>":
            bound = float(self.paper[1:])
            holds = self.ours > bound if self.paper[0] == ">" else self.ours < bound
            return "holds" if holds else "does not hold"
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
