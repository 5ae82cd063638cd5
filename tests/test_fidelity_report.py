"""The fidelity report's tables (gpusim.report.tables) on a small hand-made results table, and the fidelity
experiment (configs/experiments/fidelity.toml) with its committed report."""

from __future__ import annotations

import math
from pathlib import Path

import pandas as pd
import pytest

from gpusim.report.tables import (busy_errors, decided_by, error_percentiles, fidelity_errors, fidelity_misses,
                                  fidelity_targets, sampled_wall_parts, with_labels)

ROOT = Path(__file__).resolve().parents[1]


def _results() -> pd.DataFrame:
    """Two scenes (one of 2M fragments) x two schemes x full, sampled and analytic on one GPU."""
    rows = []
    cases = {  # (scene, scheme): full cycles, sampled cycles, its interval, analytic cycles, fragments
        ("big", "kbuffer"): (1000, 1010, (990, 1030), 1200, 2_000_000),
        ("big", "zbuffer"): (500, 540, (520, 560), 480, 2_000_000),
        ("small", "kbuffer"): (100, 99, (95, 105), 104, 1000),
        ("small", "zbuffer"): (50, 50, (50, 50), 50, 1000),
    }
    walls = {"full": 10.0, "sampled": 0.5, "analytic": 0.1}
    for (scene, scheme), (full, sampled, (low, high), analytic, fragments) in cases.items():
        for level, cycles in (("full", full), ("sampled", sampled), ("analytic", analytic)):
            rows.append({"run": f"{scene}-{scheme}-{level}", "status": "ok", "error": "", "index": len(rows),
                         "scene": scene, "width": 8, "height": 8, "trace": "", "gpu": "gtx280", "fidelity": level,
                         "scheme": scheme, "variant": scheme, "cycles": cycles, "fragments": fragments,
                         "wall_seconds_timing": walls[level] * (2 if scene == "big" else 1),
                         "hazards": (40 if level == "full" else 30) if scheme == "kbuffer" else math.nan,
                         "cycles_ci95_low": low if level == "sampled" else math.nan,
                         "cycles_ci95_high": high if level == "sampled" else math.nan,
                         "cycle_error_estimate": 0.01 if level == "sampled" else math.nan})
    return pd.DataFrame(rows)


def _stats() -> pd.DataFrame:
    rows = []
    for scene in ("big", "small"):
        for scheme in ("kbuffer", "zbuffer"):
            run = f"{scene}-{scheme}"
            # the full level: busy cycles per instance; the others: per unit class
            rows += [(f"{run}-full", "memory.dram", "busy_cycles", f"instance={i}", 100.0) for i in range(2)]
            rows += [(f"{run}-sampled", "dram", "busy_cycles", "", 210.0), (f"{run}-analytic", "dram", "busy_cycles",
                                                                            "", 180.0)]
            rows += [(f"{run}-analytic", "machine", "pass_cycles", "pass=a,index=0,kind=geometry,bound=latency", 900),
                     (f"{run}-analytic", "machine", "pass_cycles", "pass=b,index=1,kind=fullscreen,bound=dram", 100)]
            rows += [(f"{run}-sampled", "sample", key, "", value)
                     for key, value in (("replicates", 4), ("sms", 1), ("share", 1 / 30), ("tiles", 64),
                                        ("tiles_per_replicate", 2), ("scale_check_sms", 2), ("scale_bias", -5.4))]
            rows += [(f"{run}-sampled", "machine", "cycles", "", 540.0)]
    # an L2 on the big z-buffer's runs: the sample's is half again as busy and hits 95% against 90%
    rows += [("big-zbuffer-full", "memory.l2", stat, f"instance={i}", value) for i in range(2)
             for stat, value in (("busy_cycles", 100.0), ("hits", 90.0), ("misses", 10.0))]
    rows += [("big-zbuffer-sampled", "l2", stat, "", value)
             for stat, value in (("busy_cycles", 300.0), ("hits", 190.0), ("misses", 10.0))]
    return pd.DataFrame(rows, columns=["run", "unit", "stat", "labels", "value"])


@pytest.fixture
def errors():
    return fidelity_errors(with_labels(_results()))


