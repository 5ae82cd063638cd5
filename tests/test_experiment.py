"""Experiments: files, overlays and --set, the grid, the results tables, resume, failures, determinism."""

from __future__ import annotations

import json
import os
import shutil
import signal
import subprocess
import sys
import time
import tomllib
from pathlib import Path

import pandas as pd
import pytest

from gpusim.cli import main
from gpusim.errors import ConfigError
from gpusim.experiment import expand, load_experiment, run_experiment
from gpusim.experiment.store import WALL_COLUMNS

ROOT = Path(__file__).resolve().parents[1]

SMALL = """
name = "small"
description = "a small sweep for the tests"
scenes = ["default"]
size = "40x32"
gpus = ["gtx280"]
fidelity = ["none", "analytic", "full", "thesis"]

[schemes.alpha-blend]
[schemes.kbuffer]
k = [2, 4]
mode = "sort-blend"
[schemes.tfss]
"""


def write(path: Path, text: str) -> Path:
    path.write_text(text)
    return path


def table(out: Path) -> pd.DataFrame:
    return pd.read_parquet(out / "results.parquet")


def same_table(a: pd.DataFrame, b: pd.DataFrame) -> None:
    """Equal apart from the wall-time columns."""
    pd.testing.assert_frame_equal(a.drop(columns=list(WALL_COLUMNS)), b.drop(columns=list(WALL_COLUMNS)))


# ------------------------------------------------------------------------------------------ the file and grid
def test_the_issue_example_gives_one_row_per_grid_point(tmp_path):
    exp = load_experiment(str(ROOT / "configs" / "experiments" / "kbuffer-k.toml"))
    runs = expand(exp)
    # 2 scenes x 1 GPU x 2 reorder-buffer sizes x (alpha-blend + 3 k values) x 2 levels
    assert len(runs) == 2 * 2 * 4 * 2
    assert [r.index for r in runs] == list(range(len(runs)))
    points = {(r.source.label, dict(r.gpu_set)["rop.reorder_entries"], r.label, r.params.get("k"), r.fidelity)
              for r in runs}
    assert len(points) == len(runs)
    kb = [r for r in runs if r.scheme == "kbuffer"]
    assert {r.params["mode"] for r in kb} == {"sort-blend"} and {r.params["k"] for r in kb} == {2, 4, 8}
    assert {r.gpu_config.rop.reorder_entries for r in runs} == {16, 64}
    assert {r.source.overrides for r in runs} == {("screen.width=320", "screen.height=240")}


def test_thesis_level_is_skipped_for_other_schemes_with_one_reason(tmp_path):
    runs = expand(load_experiment(str(write(tmp_path / "e.toml", SMALL))))
    skipped = [r for r in runs if r.skip]
    assert {r.scheme for r in skipped} == {"alpha-blend", "kbuffer"} and {r.fidelity for r in skipped} == {"thesis"}
    assert len({r.skip for r in skipped}) == 1 and "tfss" in skipped[0].skip


def test_include_overlays_and_set_overrides(tmp_path):
    write(tmp_path / "base.toml", SMALL)
    top = write(tmp_path / "top.toml", 'include = "base.toml"\nname = "top"\nfidelity = ["full"]\n'
                                       '[schemes.kbuffer]\nk = [8]\n')
    exp = load_experiment(str(top))
    assert exp.name == "top" and exp.fidelity == ["full"] and exp.size == (40, 32)
    kb = next(e for e in exp.schemes if e.label == "kbuffer")
    assert kb.axes == {"k": [8], "mode": ["sort-blend"]}           # tables merge key by key
    exp = load_experiment(str(top), ['fidelity=["analytic", "full"]', "schemes.kbuffer.k=[2, 16]",
                                     "gpu-set.rop.reorder_entries=[8, 32]", 'size="24x16"'])
    runs = expand(exp)
    assert exp.fidelity == ["analytic", "full"] and exp.size == (24, 16)
    assert {r.params["k"] for r in runs if r.scheme == "kbuffer"} == {2, 16}
    assert {dict(r.gpu_set)["rop.reorder_entries"] for r in runs} == {8, 32}
    assert len(runs) == 2 * 4 * 2                      # reorder sizes x (alpha-blend, 2 k, tfss) x levels


