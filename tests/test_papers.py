"""The seed experiments at their CI size: each report opens with its "Paper vs gpusim" table."""

from __future__ import annotations

import re

import pandas as pd
import pytest

from gpusim.experiment import load_experiment, run_experiment
from gpusim.papers import PAPERS
from gpusim.papers import seed000 as paper000
from gpusim.papers import seed002 as paper002
from gpusim.papers import seed003 as paper003
from gpusim.papers import seed004 as paper004
from gpusim.papers.base import WITHIN_1_5X, Missing, PaperRow, Target, mark, order_row, summary_row
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
    for name in ("Weighted-blended OIT", "MLAB, 2 layers", "MLAB, 4 layers", "MLAB, 2 layers, rasterizer-ordered view",
                 "MLAB, 4 layers, rasterizer-ordered view", "Moment-based OIT, 4 power moments, 80 bits",
                 "Moment-based OIT, 6 power moments, 112 bits", "Moment-based OIT, 4 trigonometric, 144 bits"):
        # the MBOIT paper's figures, on its frame's look-alike (at the CI's size, said so), with the 1.5x mark
        row = rows[("§1 table", f"{name}: time / hardware alpha blending, on the MBOIT paper's frame")]
        assert row[3].endswith("x") and float(row[4]) > 0 and "within 1.5x of the paper" in row[5], row
        assert "like-mboit-frame at 96x50, not its frame" in row[5]
        # against an RGBA16F baseline and on seed 002's own scenes: shown, not marked
        for quantity in (f"{name}: time / hardware alpha blending into RGBA16F, on the MBOIT paper's frame",
                         f"{name}: time / hardware alpha blending, mean over seed 002's look-alikes"):
            other = rows[("§1 table", quantity)]
            assert float(other[4]) > 0 and other[5].startswith("not a target"), other
    lucid = rows[("§1 table", "LucidRaster: time / hardware alpha blending, mean over scenes")]
    assert lucid[3].endswith("x") and float(lucid[4]) > 0
    results = pd.read_parquet(tmp_path / "results.parquet")
    df3 = results[(results["variant"] == "lucidraster") & (results["depth_filter"] == 3)]["stat.invalid_share"]
    df12 = results[(results["variant"] == "lucidraster") & (results["depth_filter"] == 12)]["stat.invalid_share"]
    assert (df12.to_numpy() <= df3.to_numpy()).all()


@pytest.mark.parametrize("name, first_row, lacks", [
    ("seed-000-ci", ("000 Table 3, Dragon", "MDTS frame rate (fps)"), False),
    ("seed-004-ci", ("Table 1, Dragon (871k)", "4 RGBZ: MP frame rate (fps)"), False),
])
def test_seed_ci_reports_open_with_the_paper_table(tmp_path, name, first_row, lacks):
    summary = run_experiment(load_experiment(name), tmp_path, workers=2, quiet=True)
    assert summary.failed == 0
    text = write_report(tmp_path).read_text()
    assert re.findall(r"^## .*$", text, flags=re.M)[0] == "## Paper vs gpusim"
    rows = paper_table(text)
    assert (rows[0][0], rows[0][1]) == first_row
    measured = [r for r in rows if r[3] not in ("not modelled", "not run in this experiment")]
    assert measured and all(r[4] != "-" for r in measured)       # every measured row has a ratio or verdict
    # methods gpusim lacks stay in the table (seed 000 and 004 now lack none)
    assert any(r[3] == "not modelled" for r in rows) == lacks


def test_every_paper_has_an_experiment_and_a_ci_overlay():
    for name in PAPERS:
        full, ci = load_experiment(name), load_experiment(f"{name}-ci")
        assert full.data["paper"] == ci.data["paper"] == name


# --- the reproduction targets, on small synthetic results tables --------------------------------------------------

NO_STATS = pd.DataFrame({"run": [], "stat": [], "labels": [], "value": []})


def synthetic(runs: list[dict], **columns) -> pd.DataFrame:
    """A results table of finished full-level runs (``columns`` are added, empty, when no run sets them)."""
    frame = pd.DataFrame([{"run": i, "status": "ok", "fidelity": "full", **r} for i, r in enumerate(runs)])
    for column, default in columns.items():
        if column not in frame:
            frame[column] = default
    return frame