def test_errors_hold_each_approximate_run_against_full(errors):
    assert len(errors) == 8
    row = errors.set_index("run").loc["big-zbuffer-sampled"]
    assert row["setting"] == "big gtx280" and row["config"] == "zbuffer" and row["full_run"] == "big-zbuffer-full"
    assert row["cycle_error"] == pytest.approx(0.08) and row["speedup"] == pytest.approx(20.0)
    assert not row["inside"]                                   # 500 outside [520, 560]
    inside = errors[errors["fidelity"] == "sampled"].set_index("run")["inside"].astype(bool).to_dict()
    assert inside == {"big-kbuffer-sampled": True, "big-zbuffer-sampled": False, "small-kbuffer-sampled": True,
                      "small-zbuffer-sampled": True}
    assert errors[errors["fidelity"] == "analytic"]["inside"].isna().all()


def test_percentiles_per_level_and_scheme(errors):
    table = error_percentiles(errors, "cycle_error", ["fidelity"]).set_index("fidelity")
    sampled = sorted([0.01, 0.08, 0.01, 0.0])
    assert table.loc["sampled", "median"] == pytest.approx(pd.Series(sampled).median())
    assert table.loc["sampled", "p90"] == pytest.approx(pd.Series(sampled).quantile(0.9))
    assert table.loc["sampled", "max"] == pytest.approx(0.08) and table.loc["analytic", "max"] == pytest.approx(0.2)
    per = error_percentiles(errors, "cycle_error", ["fidelity", "scheme"])
    assert per[(per["fidelity"] == "analytic") & (per["scheme"] == "kbuffer")]["max"].item() == pytest.approx(0.2)


def test_targets_count_speed_on_large_cases_only(errors):
    t = fidelity_targets(errors).set_index(["level", "target"])
    assert t.loc[("sampled", "median abs. cycle error <= 2%"), "measured"] == pytest.approx(0.01)
    assert t.loc[("sampled", "median abs. cycle error <= 2%"), "met"] == "met"
    assert t.loc[("sampled", "max abs. cycle error <= 5%"), "met"] == "missed"          # 8%
    assert t.loc[("analytic", "max abs. cycle error <= 10%"), "met"] == "missed"        # 20%
    speed = t.loc[("sampled", "median speed-up over full >= 10x")]
    assert speed["cases"] == 2 and speed["measured"] == pytest.approx(20.0) and speed["met"] == "met"
    assert t.loc[("analytic", "median speed-up over full >= 50x"), "measured"] == pytest.approx(100.0)
    assert t.loc[("sampled", "full cycles inside the 95% interval >= 95%"), "measured"] == pytest.approx(0.75)
    assert t.loc[("sampled", "full cycles inside the 95% interval >= 95%"), "met"] == "missed"
    assert t.loc[("sampled", "cases with abs. cycle error <= 5%: >= 90%"), "measured"] == pytest.approx(0.75)
    small = fidelity_targets(errors[errors["fragments"] < 1_000_000]).set_index(["level", "target"])
    assert small.loc[("sampled", "median speed-up over full >= 10x"), "met"] == "no cases"


def test_misses_say_what_decided_them(errors):
    stats = _stats()
    assert decided_by(stats)["big-kbuffer-analytic"] == "latency 90%, dram 10%"
    misses = fidelity_misses(errors, stats).set_index(["fidelity", "setting", "config"])
    assert set(misses.index) == {("analytic", "big gtx280", "kbuffer"), ("sampled", "big gtx280", "zbuffer")}
    assert misses.loc[("analytic", "big gtx280", "kbuffer"), "decided by"] == "latency 90%, dram 10%"
    sampled = misses.loc[("sampled", "big gtx280", "zbuffer")]
    assert sampled["missed"] == "error and interval" and "4 x 1 SM" in sampled["decided by"]
    assert "2 of 64 tiles each; scale check on 2 SM: machine-size bias -1.00%" in sampled["decided by"]
    # the units furthest from the full run's busy cycles (over 5%), the furthest first, and the L2's hit rates
    assert sampled["decided by"].endswith("; busy against full: l2 +50%; L2 hits 95.0% (full 90.0%)")