def test_config_command_prints_runs_and_count(tmp_path, capsys):
    path = write(tmp_path / "e.toml", SMALL)
    assert main(["config", str(path)]) == 0
    out = capsys.readouterr().out.strip().splitlines()
    assert out[-1] == "16 runs (3 skipped)"
    assert sum("kbuffer" in line and "k=2 mode=sort-blend" in line for line in out) == 4
    assert not (tmp_path / "reports").exists()
    assert main(["config", str(path), "--toml", "--set", "schemes.kbuffer.k=[4]"]) == 0
    resolved = tomllib.loads(capsys.readouterr().out)
    assert resolved["schemes"]["kbuffer"] == {"k": [4], "mode": "sort-blend"} and resolved["size"] == "40x32"


@pytest.mark.parametrize("text, message", [
    ('scenes = ["default"]\nbogus = 1\n[schemes.alpha-blend]\n', "bogus: unknown key (valid: name, description"),
    ('scenes = ["default"]\n[schemes.teapot]\n', "schemes.teapot: unknown scheme 'teapot' (valid: adaptive-bucket-depth-peeling, alpha-blend"),
    ('scenes = ["default"]\n[schemes.kbuffer]\nkk = 4\n', "schemes.kbuffer.kk: unknown parameter of kbuffer "
                                                          "(valid: k, mode"),
    ('scenes = ["default"]\n[schemes.kbuffer]\nk = [4, 0]\n', "schemes.kbuffer: k: must be >= 1"),
    ('scenes = ["default"]\n[schemes.kbuffer]\nmode = "peal"\n', "'peal' is not a valid choice (valid: peel, "
                                                                  "sort-blend)"),
    ('scenes = ["default"]\ngpus = ["gtx9999"]\n[schemes.kbuffer]\n', "gpus: 'gtx9999' is not a GPU preset (valid: "
                                                                      "geforce7900gtx, gtx280, laptop-ampere, modern)"),
    ('scenes = ["default"]\n[schemes.kbuffer]\n[gpu-set]\n"rop.entries" = 4\n',
     "gpu-set: rop.entries: unknown key (valid: units, reorder_entries"),
    ('scenes = ["default"]\n[schemes.kbuffer]\n[gpu-set]\n"rop.units" = [8, 0]\n', "gpu-set: rop.units: must be >= 1"),
    ('scenes = ["default"]\nfidelity = ["fast"]\n[schemes.kbuffer]\n', "fidelity: 'fast' is not a level (valid: none, "
                                                                       "analytic"),
    ('scenes = ["nowhere"]\n[schemes.kbuffer]\n', "unknown scene 'nowhere' (built-in scenes:"),
    ('traces = ["missing.npz"]\n[schemes.kbuffer]\n', "traces: missing.npz: no such file"),
    ('scenes = ["default"]\nsize = "big"\n[schemes.kbuffer]\n', "size: 'big' is not WIDTHxHEIGHT"),
    ('scenes = ["default"]\n', "schemes: name at least one scheme"),
    ('scenes = ["default"]\ninclude = "nope.toml"\n[schemes.kbuffer]\n', "include: nope.toml: no such file"),
    ('scenes = ["default"]\n[schemes.kbuffer]\nk = [4, 4]\n', "schemes.kbuffer.k: lists 4 twice"),
    ('scenes = ["default"]\n[scene-set]\n"camera.fov" = 40\n[schemes.kbuffer]\n', "camera.fov: unknown key"),
    ('scenes = ["default"\n', "invalid TOML"),
    ('scenes = ["default", "../configs/scenes/default.toml"]\n[schemes.kbuffer]\n',
     "would both be the scene 'default' in the results"),
    ('scenes = ["default"]\n[schemes.kbuffer]\n[gpu-set]\n"runner.workers" = [1, 2]\n',
     "gpu-set.runner.workers: the number of processes changes no figure"),
    ('scenes = ["default"]\n[schemes.kbuffer]\nscheme = "tfss"\n', "schemes.kbuffer: the label names the scheme"),
    (b'scenes = ["d\xe9fault"]\n', "not UTF-8 text"),
    ('scenes = ["default"]\nschemes = 3\n', "schemes: expected tables such as [schemes.kbuffer]"),
    ('scenes = ["default"]\ngpus = ["nofile.toml"]\n[schemes.kbuffer]\n', "gpus: nofile.toml: no such GPU file"),
    ('scenes = ["default"]\ndescription = """two\nlines"""\n[schemes.kbuffer]\n', "description: expected one line"),
])
def test_bad_experiment_fails_before_running_with_one_line(tmp_path, capsys, text, message):
    (tmp_path / "configs").mkdir()
    path = tmp_path / "configs" / "bad.toml"
    path.write_bytes(text) if isinstance(text, bytes) else path.write_text(text)
    (tmp_path / "configs" / "scenes").mkdir()
    shutil.copy(ROOT / "configs" / "scenes" / "default.toml", tmp_path / "configs" / "scenes")
    out = tmp_path / "out"
    assert main(["run", str(path), "-o", str(out), "--quiet"]) == 2
    err = capsys.readouterr().err
    assert message in err, err
    assert len(err.strip().splitlines()) == 1 and err.startswith("gpusim: error: ") and str(path) in err
    assert not out.exists()