def by_key(comparison) -> dict[tuple[str, str], object]:
    return {(r.source, r.quantity): r for r in comparison.rows}


def test_target_mark_and_summary_row():
    assert Target(factor=1.5).holds(1.4, 1.0) and Target(factor=1.5).holds(1.0, 1.4)
    assert not Target(factor=1.5).holds(1.6, 1.0) and not Target(factor=1.5).holds(-1.0, 1.0)
    assert Target(relative=0.2).holds(3.9, 3.3) and not Target(relative=0.2).holds(4.0, 3.3)
    assert Target(points=0.1).holds(0.22, 0.14) and not Target(points=0.1).holds(0.25, 0.14)
    assert [str(t) for t in (WITHIN_1_5X, Target(relative=0.2), Target(points=0.05))] == \
        ["within 1.5x", "within 20%", "within 5 points"]
    inside, outside = mark(PaperRow("s", "q", 2.0, 2.9, "why"), WITHIN_1_5X), mark(PaperRow("s", "q", 2.0, 3.1),
                                                                                    WITHIN_1_5X)
    assert inside.met and inside.note == "within 1.5x of the paper: met; why" and inside.verdict == ""
    assert outside.met is False and outside.note.startswith("misses")
    assert mark(PaperRow("s", "q", 2.0, "not run in this experiment"), WITHIN_1_5X).met is None
    cells = [PaperRow("s", "q", 1.0, v) for v in (1.0, 1.1, 1.2, 1.3, 2.0)]
    cells = [mark(c, WITHIN_1_5X) for c in cells] + [PaperRow("s", "q", 1.0, "not modelled")]
    four = summary_row("T", "pairs", cells, 0.8)
    assert (four.paper, four.ours, four.verdict, four.met) == ("at least 80%", "4 of 5 (80%)", "met", True)
    cells[3] = mark(PaperRow("s", "q", 1.0, 1.6), WITHIN_1_5X)
    three = summary_row("T", "pairs", cells, 0.8)
    assert (three.ours, three.verdict) == ("3 of 5 (60%)", "missed")
    assert three.note.startswith("target at least 80%: missed")
    assert summary_row("T", "pairs", cells[-1:]).ours == "not run in this experiment"


def test_order_row_lists_both_orders():
    same = order_row("s", "order", ["A", "B", "C"], {"A": 3, "B": 2, "C": 1}.__getitem__)
    assert (same.ours, same.verdict) == ("A > B > C", "met")
    other = order_row("s", "order", ["A", "B", "C"], {"A": 1, "B": 2, "C": 3}.__getitem__)
    assert (other.paper, other.ours, other.verdict) == ("A > B > C", "C > B > A", "missed")

    def missing(name):
        raise Missing(name)
    assert order_row("s", "order", ["A"], missing).ours == "not run in this experiment"


def seed000_results(speed_up: dict[str, float] | None = None) -> pd.DataFrame:
    """Every modelled Table 3 method on every look-alike at the paper's frame rate (times ``speed_up``)."""
    runs = []
    for method, variant in paper000.VARIANT.items():
        for i, model in enumerate(paper000.MODELS):
            if variant:
                rate = paper000.TABLE_3[method][0][i] * (speed_up or {}).get(method, 1.0)
                runs.append({"scene": paper000.SCENE[model], "variant": variant, "microseconds": 1e6 / rate})
    return synthetic(runs, geometry_passes=float("nan"))


def test_seed000_every_pair_within_1_5x_and_the_order():
    rows = by_key(paper000.compare(seed000_results(), NO_STATS))
    pairs = [r for (s, q), r in rows.items() if s.startswith("000 Table 3,") and q.endswith("/ DP frame rate")]
    assert len(pairs) == 9 * 5                                     # the other 9 methods over DP, 5 models
    summary = rows[("000 Table 3", "pairs of modelled methods within 1.5x of the paper's ratio")]
    assert (summary.ours, summary.verdict) == ("225 of 225 (100%)", "met")    # 10 methods: 45 pairs x 5 models
    assert rows[("000 Table 3", "models whose order of the methods is the paper's")].ours == "5 of 5 (100%)"
    bunny = rows[("000 Table 3, Bunny", "modelled methods by frame rate, fastest first")]
    assert bunny.paper == bunny.ours == "K-buffer > BDP > ABS > MDTS > SRAB > BDP2 > ADP > Liu > DDP > DP"
    assert rows[("000 Table 3, Dragon", "K-buffer / ABS frame rate")].note.startswith("within 1.5x")


