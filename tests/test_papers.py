"""The seed experiments at their CI size: each report opens with its "Paper vs gpusim" table."""

from __future__ import annotations

import re

import pandas as pd
import pytest

from gpusim.experiment import load_experiment, run_experiment
from gpusim.papers import PAPERS
from gpusim.papers.base import PaperRow
from gpusim.report.experiment import write_report


def paper_table(index_text: str) -> list[list[str]]:
    """The rows of the report's Paper vs gpusim table, as cells."""
    part = index_text.split("## Paper vs gpusim", 1)[1]
    lines = [line for line in part.splitlines() if line.startswith("| ") and not line.startswith("| source")]
    rows = []
    for line in lines:
        if line.startswith("|---"):
            continue
        rows.append([c.strip() for c in line.strip("|").split(" | ")])
        if not part.split(line, 1)[1].startswith("\n|"):
            break
    return rows


@pytest.fixture(scope="module")
def seed003(tmp_path_factory):
    out = tmp_path_factory.mktemp("seed003")
    summary = run_experiment(load_experiment("seed-003-ci"), out, workers=2, quiet=True)
    assert summary.failed == 0
    return out, write_report(out).read_text()


def test_seed003_report_opens_with_the_paper_table(seed003):
    _, text = seed003
    headings = re.findall(r"^## .*$", text, flags=re.M)
    assert headings[0] == "## Paper vs gpusim"
    rows = paper_table(text)
    by = {(r[0], r[1]): r for r in rows}
    # Table 4-1 and section 4.3.2 are reproduced exactly on the frames run; the others say they were not run
    for frame in (120, 480):
        assert by[(f"Table 4-1, Frame{frame}", "fragments")][4] == "1.000"
        assert by[(f"§4.3.2, Frame{frame}", "R-buffer execution time (cycles)")][4] == "1.000"
        assert by[(f"§4.3.2, Frame{frame}", "Weight-Factor execution time (cycles)")][4] == "1.000"
    assert by[("Table 4-1, Frame60", "fragments")][3] == "not run in this experiment"
    assert by[("Fig. 4-3, Frame480", "TFSS(L_num=3) memory / R-buffer memory")][4] == "holds"
    assert "### Sensitivity: what the thesis leaves unstated" in text


def test_seed003_comparison_reads_the_results_only(seed003):
    out, _ = seed003
    results = pd.read_parquet(out / "results.parquet")
    stats = pd.read_parquet(out / "stats.parquet")
    rows = {(r.source, r.quantity): r for r in PAPERS["seed-003"].compare(results, stats).rows}
    rb = results[(results["variant"] == "r-buffer") & (results["scene"] == "thesis-frame480")]
    assert rows[("§4.3.2, Frame480", "R-buffer execution time (cycles)")].ours == float(rb["cycles"].iloc[0])
    # the comparison follows the table: change our number and the row changes with it
    changed = results.copy()
    changed.loc[rb.index, "cycles"] = 1.0
    again = {(r.source, r.quantity): r for r in PAPERS["seed-003"].compare(changed, stats).rows}
    assert again[("§4.3.2, Frame480", "R-buffer execution time (cycles)")].ours == 1.0


def test_paper_row_ratio_and_verdict():
    assert PaperRow("s", "q", 2.0, 3.0).ratio == 1.5
    assert PaperRow("s", "q", "> 1", 1.2).verdict == "holds"
    assert PaperRow("s", "q", "< 1", 1.2).verdict == "does not hold"
    assert PaperRow("s", "q", 2.0, "not modelled").ratio != PaperRow("s", "q", 2.0, "not modelled").ratio


def test_seed002_ci_report(tmp_path):
    summary = run_experiment(load_experiment("seed-002-ci"), tmp_path, workers=2, quiet=True)
    assert summary.failed == 0
    text = write_report(tmp_path).read_text()
    assert re.findall(r"^## .*$", text, flags=re.M)[0] == "## Paper vs gpusim"
    rows = {(r[0], r[1]): r for r in paper_table(text)}
    assert rows[("§1 table", "MLAB, 2 layers: time / hardware alpha blending")][3] == "not modelled"
    lucid = rows[("§1 table", "LucidRaster: time / hardware alpha blending, mean over scenes")]
    assert lucid[3].endswith("x") and float(lucid[4]) > 0
    results = pd.read_parquet(tmp_path / "results.parquet")
    df3 = results[(results["variant"] == "lucidraster") & (results["depth_filter"] == 3)]["stat.invalid_share"]
    df12 = results[(results["variant"] == "lucidraster") & (results["depth_filter"] == 12)]["stat.invalid_share"]
    assert (df12.to_numpy() <= df3.to_numpy()).all()


@pytest.mark.parametrize("name, first_row", [
    ("seed-000-ci", ("000 Table 3, Dragon", "MDTS frame rate (fps)")),
    ("seed-004-ci", ("Table 1, Dragon (871k)", "4 RGBZ: MP frame rate (fps)")),
])
def test_seed_ci_reports_open_with_the_paper_table(tmp_path, name, first_row):
    summary = run_experiment(load_experiment(name), tmp_path, workers=2, quiet=True)
    assert summary.failed == 0
    text = write_report(tmp_path).read_text()
    assert re.findall(r"^## .*$", text, flags=re.M)[0] == "## Paper vs gpusim"
    rows = paper_table(text)
    assert (rows[0][0], rows[0][1]) == first_row
    measured = [r for r in rows if r[3] not in ("not modelled", "not run in this experiment")]
    assert measured and all(r[4] != "-" for r in measured)       # every measured row has a ratio or verdict
    assert any(r[3] == "not modelled" for r in rows)              # methods gpusim lacks stay in the table


def test_every_paper_has_an_experiment_and_a_ci_overlay():
    for name in PAPERS:
        full, ci = load_experiment(name), load_experiment(f"{name}-ci")
        assert full.data["paper"] == ci.data["paper"] == name