@pytest.mark.parametrize("args, message", [
    (["--set", "fidelity"], "expected KEY=VALUE"),
    (["--set", "schemes.kbuffer.k=[0]"], "k: must be >= 1"),
    (["--workers", "0"], "--workers 0: give at least 1"),
    (["--cluster", "tcp://127.0.0.1:9", "--workers", "2"], "exclude each other"),
    (["--cluster", "tcp://127.0.0.1:9"], "cannot reach a dask scheduler"),
    (["--set", "include=other.toml"], "include is read from the file before --set applies"),
])
def test_bad_command_line_is_one_line(tmp_path, capsys, args, message):
    path = write(tmp_path / "e.toml", SMALL)
    assert main(["run", str(path), "-o", str(tmp_path / "out"), "--quiet", *args]) == 2
    err = capsys.readouterr().err
    assert message in err and len(err.strip().splitlines()) == 1
    assert not (tmp_path / "out").exists()


def test_an_output_path_that_cannot_hold_results_is_one_line(tmp_path, capsys):
    path = write(tmp_path / "e.toml", SMALL.replace('["none", "analytic", "full", "thesis"]', '["none"]'))
    (tmp_path / "afile").write_text("x")
    for out in (tmp_path / "afile", tmp_path / "afile" / "below"):
        assert main(["run", str(path), "-o", str(out), "--quiet"]) == 2
        err = capsys.readouterr().err
        assert err.startswith("gpusim: error: ") and len(err.strip().splitlines()) == 1, err
        assert "Traceback" not in err
    assert (tmp_path / "afile").read_text() == "x"


def test_a_scene_with_no_fragments_runs(tmp_path):
    path = write(tmp_path / "e.toml", 'scenes = ["default"]\nsize = "16x16"\nfidelity = ["none", "full"]\n'
                                      '[scene-set]\n"camera.target" = [[0.0, 0.6, 100.0]]\n[schemes.alpha-blend]\n')
    summary = run_experiment(load_experiment(str(path)), tmp_path / "out", workers=1, quiet=True)
    assert summary.failed == 0 and (table(tmp_path / "out")["fragments"] == 0).all()


# ------------------------------------------------------------------------------------------- running a sweep
@pytest.fixture(scope="module")
def small_run(tmp_path_factory):
    """The small sweep run once in this process; (experiment file, output directory)."""
    folder = tmp_path_factory.mktemp("small")
    path = write(folder / "e.toml", SMALL)
    out = folder / "out"
    summary = run_experiment(load_experiment(str(path)), out, workers=1, quiet=True)
    assert summary.failed == 0 and summary.skipped == 3 and summary.ok == 13
    return path, out


def test_results_table_has_a_row_per_run_with_axes_and_figures(small_run):
    _, out = small_run
    t = table(out)
    assert len(t) == 16 and t["run"].is_unique and list(t["index"]) == list(range(16))
    assert t.equals(pd.read_parquet(out / "results.parquet"))
    csv = pd.read_csv(out / "results.csv")
    assert list(csv.columns) == list(t.columns) and len(csv) == 16
    for column in ("run", "status", "error", "scene", "gpu", "fidelity", "scheme", "k", "mode", "l_num", "cycles",
                   "wall_seconds_functional", "wall_seconds_timing", "footprint_bytes", "accesses",
                   "dropped_fragments", "hazards", "rmse", "psnr", "differing_pixels", "stat.batches"):
        assert column in t, column
    ok = t[t["status"] == "ok"]
    assert set(t["status"]) == {"ok", "skipped"}
    assert ok[ok["fidelity"] == "none"]["cycles"].isna().all()
    assert (ok[ok["fidelity"] != "none"]["cycles"] > 0).all()
    assert ok["stat.batches"].notna().sum() == len(ok[ok["scheme"] == "kbuffer"])       # NaN for other schemes
    assert ok[(ok["scheme"] == "kbuffer") & (ok["fidelity"] == "full")]["hazards"].notna().all()
    # the functional figures do not depend on the level
    kb2 = ok[(ok["scheme"] == "kbuffer") & (ok["k"] == 2)]
    assert kb2["rmse"].nunique() == 1 and kb2["footprint_bytes"].nunique() == 1
    tfss = ok[ok["scheme"] == "tfss"]
    assert set(tfss["fidelity"]) == {"none", "analytic", "full", "thesis"}