def test_seed000_a_per_model_difference_survives_the_per_method_fit():
    # DP 3x too fast on the Bunny only: no one factor for DP fixes the Bunny without breaking the others
    results = seed000_results()
    bunny = results["scene"] == paper000.SCENE["Bunny"]
    results.loc[bunny & (results["variant"] == "depth-peeling"), "microseconds"] /= 3.0
    fit = by_key(paper000.compare(results, NO_STATS))[("000 Table 3", "pairs within 1.5x with each method's frame "
                                                                      "rates over its own fitted factor")]
    held, total = map(int, re.match(r"(\d+) of (\d+)", fit.ours).groups())
    assert total == 225 and 180 <= held < 225 and fit.note.startswith("[derived] a diagnostic")


def test_seed000_the_stanford_bunny_stands_for_its_look_alike_where_it_ran():
    results = seed000_results()
    assert paper000.scenes_in(results, paper000.SCENE)["Bunny"] == "like-bunny"
    real = results.copy()
    real.loc[real["scene"] == "like-bunny", "scene"] = "stanford-bunny"
    assert paper000.scenes_in(real, paper000.SCENE)["Bunny"] == "stanford-bunny"
    assert paper000.scenes_in(real, paper000.CUDP_SCENE)["Dragon"] == "like-dragon"
    rows = by_key(paper000.compare(real, NO_STATS))
    row = rows[("000 Table 3, Bunny", "ABS frame rate (fps)")]
    assert row.ours == pytest.approx(614) and row.note.startswith("the Stanford bunny itself")
    assert rows[("000 Table 3", "pairs of modelled methods within 1.5x of the paper's ratio")].verdict == "met"
    assert rows[("001 Table 1, Bunny", "CUDP2 frame rate (fps)")].note.startswith("the Stanford bunny itself")


def test_seed000_bucket_methods_geometry_passes_are_the_texts():
    """Table 3 prints no pass count for BDP, BDP2 and ADP; its caption and section 5.1 give 1, 2 and 2."""
    results = seed000_results()
    results["geometry_passes"] = results["variant"].map({"bdp": 1, "bdp2": 2, "adp": 3})
    rows = by_key(paper000.compare(results, NO_STATS))
    for method, ours in (("BDP", 1), ("BDP2", 2), ("ADP", 3)):
        row = rows[("000 Table 3 caption / §5.1, Dragon", f"{method} geometry passes")]
        assert (row.paper, row.ours) == (paper000.TEXT_PASSES[method], ours)
        assert row.note.startswith("[derived]")


