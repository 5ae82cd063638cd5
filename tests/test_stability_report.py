"""The stability experiment (configs/experiments/stability.toml) at its CI size: [[scene-sweeps]] in experiment
files, and the report's Stability section, drawn from the results table.

The sweep runs once (126 analytic runs at 8x8, a few seconds); the section is written on its tables with one
run's figures changed, which the section must follow.
"""

from __future__ import annotations

from pathlib import Path

import pandas as pd
import pytest

from gpusim.errors import ConfigError
from gpusim.experiment import load_experiment
from gpusim.experiment.grid import expand
from gpusim.report.experiment import _Report
from gpusim.report.figures import MAX_PNG_BYTES
from gpusim.report.tables import fmt, most_faithful
from gpusim.schemes import scheme_names

ROOT = Path(__file__).resolve().parents[1]
SWEEPS = {"depth-complexity": "objects.0.layers", "alpha": "objects.0.alpha", "disorder": "objects.0.order"}


@pytest.fixture(scope="module")
def sweep(tmp_path_factory) -> Path:
    from conftest import ran_experiment
    return ran_experiment("stability-ci", tmp_path_factory.mktemp("stability-ci"))


def _section(root: Path, out: Path) -> str:
    report = _Report(root, out)
    report.figdir.mkdir(parents=True, exist_ok=True)
    report.stability()
    return "\n".join(report.lines)


def test_the_full_experiment_sweeps_every_scheme_over_depth_alpha_and_order():
    exp = load_experiment("stability")
    assert {e.scheme for e in exp.schemes} == set(scheme_names())
    assert {s.name: list(s.axes) for s in exp.scene_sweeps} == {
        "depth-complexity": ["objects.0.layers"], "alpha": ["objects.0.alpha", "objects.0.layers"],
        "disorder": ["objects.0.order", "objects.0.layers"]}
    assert exp.scene_sweeps[0].axes["objects.0.layers"] == [1, 4, 16, 64, 256]
    assert set(exp.scenes) == {"stress-layers", "coplanar", "alpha-extremes", "slivers"}
    runs = expand(exp)
    depth = {r.source.scene_set for r in runs if r.source.label == "depth-complexity"}
    assert depth == {(("objects.0.layers", n),) for n in (1, 4, 16, 64, 256)}


def test_the_ci_results_hold_each_sweep_as_scene_columns(sweep):
    results = pd.read_parquet(sweep / "results.parquet")
    for scene, key in SWEEPS.items():
        rows = results[results["scene"] == scene]
        assert rows[f"scene.{key}"].nunique() == 2, scene
        assert rows["scheme"].nunique() == len(scheme_names())
    layers = results[results["scene"] == "depth-complexity"]
    # layer-stack covers every pixel with each layer: depth complexity is the layer count
    assert (layers["fragments"] / layers["pixels"] == layers["scene.objects.0.layers"]).all()
    assert results.loc[results["scene"] == "alpha-extremes", [f"scene.{k}" for k in SWEEPS.values()]].isna().all().all()


def test_the_stability_section_has_its_parts_and_follows_the_table(sweep, tmp_path):
    # the sweep's tables with alpha-blend dropping 12,345 fragments on one scene: the section must show it
    results = pd.read_parquet(sweep / "results.parquet")
    hit = (results["scheme"] == "alpha-blend") & (results["scene"] == "alpha") & \
          (results["scene.objects.0.alpha"] == 1.0)
    assert hit.sum() == 1 and (results["dropped_fragments"] == 12345).sum() == 0
    results.loc[hit, ["dropped_fragments", "rmse"]] = [12345, 0.75]
    results.to_parquet(tmp_path / "results.parquet")
    for name in ("stats.parquet", "resolved.toml"):
        (tmp_path / name).write_bytes((sweep / name).read_bytes())
    text = _section(tmp_path, tmp_path)
    for heading in ("## Stability: the schemes against the scene",
                    "### Image error against simulated cycles, every scheme",
                    *(f"### `{scene}`: against `{key}`" for scene, key in SWEEPS.items()),
                    "### Dropped and misordered fragments"):
        assert heading in text, heading
    figures = sorted(p.name for p in (tmp_path / "figures").glob("*.png"))
    assert figures == ["stability-alpha.png", "stability-depth-complexity.png",
                       "stability-disorder-objects.0.layers-12.png", "stability-disorder-objects.0.layers-4.png",
                       "stability-error-vs-cycles.png"]
    assert all(0 < (tmp_path / "figures" / f).stat().st_size <= MAX_PNG_BYTES for f in figures)
    assert "Depth complexity (fragments per covered pixel) of depth-complexity: objects.0.layers=1: 1; " \
           "objects.0.layers=12: 12." in text
    # the k-buffer keeps k = 8 of 12 layers (drops 4 a pixel); sort-and-blend keeps all and misorders instead
    assert "| depth-complexity objects.0.layers=12 | kbuffer | 256 | 64 |" in text
    assert "| kbuffer-sort-blend | 0 | 0 | 64 | misordered_pairs |" in text
    assert "| wboit | 9 | 0 | 0 | 0 | - | 0 |" in text            # never drops; its error is an approximation
    assert "| alpha objects.0.alpha=1 | alpha-blend | 12,345 |" in text
    assert "| alpha-blend | 9 | 1 | 12,345 |" in text
    half = results[(results["scheme"] == "alpha-blend") & (results["scene"] == "alpha") &
                   (results["scene.objects.0.alpha"] == 0.5)]["rmse"].item()
    assert f"| alpha-blend | {fmt(half)} | 0.75 |" in text          # the alpha sweep's RMSE table