def test_stats_table_is_long_form_and_agrees_with_the_row(small_run):
    _, out = small_run
    t, s = table(out), pd.read_parquet(out / "stats.parquet")
    assert list(s.columns) == ["run", "unit", "stat", "labels", "value", "value_unit", "description"]
    assert set(s["run"]) == set(t[t["status"] == "ok"]["run"])
    row = t[(t["scheme"] == "kbuffer") & (t["fidelity"] == "full") & (t["k"] == 4)].iloc[0]
    mine = s[s["run"] == row["run"]]
    accesses = mine[(mine["unit"] == "scheme") & (mine["stat"] == "accesses")]
    assert accesses["value"].sum() == row["accesses"]
    assert accesses["labels"].str.match(r"structure=\w+,operation=\w+").all()
    footprint = mine[(mine["stat"] == "footprint_bytes")]["value"].sum()
    assert footprint == row["footprint_bytes"]
    assert mine[(mine["unit"] == "machine") & (mine["stat"] == "cycles")]["value"].iloc[0] == row["cycles"]
    assert mine[mine["stat"] == "pass_cycles"]["value"].sum() == row["cycles"]
    assert {"memory.dram"} <= set(mine["unit"])
    assert mine[mine["unit"] == "memory.dram"]["labels"].str.startswith("instance=").all()


def test_submitted_triangles_stat_is_what_the_timing_model_charges():
    """A trace whose metadata does not count its triangles (a CSV import) reports the highest primitive id + 1,
    as the front end and the k-buffer's batches count them; a trace that says reports its own count."""
    import numpy as np
    from gpusim.experiment.execute import trace_stat_rows
    from gpusim.trace import FragmentTrace
    n = 5
    fields = dict(x=np.arange(n, dtype=np.uint16), y=np.zeros(n, np.uint16), z=np.full(n, 0.5, np.float32),
                  rgba=np.full((n, 4), 0.5, np.float32), prim=np.array([0, 0, 3, 7, 7], np.uint32),
                  opaque=np.zeros(n, bool))
    bare = FragmentTrace(width=8, height=1, **fields)
    (row,) = trace_stat_rows(bare)
    assert (row["stat"], row["value"], row["value_unit"]) == ("primitives_submitted", 8, "triangles")
    said = FragmentTrace(width=8, height=1, meta={"primitives": 12}, **fields)
    assert trace_stat_rows(said)[0]["value"] == 12


def test_each_run_has_its_files(small_run):
    _, out = small_run
    t = table(out)
    assert (out / "resolved.toml").is_file()
    for _, row in t[t["status"] == "ok"].iterrows():
        folder = out / "runs" / row["run"]
        record = json.loads((folder / "record.json").read_text())
        assert record["scheme"] == row["scheme"] and (folder / "image.png").is_file()
        assert ("timing" in record) == (row["fidelity"] != "none")
        assert f"scheme = \"{row['scheme']}\"" in (folder / "config.toml").read_text()
    full_kb = t[(t["scheme"] == "kbuffer") & (t["fidelity"] == "full")].iloc[0]
    assert (out / "runs" / full_kb["run"] / "image-timed.png").is_file()


def test_rerun_reuses_everything_and_is_deterministic(small_run, tmp_path):
    path, out = small_run
    first = table(out)
    again = run_experiment(load_experiment(str(path)), out, workers=1, quiet=True)
    assert again.reused == 13 and again.computed == 0
    same_table(first, table(out))
    fresh = tmp_path / "fresh"                      # the same experiment computed again from nothing
    run_experiment(load_experiment(str(path)), fresh, workers=2, quiet=True)
    same_table(first, table(fresh))
    a, b = pd.read_parquet(out / "stats.parquet"), pd.read_parquet(fresh / "stats.parquet")
    pd.testing.assert_frame_equal(a, b)