def test_seed000_misses_when_methods_are_three_times_too_fast():
    # one method of ten 3x too fast misses 45 of 225 pairs, within the 80% target: two miss it
    one = by_key(paper000.compare(seed000_results({"DP": 3.0}), NO_STATS))
    summary = one[("000 Table 3", "pairs of modelled methods within 1.5x of the paper's ratio")]
    assert (summary.ours, summary.verdict) == ("180 of 225 (80%)", "met")     # the 45 pairs with DP miss
    rows = by_key(paper000.compare(seed000_results({"DP": 3.0, "DDP": 3.0}), NO_STATS))
    summary = rows[("000 Table 3", "pairs of modelled methods within 1.5x of the paper's ratio")]
    assert (summary.ours, summary.verdict) == ("145 of 225 (64%)", "missed")  # with DP or DDP, but DDP / DP, miss
    # two methods 3x too fast on every model: one factor each brings every pair back
    fit = "pairs within 1.5x with each method's frame rates over its own fitted factor"
    assert (rows[("000 Table 3", fit)].ours, rows[("000 Table 3", fit)].met) == ("225 of 225 (100%)", None)
    missed = rows[("000 Table 3, Lucy", "ABS / DP frame rate")]
    assert missed.met is False and missed.note.startswith("misses: not within 1.5x")
    assert rows[("000 Table 3, Lucy", "DDP / DP frame rate")].met is True
    order = rows[("000 Table 3, Dragon", "modelled methods by frame rate, fastest first")]
    assert order.paper == "ABS > BDP > K-buffer > MDTS > BDP2 > ADP > SRAB > Liu > DDP > DP"
    assert order.ours == "ABS > BDP > K-buffer > MDTS > BDP2 > DDP > ADP > SRAB > DP > Liu"
    assert order.verdict == "missed"
    # seed 001's Table 1 reads the same runs (its own paper numbers): all six pairs on each of five models
    assert re.fullmatch(r"\d+ of 30 \(\d+%\)",
                        rows[("001 Table 1", "pairs of modelled methods within 1.5x of the paper's ratio")].ours)


def seed004_results(slower: dict[tuple, float] | None = None) -> pd.DataFrame:
    """Table 1 at the paper's frame rates; ``slower`` divides the rate of (mode, dataset, k)."""
    runs = []
    for name, _, scene, _ in paper004.DATASETS:
        for k in (4, 16):
            for mode, rate in zip(("MP", "SP", "SPwH"), paper004.TABLE_1[(k, name)]):
                rate /= (slower or {}).get((mode, name, k), 1.0)
                passes = {"geometry_passes": k} if mode == "MP" else {}
                runs.append({"scene": scene, "microseconds": 1e6 / rate, **paper004._variant(mode, k), **passes})
            # the multi-pass k-buffer (not in the table): twice MP's rate in 2 passes
            runs.append({"scene": scene, "microseconds": 1e6 / (2 * paper004.TABLE_1[(k, name)][0]),
                         "geometry_passes": 2, **paper004._variant("MP-k", k)})
    return synthetic(runs, geometry_passes=float("nan"), hazards=float("nan"))


def test_seed004_sp_ratios_within_1_5x():
    rows = by_key(paper004.compare(seed004_results(), NO_STATS))
    summary = rows[("Table 1", "SP / MP and SP / SPwH within 1.5x of the paper's")]
    assert (summary.ours, summary.verdict) == ("12 of 12 (100%)", "met")
    rows = by_key(paper004.compare(seed004_results({("SPwH", "Lucy", 4): 10.0}), NO_STATS))
    summary = rows[("Table 1", "SP / MP and SP / SPwH within 1.5x of the paper's")]
    assert (summary.ours, summary.verdict) == ("11 of 12 (92%)", "missed")
    lucy = rows[("Table 1, Lucy (28.0M)", "4 RGBZ: SP / SPwH")]
    assert lucy.ratio == pytest.approx(10.0) and lucy.note.startswith("misses")
    assert rows[("Table 1, Lucy (28.0M)", "4 RGBZ: SP / MP")].met
    assert rows[("Table 1, Lucy (28.0M)", "4 RGBZ: SP / MP")].note.endswith("; vertices in device memory")
    # the experiment's assumption, vertices sent from host memory every draw, is said on every SP / MP row
    host = by_key(paper004.compare(seed004_results().assign(**{"raster.vertex_source": "host"}), NO_STATS))
    assert "from host memory over PCI Express (an assumption" in host[("Table 1, Dragon (871k)", "16 Z: SP / MP")].note
    # the multi-pass k-buffer's section: its passes and its rate against MP's and SP's for the same entries
    section = paper004.compare(seed004_results(), NO_STATS).sections[0]
    table = section.table.set_index(["dataset", "entries"])
    assert len(table) == 6 and (table["geometry passes"] == 2).all()
    assert table.loc[("Dragon", "16 Z"), "/ MP fps"] == pytest.approx(2.0)
    assert table.loc[("Dragon", "16 Z"), "/ SP fps"] == pytest.approx(2 * 10.3 / 139)
    assert not paper004.compare(seed004_results().query("variant != 'mpk-z' and variant != 'mpk-rgbz'"),
                                NO_STATS).sections