def test_no_stability_section_without_a_scene_sweep(tmp_path):
    assert _section(ROOT / "reports" / "quick-start", tmp_path) == ""


@pytest.mark.parametrize("extra, message", [
    ('[[scene-sweeps]]\nscene = "layer-stack"\nsett = 1\n',
     "scene-sweeps.0.sett: unknown key (valid: scene, name, set)"),
    ('[[scene-sweeps]]\nname = "x"\n', "scene-sweeps.0.scene: expected a scene name or file"),
    ('[[scene-sweeps]]\nscene = "layer-stack"\nset = { "objects.0.layerz" = [1, 2] }\n',
     "scene-sweeps.0.set on scene layer-stack: objects.0.layerz: unknown key"),
    ('[[scene-sweeps]]\nscene = "layer-stack"\nset = { "objects.0.layers" = [] }\n',
     "scene-sweeps.0.set.objects.0.layers: an empty list leaves no runs"),
    ('[[scene-sweeps]]\nscene = "layer-stack"\nset = { "objects.0.layers" = [1, 4] }\n'
     '[[scene-sweeps]]\nscene = "layer-stack"\nset = { "objects.0.layers" = 4 }\n',
     "'layer-stack' objects.0.layers=4 is listed twice"),
    ('[scene-set]\n"objects.0.alpha" = 0.5\n[[scene-sweeps]]\nscene = "layer-stack"\n'
     'set = { "objects.0.alpha" = [0.2] }\n', "scene-sweeps.0.set: objects.0.alpha is also in [scene-set]"),
])
def test_scene_sweep_errors_are_one_line(tmp_path, extra, message):
    path = tmp_path / "e.toml"
    path.write_text('scenes = ["coplanar"]\nsize = "8x8"\nfidelity = ["none"]\n[schemes.alpha-blend]\n' + extra)
    with pytest.raises(ConfigError) as info:
        load_experiment(str(path))
    assert message in str(info.value) and "\n" not in str(info.value)


def test_set_reaches_a_sweep_axis(tmp_path):
    exp = load_experiment("stability-ci", ["scene-sweeps.0.set.objects.0.layers=[3]"])
    assert exp.scene_sweeps[0].axes == {"objects.0.layers": [3]}
    with pytest.raises(ConfigError, match="'scene-sweeps.5' is not one of the file's 3"):
        load_experiment("stability-ci", ["scene-sweeps.5.set.objects.0.layers=[3]"])


def test_a_refused_run_falls_back_to_its_most_faithful_finished_level():
    rows = pd.DataFrame({"index": range(6), "setting": ["a", "a", "b", "b", "c", "c"],
                         "config": ["k"] * 6, "fidelity": ["analytic", "sampled"] * 3,
                         "status": ["ok", "ok", "ok", "failed", "failed", "failed"], "cycles": [1, 2, 3, 4, 5, 6]})
    runs, fallback = most_faithful(rows)
    assert runs["cycles"].tolist() == [2, 3] and fallback["setting"].tolist() == ["b"]


def test_committed_stability_report_matches_the_experiment():
    report = ROOT / "reports" / "stability"
    text = (report / "index.md").read_text()
    assert "## Stability: the schemes against the scene" in text and "![image error against simulated cycles" in text
    for png in (report / "figures").glob("*.png"):
        assert png.stat().st_size <= MAX_PNG_BYTES, png
    t = pd.read_parquet(report / "results.parquet")
    assert len(t) == len(expand(load_experiment("stability"))), \
        "reports/stability is not the experiment's: run `gpusim run stability` and commit reports/stability"
    assert (t["status"] != "pending").all()
    # the only failures are the event model's refusals, whose analytic runs stand in
    assert t.loc[t["status"] == "failed", "error"].str.contains("runner.max_operations").all()