def test_run_ids_follow_config_and_trace_content(small_run, tmp_path):
    path, out = small_run
    ids = set(table(out)["run"])
    other = run_experiment(load_experiment(str(path), ['size="40x30"', 'fidelity=["none"]']), tmp_path / "o",
                           workers=1, quiet=True)
    assert other.reused == 0
    assert not ids & set(table(tmp_path / "o")["run"])
    same = load_experiment(str(path), ["gpu-set.runner.workers=1"])          # changes no figure: same ids
    assert {r.gpu_config.runner.workers for r in expand(same)} == {1}
    copy = tmp_path / "copy"
    shutil.copytree(out, copy)
    assert run_experiment(same, copy, workers=1, quiet=True).reused == 13


def test_runs_made_by_other_code_are_computed_again(small_run, tmp_path, monkeypatch):
    """A run's id holds the model's code: a sweep into runs an edited model made reuses none of them, and gives
    the same figures when the edit changed none."""
    from gpusim.experiment import grid
    path, out = small_run
    copy = tmp_path / "copy"
    shutil.copytree(out, copy)
    monkeypatch.setattr(grid, "model_fingerprint", lambda: "0" * 16)
    again = run_experiment(load_experiment(str(path)), copy, workers=1, quiet=True)
    assert again.reused == 0 and again.computed == 13
    before, after = table(out), table(copy)
    assert not set(before["run"]) & set(after["run"])
    same_table(before.drop(columns="run"), after.drop(columns="run"))


def test_the_model_fingerprint_follows_the_models_code_not_the_reports(tmp_path):
    from gpusim.experiment.grid import source_fingerprint
    for rel in ("hw/core.py", "report/tables.py", "cli/main.py", "__init__.py"):
        (tmp_path / rel).parent.mkdir(parents=True, exist_ok=True)
        (tmp_path / rel).write_text("x = 1\n")
    first = source_fingerprint(tmp_path)
    (tmp_path / "report" / "tables.py").write_text("x = 2\n")
    (tmp_path / "cli" / "main.py").write_text("x = 2\n")
    assert source_fingerprint(tmp_path) == first
    (tmp_path / "hw" / "core.py").write_text("x = 2\n")
    changed = source_fingerprint(tmp_path)
    assert changed != first and len(changed) == 16
    (tmp_path / "hw" / "core.py").rename(tmp_path / "hw" / "unit.py")     # a move is a change too
    assert source_fingerprint(tmp_path) not in (first, changed)


def test_failed_runs_are_rows_and_the_exit_status_says_so(tmp_path, capsys):
    path = write(tmp_path / "e.toml", SMALL.replace("[schemes.alpha-blend]", "[gpu-set]\n\"runner.max_cycles\" = 2000"
                                                    "\n[schemes.alpha-blend]"))
    out = tmp_path / "out"
    code = main(["run", str(path), "-o", str(out), "--quiet", "--workers", "1", "--no-report"])
    lines = capsys.readouterr().out.strip().splitlines()
    t = table(out)
    failed = t[t["status"] == "failed"]
    assert code == 1 and lines[-1] == f"{len(failed)} of 16 runs failed"
    assert len(failed) and set(failed["fidelity"]) == {"full"}
    assert failed["error"].str.contains("max_cycles").all() and not failed["error"].str.contains("\n").any()
    assert failed["footprint_bytes"].notna().all()                 # the functional figures are kept
    assert (t[t["fidelity"] == "none"]["status"] == "ok").all()
    assert not any((out / "runs" / r / "outcome.json").read_text().count('"ok"') for r in failed["run"])
    again = run_experiment(load_experiment(str(path)), out, workers=1, quiet=True)
    assert again.computed == len(failed)                          # a failed run is tried again


def test_a_trace_file_experiment_sweeps_one_axis(tmp_path):
    from gpusim.scene import load_scene, trace_scene
    from gpusim.trace_io import save_trace
    scene, base = load_scene("foliage", ["screen.width=48", "screen.height=48", "objects.1.count=200"])
    save_trace(trace_scene(scene, base, progress=False), tmp_path / "f.npz")
    path = write(tmp_path / "df.toml", 'traces = ["f.npz"]\nfidelity = ["none"]\n'
                                       '[schemes.lucidraster]\ndepth_filter = [1, 3]\n')
    run_experiment(load_experiment(str(path)), tmp_path / "out", workers=1, quiet=True)
    t = table(tmp_path / "out")
    assert list(t["depth_filter"]) == [1, 3] and list(t["scene"]) == ["f", "f"]
    assert t["stat.invalid_pixels"].iloc[0] >= t["stat.invalid_pixels"].iloc[1]