def seed002_results() -> tuple[pd.DataFrame, pd.DataFrame]:
    """Each look-alike with the NVidia SW/HW, DF costs at the paper's averages and stages 14/5/60/21%."""
    runs, stats = [], []
    for name, scene in paper002.SCENES.items():
        if scene is None:
            continue
        runs.append({"scene": scene, "variant": "alpha-blend", "cycles": 100.0})
        for df, cost in ((3, 1.0), (8, 1.02), (12, 1.17)):
            runs.append({"scene": scene, "variant": "lucidraster", "depth_filter": df,
                         "cycles": 100 * paper002.SW_HW_NV[name] * cost})
    results = synthetic(runs, width=320, height=166, **{"stat.invalid_share": 0.0})
    for rid in results[(results["variant"] == "lucidraster") & (results["depth_filter"] == 3)]["run"]:
        for part, cycles in (("setup", 14), ("bin-count", 2), ("bin-write", 3), ("raster-low", 60),
                             ("raster-high", 21)):
            stats.append({"run": rid, "stat": "pass_cycles", "labels": f"pass={part}", "value": cycles})
    return results, pd.DataFrame(stats)


def test_seed002_targets():
    rows = by_key(paper002.compare(*seed002_results()))
    mean_row = rows[("§1 table", "LucidRaster: time / hardware alpha blending, mean over scenes")]
    assert mean_row.met and mean_row.note.startswith("within 20% of the paper: met")
    nvidia = rows[("§3 NVidia table", "scenes whose LucidRaster SW/HW is within 1.5x of the paper's")]
    assert (nvidia.ours, nvidia.verdict) == ("7 of 7 (100%)", "met")
    # the AMD table's Boxes (2.70) is 1.58x below the NVidia one we reproduce: a miss
    amd = rows[("§3 AMD table", "scenes whose LucidRaster SW/HW is within 1.5x of the paper's")]
    assert (amd.ours, amd.verdict) == ("6 of 7 (86%)", "missed")
    assert rows[("§3 AMD table, Boxes", "LucidRaster SW/HW")].note.startswith("misses")
    assert rows[("§3 AMD table, Conference", "LucidRaster SW/HW")].met is None       # no look-alike
    for stage in ("setup", "binning", "low raster", "high raster"):      # high: 21% against 18%, within 10 points
        assert rows[("§3 NVidia table, averages", f"share of LucidRaster's time in {stage}")].met
    for df in (8, 12):
        assert rows[("§4 sorting errors, averages", f"time at DF={df} / time at DF=3, mean over scenes")].met
    overall = rows[("reproduction targets", "targets met")]
    assert (overall.ours, overall.verdict) == ("8 of 9 (89%)", "missed")


def test_seed002_intro_baselines_are_compared_on_the_mboit_frame():
    """WBOIT, MLAB and MBOIT's figures come from the MBOIT paper: their marked rows use its frame's look-alike
    alone, LucidRaster's mean uses seed 002's look-alikes alone."""
    runs = [{"scene": "like-bunny-002", "variant": "alpha-blend", "cycles": 100.0, "width": 2560, "height": 1330},
            {"scene": "like-bunny-002", "variant": "wboit", "cycles": 500.0, "width": 2560, "height": 1330},
            {"scene": "like-bunny-002", "variant": "lucidraster", "depth_filter": 3, "cycles": 330.0, "width": 2560,
             "height": 1330}]
    for variant, cycles in (("alpha-blend", 100.0), ("alpha-blend-rgba16f", 200.0), ("wboit", 150.0)):
        runs.append({"scene": "like-mboit-frame", "variant": variant, "cycles": cycles, "width": 128, "height": 128})
    runs.append({"scene": "like-mboit-frame", "variant": "lucidraster", "depth_filter": 3, "cycles": 1000.0,
                 "width": 128, "height": 128})
    rows = by_key(paper002.compare(synthetic(runs, **{"stat.invalid_share": 0.0}),
                                   pd.DataFrame(columns=["run", "stat", "labels", "value"])))
    frame = rows[("§1 table", "Weighted-blended OIT: time / hardware alpha blending, on the MBOIT paper's frame")]
    assert frame.ours == 1.5 and frame.met and "scaled 8x each way" in frame.note
    assert rows[("§1 table", "Weighted-blended OIT: time / hardware alpha blending into RGBA16F, on the MBOIT "
                             "paper's frame")].ours == 0.75
    assert rows[("§1 table", "Weighted-blended OIT: time / hardware alpha blending, mean over seed 002's "
                             "look-alikes")].ours == 5.0
    assert rows[("§1 table", "LucidRaster: time / hardware alpha blending, mean over scenes")].ours == 3.3