def test_a_thinned_sample_says_so():
    from gpusim.report.tables import sample_sizes
    rows = [("r", "sample", k, "", v) for k, v in (("replicates", 4), ("sms", 1), ("share", 0.25 / 30), ("tiles", 2304),
                                                    ("tiles_per_replicate", 19), ("thin", 0.25), ("work_checks", 2))]
    rows.append(("r", "machine", "cycles", "", 1000.0))
    stats = pd.DataFrame(rows, columns=["run", "unit", "stat", "labels", "value"])
    assert sample_sizes(stats)["r"] == "4 x 1 SM (thinned to 25% of their work, 2 work checks), 19 of 2,304 tiles each"


def test_busy_errors_sum_the_full_levels_instances(errors):
    busy = busy_errors(errors, _stats())
    dram = busy[busy["unit"] == "dram"]
    assert set(busy["unit"]) == {"dram", "l2"} and len(dram) == 8
    assert dram[dram["fidelity"] == "sampled"]["busy_error"].tolist() == pytest.approx([0.05] * 4)
    assert dram[dram["fidelity"] == "analytic"]["busy_error"].tolist() == pytest.approx([-0.1] * 4)
    l2 = busy[busy["unit"] == "l2"].set_index("fidelity")["busy_error"]
    assert l2["sampled"] == pytest.approx(0.5) and math.isnan(l2["analytic"])      # the analytic level has none


@pytest.fixture(scope="module")
def corpus(tmp_path_factory) -> Path:
    """The fidelity corpus at its CI size (every scheme, two small scenes, gtx280 and modern, three levels)."""
    from conftest import ran_experiment
    return ran_experiment("fidelity-ci", tmp_path_factory.mktemp("fidelity-ci"))


def test_the_corpus_covers_every_scheme_gpu_and_scene():
    from gpusim.experiment import load_experiment
    from gpusim.schemes import scheme_names
    exp = load_experiment("fidelity")
    assert {e.scheme for e in exp.schemes} == set(scheme_names())
    assert set(exp.gpus) >= {"gtx280", "geforce7900gtx", "modern"} and exp.fidelity == ["full", "sampled", "analytic"]
    assert {s.name for s in exp.scene_sweeps} >= {"default", "bunny", "foliage", "nested-spheres", "thesis-frame120",
                                                  "stress-layers", "coplanar"}


def test_the_ci_corpus_reports_each_sampled_runs_interval(corpus):
    from gpusim.report.experiment import _Report
    results = pd.read_parquet(corpus / "results.parquet")
    sampled = results[results["fidelity"] == "sampled"]
    assert len(sampled) and (sampled["cycles_ci95_low"] <= sampled["cycles"]).all()
    assert (sampled["cycles"] <= sampled["cycles_ci95_high"]).all() and (sampled["cycle_error_estimate"] >= 0).all()
    assert results.loc[results["fidelity"] != "sampled", "cycles_ci95_low"].isna().all()
    report = _Report(corpus, corpus)
    report.figdir.mkdir(parents=True, exist_ok=True)
    report.error_against_time()
    text = "\n".join(report.lines)
    for heading in ("#### Targets", "#### Cycle error per level and scheme",
                    "#### The sampled level's 95% confidence interval", "#### RMW hazards and busy cycles per unit",
                    "#### Cases that miss"):
        assert heading in text, heading
    assert "no case here has that many fragments, so the speed targets are not measured" in text
    errors = fidelity_errors(with_labels(report.results))
    inside = int(errors["inside"].dropna().astype(bool).sum())
    assert f"inside the sampled run's 95% interval in {inside} of {len(sampled)} cases" in text
    # the CI scenes lie in at most 16 tiles: every sampled run is the run itself (sample.min_tiles), said so
    assert f"{len(sampled)} of the {len(sampled)} sampled runs simulated the whole run, once" in text
    assert (sampled["cycles"].to_numpy() == results.loc[results["fidelity"] == "full", "cycles"].to_numpy()).all()


def test_whole_sampled_runs_are_those_of_a_share_of_one():
    from gpusim.report.tables import whole_samples
    stats = _stats()
    stats.loc[(stats["run"] == "small-zbuffer-sampled") & (stats["stat"] == "share"), "value"] = 1.0
    assert whole_samples(stats) == {"small-zbuffer-sampled"}