# ------------------------------------------------------------------------------------ interruption and resume
KILL = SMALL.replace('size = "40x32"', 'size = "64x48"').replace(
    '[schemes.tfss]', '[schemes.tfss]\nl_num = [1, 2, 3]\n[schemes.freepipe-abuffer]\nlayers = [4, 8, 16]\n'
                      '[schemes.depth-peeling]\n[schemes.dual-depth-peeling]\n[schemes.r-buffer]')


def _finished(out: Path) -> int:
    return sum(1 for _ in (out / "runs").glob("*/outcome.json")) if (out / "runs").is_dir() else 0


@pytest.mark.parametrize("sig", [signal.SIGKILL, signal.SIGTERM])
def test_a_killed_sweep_resumes_to_the_same_table(tmp_path, sig):
    path = write(tmp_path / "e.toml", KILL)
    out = tmp_path / "out"
    cmd = [sys.executable, "-m", "gpusim", "run", str(path), "-o", str(out), "--workers", "2", "--quiet",
           "--no-report"]
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, cwd=ROOT,
                            env=dict(os.environ, PYTHONFAULTHANDLER="1"))     # SIGABRT dumps every thread
    deadline = time.monotonic() + 120
    while _finished(out) < 3 and proc.poll() is None and time.monotonic() < deadline:
        time.sleep(0.02)
    assert proc.poll() is None, "the sweep ended before it could be killed; make it longer"
    proc.send_signal(sig)
    try:
        _, err = proc.communicate(timeout=60)
    except subprocess.TimeoutExpired:          # it went on after the signal: say where each thread was
        proc.send_signal(signal.SIGABRT)
        _, err = proc.communicate(timeout=60)
        pytest.fail(f"the sweep did not stop within 60 s of the signal ({_finished(out)} runs finished); "
                    f"its threads: {err.decode()[-4000:]}")
    assert proc.returncode == (-signal.SIGKILL if sig == signal.SIGKILL else 130), \
        f"exit {proc.returncode} with {_finished(out)} runs finished; stderr: {err.decode()[-1500:]}"
    if sig == signal.SIGTERM:
        assert b"run the same command again to resume" in err
    done = _finished(out)
    total = len(expand(load_experiment(str(path))))
    assert 3 <= done < total - 4
    if (out / "results.parquet").exists():                          # never corrupt: it reads
        partial = pd.read_parquet(out / "results.parquet")
        assert set(partial["status"]) <= {"ok", "pending", "skipped"} and "pending" in set(partial["status"])
    resumed = run_experiment(load_experiment(str(path)), out, workers=2, quiet=True)
    assert resumed.reused >= done - 2 and resumed.failed == 0       # at most the runs in flight are lost
    reference = run_experiment(load_experiment(str(path)), tmp_path / "ref", workers=1, quiet=True)
    assert reference.failed == 0
    same_table(table(tmp_path / "ref"), table(out))
    time.sleep(1.0)                                                 # orphaned workers notice and leave
    if sys.platform.startswith("linux"):
        ps = subprocess.run(["ps", "-eo", "ppid,args"], capture_output=True, text=True).stdout
        assert not [line for line in ps.splitlines() if line.strip().startswith("1 ") and "spawn_main" in line
                    and str(os.getpid()) not in line]


def test_a_stop_lost_in_a_finalizer_still_stops_the_sweep(tmp_path, monkeypatch, capsys):
    """A SIGTERM handled while Python runs a finalizer loses its KeyboardInterrupt ("Exception ignored");
    the recorded stop still ends the sweep after that task, with exit 130 and the finished runs kept."""
    import gpusim.experiment.executors as executors
    path = write(tmp_path / "e.toml", SMALL)
    real, calls = executors.execute, []

    class SignalledInFinalizer:
        def __del__(self):
            os.kill(os.getpid(), signal.SIGTERM)
            for _ in range(10_000):          # the handler runs here, in __del__: its exception is lost
                pass

    def execute(task, trace, reference):
        calls.append(task)
        if len(calls) == 2:
            SignalledInFinalizer()           # collected at once
        return real(task, trace, reference)

    lost = []
    monkeypatch.setattr(executors, "execute", execute)
    monkeypatch.setattr(sys, "unraisablehook", lambda u: lost.append(u.exc_type))
    rc = main(["run", str(path), "-o", str(tmp_path / "out"), "--workers", "1", "--quiet", "--no-report"])
    err = capsys.readouterr().err
    assert lost == [KeyboardInterrupt], f"the interrupt was not lost ({lost}): the test tests nothing"
    assert rc == 130 and len(calls) == 2, (rc, len(calls))
    assert "run the same command again to resume" in err
    assert _finished(tmp_path / "out") >= 1