def test_seed002_frames_scale_to_the_paper():
    """A look-alike at its scaled frame stands for k^2 of it; at another size (the CI's) it is said not to."""
    runs = []
    for scene, (width, height) in (("like-dragon-002", (2560, 1330)), ("like-boxes-002", (640, 333)),
                                   ("like-teapot-002", (96, 50))):
        runs.append({"scene": scene, "variant": "alpha-blend", "cycles": 100.0, "microseconds": 2.0,
                     "fragments": 1000, "width": width, "height": height})
        runs.append({"scene": scene, "variant": "lucidraster", "depth_filter": 3, "cycles": 300.0,
                     "microseconds": 6.0, "fragments": 1000, "width": width, "height": height,
                     "stat.samples_per_tri_half_block": 4.0})
    rows = by_key(paper002.compare(synthetic(runs, **{"stat.invalid_share": 0.0}), pd.DataFrame(
        columns=["run", "stat", "labels", "value"])))
    assert rows[("§3 NVidia table, Dragon", "samples in the frame")].ours == 1000
    assert rows[("§3 NVidia table, Boxes", "samples in the frame")].ours == 16 * 1000
    assert rows[("§3 NVidia table, Boxes", "LucidRaster time (us)")].ours == 16 * 6.0
    assert "scaled 4x each way" in rows[("§3 NVidia table, Boxes", "LucidRaster SW/HW")].note
    teapot = rows[("§3 NVidia table, Teapot", "LucidRaster SW/HW")]
    assert teapot.ours == 3.0 and "not its frame" in teapot.note
    assert rows[("§3 NVidia table, Teapot", "samples in the frame")].ours == 1000


def seed003_results(tfss: float) -> pd.DataFrame:
    """Two frames with thesis-model times R-buffer 100, Weight-Factor 50 and TFSS ``tfss`` cycles."""
    runs = []
    for frame in (60, 480):
        for name, cycles in (("R-buffer", 100.0), ("TFSS", tfss), ("Weight-Factor", 50.0)):
            variant, params = paper003.TIMED[name]
            runs.append({"scene": paper003.frame_scene(frame), "variant": variant, "fidelity": "thesis",
                         "cycles": cycles, **params})
    return synthetic(runs, dropped_fragments=0, **{c: float("nan") for c in (
        "fragment_bytes", "depth_bytes", "address_bytes", "l_num", "d_avg")})


def test_seed003_time_order_and_reduction():
    rows = by_key(paper003.compare(seed003_results(55.0), NO_STATS))
    order = rows[("Fig. 4-7", "frames in the thesis's order of execution time")]
    assert (order.ours, order.verdict) == ("2 of 2 (100%)", "met")
    reduction = rows[("§5.1", "TFSS execution-time reduction vs R-buffer, mean over frames")]
    assert reduction.ours == pytest.approx(0.45) and reduction.met
    rows = by_key(paper003.compare(seed003_results(30.0), NO_STATS))    # TFSS faster than Weight-Factor
    frame = rows[("Fig. 4-7, Frame480", "execution time, slowest first")]
    assert frame.ours == "R-buffer > Weight-Factor > TFSS" and frame.verdict == "missed"
    assert rows[("Fig. 4-7", "frames in the thesis's order of execution time")].verdict == "missed"
    reduction = rows[("§5.1", "TFSS execution-time reduction vs R-buffer, mean over frames")]
    assert reduction.ours == pytest.approx(0.70) and reduction.note.startswith("misses: not within 10 points")