def test_committed_fidelity_report_matches_the_experiment():
    """reports/fidelity/ is fidelity-report.toml's run (fidelity.toml's grid at the committed size)."""
    import tomllib

    from gpusim.experiment import load_experiment
    from gpusim.experiment.grid import expand
    from gpusim.report.figures import MAX_PNG_BYTES
    report = ROOT / "reports" / "fidelity"
    text = (report / "index.md").read_text()
    for heading in ("### The simulator's own fidelity: cycle error against wall time", "#### Targets",
                    "#### The sampled level's 95% confidence interval", "#### Cases that miss"):
        assert heading in text, heading
    for png in (report / "figures").glob("*.png"):
        assert png.stat().st_size <= MAX_PNG_BYTES, png
    t = pd.read_parquet(report / "results.parquet")
    assert len(t) == len(expand(load_experiment("fidelity"))) == len(expand(load_experiment("fidelity-report"))), \
        "reports/fidelity is not the experiment's: run `gpusim run fidelity-report` and commit reports/fidelity"
    assert (t["status"] == "ok").all(), t.loc[t["status"] != "ok", "error"].iloc[0]
    resolved = tomllib.loads((report / "resolved.toml").read_text())
    assert [s["set"] for s in resolved["scene-sweeps"]] == \
        [s["set"] for s in load_experiment("fidelity-report").resolved_data()["scene-sweeps"]]


def test_committed_speed_report_measures_the_speed_targets():
    """reports/fidelity-speed/ is fidelity-speed.toml's run: every case of at least 1M fragments, so its targets
    table measures the speed-ups; its only failed runs are refusals over runner.max_operations."""
    from gpusim.experiment import load_experiment
    from gpusim.experiment.grid import expand
    from gpusim.report.tables import FAST_CASE_FRAGMENTS, fast_cases
    report = ROOT / "reports" / "fidelity-speed"
    t = pd.read_parquet(report / "results.parquet")
    assert len(t) == len(expand(load_experiment("fidelity-speed"))), \
        "reports/fidelity-speed is not the experiment's: run `gpusim run fidelity-speed` and commit it"
    failed = t[t["status"] != "ok"]
    assert failed["error"].str.contains("over runner.max_operations").all(), failed["error"].tolist()
    assert (t.loc[t["status"] == "ok", "fragments"] >= FAST_CASE_FRAGMENTS).all()
    errors = fidelity_errors(with_labels(t))
    fast = fast_cases(errors)
    text = (report / "index.md").read_text()
    assert f"{FAST_CASE_FRAGMENTS:,} fragments only: 1 setting, {len(fast)} runs here." in text
    targets = fidelity_targets(errors).set_index(["level", "target"])
    speed = targets[targets.index.get_level_values("target").str.contains("speed-up")]
    assert (speed["cases"] > 0).all()


def test_the_sampled_levels_wall_time_is_split_on_the_speed_cases():
    """The speed cases' sampled runs: each part's share of the level's wall time, and the speed-up it would have
    with its samples free (the full level's wall time over the whole run's part and the rest)."""
    errors = fidelity_errors(with_labels(_results()))
    stats = pd.DataFrame([{"run": run, "unit": "sample", "stat": "wall_seconds", "labels": f"part={part}",
                           "value": value}
                          for run in ("big-kbuffer-sampled", "small-kbuffer-sampled")
                          for part, value in (("run", 0.2), ("programs", 0.1), ("events", 0.15), ("other", 0.0))])
    parts = sampled_wall_parts(errors, stats).set_index("config")
    assert len(parts) == 1                                   # the big kbuffer case alone: the others lack the split
    row, big = parts.iloc[0], errors.set_index("run").loc["big-kbuffer-sampled"]
    wall = big["wall_seconds"]
    assert row["run_share"] == pytest.approx(0.2 / wall) and row["events_share"] == pytest.approx(0.15 / wall)
    assert row["other_share"] == pytest.approx((wall - 0.45) / wall)     # the wall time in none of the parts
    assert row["speedup_samples_free"] == pytest.approx(big["full_wall_seconds"] / (wall - 0.25))
    # the share of their 0.25 s the samples may keep for 10x: what a tenth of full leaves after the rest
    assert row["samples_budget"] == pytest.approx(max(0.0, (big["full_wall_seconds"] / 10 - (wall - 0.25)) / 0.25))
    assert sampled_wall_parts(errors, stats.iloc[:0]).empty