# ------------------------------------------------------------------------------------------------ dask
def test_dask_cluster_gives_the_same_table(small_run, tmp_path):
    distributed = pytest.importorskip("distributed")
    path, out = small_run
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None) as cluster:
        summary = run_experiment(load_experiment(str(path)), tmp_path / "dask", cluster=cluster.scheduler_address,
                                 quiet=True)
    assert summary.computed == 13 and summary.failed == 0
    same_table(table(out), table(tmp_path / "dask"))


# ------------------------------------------------------------------------------------------------ report
def test_report_has_both_error_against_time_figures(small_run, tmp_path):
    from gpusim.report.experiment import write_report
    from gpusim.report.figures import MAX_PNG_BYTES
    _, out = small_run
    index = write_report(out, tmp_path / "report")
    text = index.read_text()
    for heading in ("## Error against run time", "### Image error against simulated cycles",
                    "### The simulator's own fidelity", "## Footprint by structure",
                    "## Accesses by structure and operation", "## Cycles and where they go", "## RMW hazards",
                    "## Images", "## Skipped and failed runs"):
        assert heading in text, heading
    figs = sorted(p.name for p in (tmp_path / "report" / "figures").glob("*.png"))
    assert any(n.startswith("error-vs-cycles") for n in figs) and "fidelity-vs-wall.png" in figs
    for name in figs:
        assert f"(figures/{name})" in text
        assert (tmp_path / "report" / "figures" / name).stat().st_size < MAX_PNG_BYTES
    assert "(full level)" in text or "full level" in text


def test_report_command_on_a_directory_without_results(tmp_path, capsys):
    assert main(["report", str(tmp_path)]) == 2
    assert "no results.parquet here" in capsys.readouterr().err


def test_core_does_not_import_matplotlib():
    code = ("import sys, gpusim, gpusim.experiment, gpusim.hw, gpusim.schemes, gpusim.replay, gpusim.metrics, "
            "gpusim.experiment.runner, gpusim.experiment.executors; "
            "assert 'matplotlib' not in sys.modules, sorted(m for m in sys.modules if 'matplotlib' in m)")
    subprocess.run([sys.executable, "-c", code], check=True, cwd=ROOT)


def test_committed_quick_start_report_is_complete_and_small():
    report = ROOT / "reports" / "quick-start"
    text = (report / "index.md").read_text()
    assert "![image error against cycles" in text and "![cycle error against wall time]" in text
    for png in (report / "figures").glob("*.png"):
        assert png.stat().st_size < 200_000, png
    t = pd.read_parquet(report / "results.parquet")
    assert set(t["fidelity"]) >= {"analytic", "sampled", "full"} and (t["status"] != "failed").all()
    exp = load_experiment("quick-start")
    assert len(t) == len(expand(exp))
    with pytest.raises(ConfigError):
        load_experiment("no-such-experiment")


def test_a_scheme_twice_under_labels_and_scene_set_axes(tmp_path):
    path = write(tmp_path / "e.toml", 'scenes = ["default"]\nsize = "24x20"\nfidelity = ["none"]\n'
                                      '[scene-set]\n"screen.background" = [[1.0, 1.0, 1.0], [0.0, 0.0, 0.0]]\n'
                                      '[schemes.kbuffer]\nk = 2\n'
                                      '[schemes.kb-blender]\nscheme = "kbuffer"\nhw = "blender"\n')
    runs = expand(load_experiment(str(path)))
    assert [(r.label, r.scheme) for r in runs[:2]] == [("kbuffer", "kbuffer"), ("kb-blender", "kbuffer")]
    assert len(runs) == 4 and runs[2].source.scene_set == (("screen.background", (0.0, 0.0, 0.0)),)
    run_experiment(load_experiment(str(path)), tmp_path / "out", workers=1, quiet=True)
    t = table(tmp_path / "out")
    assert list(t["variant"]) == ["kbuffer", "kb-blender"] * 2 and list(t["hw"][:2]) == ["texture-rmw", "blender"]
    assert t["scene.screen.background"].nunique() == 2 and t["run"].is_unique
    with pytest.raises(ConfigError, match="schemes.kb: unknown scheme 'kbuf'"):
        load_experiment(str(write(tmp_path / "b.toml", 'scenes = ["default"]\n[schemes.kb]\nscheme = "kbuf"\n')))


def test_a_malformed_trace_fails_in_one_line_before_any_output(tmp_path, capsys):
    (tmp_path / "bad.npz").write_bytes(b"PK\x03\x04 not really a zip")
    path = write(tmp_path / "e.toml", 'scenes = ["default"]\nsize = "16x16"\ntraces = ["bad.npz"]\n'
                                      'fidelity = ["none"]\n[schemes.alpha-blend]\n')
    out = tmp_path / "out"
    assert main(["run", str(path), "-o", str(out), "--quiet"]) == 2
    err = capsys.readouterr().err
    assert "bad.npz" in err and len(err.strip().splitlines()) == 1
    assert not out.exists()


def test_report_of_a_functional_only_sweep(tmp_path):
    from gpusim.report.experiment import write_report
    path = write(tmp_path / "e.toml", 'scenes = ["default"]\nsize = "24x20"\nfidelity = ["none"]\n'
                                      '[schemes.lucidraster]\ndepth_filter = [1, 3]\n')
    run_experiment(load_experiment(str(path)), tmp_path / "out", workers=1, quiet=True)
    text = write_report(tmp_path / "out").read_text()
    assert "No run has simulated cycles" in text and "No timed run." in text
    assert "## Scheme statistics" in text and "invalid_pixels" in text


def test_whole_numbers_stay_whole_and_resolved_toml_runs_again(tmp_path, monkeypatch):
    shutil.copy(ROOT / "configs" / "scenes" / "default.toml", tmp_path / "myscene.toml")
    path = write(tmp_path / "e.toml", 'scenes = ["myscene.toml"]\nsize = "24x20"\nfidelity = ["none", "analytic"]\n'
                                      '[schemes.alpha-blend]\n[schemes.kbuffer]\nk = [2, 4]\n')
    out = tmp_path / "out"
    run_experiment(load_experiment(str(path)), out, workers=1, quiet=True)
    t = table(out)
    assert str(t["k"].dtype) == "Int64" and str(t["cycles"].dtype) == "Int64"
    written = pd.read_csv(out / "results.csv", dtype=str)           # as the CSV spells them: 4, not 4.0
    assert written["k"].dropna().tolist() == ["2", "2", "4", "4"] and not written["cycles"].str.contains(r"\.").any()
    monkeypatch.chdir(out)                                        # relative paths were made absolute
    again = load_experiment("resolved.toml")
    assert len(expand(again)) == len(t)


def test_report_images_use_each_traces_own_reference(tmp_path):
    from gpusim.report.experiment import write_report
    path = write(tmp_path / "e.toml", 'scenes = ["default"]\nsize = "24x20"\nfidelity = ["none"]\n'
                                      '[scene-set]\n"screen.background" = [[1.0, 1.0, 1.0], [0.0, 0.0, 0.0]]\n'
                                      '[schemes.alpha-blend]\n')
    run_experiment(load_experiment(str(path)), tmp_path / "out", workers=1, quiet=True)
    text = write_report(tmp_path / "out").read_text()
    images = sorted(p.name for p in (tmp_path / "out" / "figures").glob("images-*.png"))
    assert len(images) == 2 and text.count("![images of default screen.background=") == 2


def test_a_sweep_in_one_process_leaves_no_event_model_behind(tmp_path):
    """The event model's objects form reference cycles; each run's are collected before the next run, so a
    long sweep in one process (or one worker) holds one run's memory, not the sum of all of them."""
    import gc

    import simpy
    path = write(tmp_path / "e.toml", 'scenes = ["default"]\nsize = "24x20"\nfidelity = ["full"]\n'
                                      '[schemes.depth-peeling]\n[schemes.kbuffer]\nk = 2\n')
    gc.disable()                 # only the sweep's own collections count
    try:
        run_experiment(load_experiment(str(path)), tmp_path / "out", workers=1, quiet=True)
        # type(), not isinstance: a dead weak proxy among the objects (numba makes some) raises on isinstance
        alive = [o for o in gc.get_objects() if issubclass(type(o), simpy.Environment)]
    finally:
        gc.enable()
    assert not alive
