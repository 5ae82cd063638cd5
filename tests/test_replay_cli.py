"""``gpusim replay`` and ``gpusim schemes``: JSON, outputs, one-line errors."""

from __future__ import annotations

import json

import numpy as np
import pytest
from conftest import make_trace

from gpusim.cli import main
from gpusim.trace_io import save_trace


@pytest.fixture
def trace_file(tmp_path, random_trace):
    path = tmp_path / "t.npz"
    save_trace(random_trace, path)
    return path


def test_replay_json_has_the_documented_keys(trace_file, capsys):
    assert main(["replay", str(trace_file), "--scheme", "freepipe-abuffer", "--param", "layers=8", "--json"]) == 0
    rec = json.loads(capsys.readouterr().out)
    for key in ("scheme", "params", "fragments", "pixels", "geometry_passes", "footprint_bytes", "accesses",
                "dropped_fragments", "error", "wall_seconds"):
        assert key in rec
    assert rec["params"]["layers"] == 8
    assert rec["footprint_bytes"]["total"] == sum(v for k, v in rec["footprint_bytes"].items() if k != "total")
    assert set(rec["error"]) >= {"rmse", "psnr", "differing_pixels"}
    assert rec["accesses"]["counter"]["atomic_inc"] == rec["fragments"] == 5000


def test_replay_writes_image_difference_and_stats(trace_file, tmp_path, capsys):
    out = tmp_path / "out"
    assert main(["replay", str(trace_file), "--scheme", "wboit", "-o", str(out)]) == 0
    text = capsys.readouterr().out
    assert "footprint" in text and "error" in text
    assert (out / "image.png").stat().st_size > 0 and (out / "difference.png").stat().st_size > 0
    assert json.loads((out / "stats.json").read_text())["scheme"] == "wboit"


@pytest.mark.parametrize("args, message", [
    (["--scheme", "abuffer"], "unknown scheme (valid: adaptive-bucket-depth-peeling, alpha-blend"),
    (["--scheme", "kbuffer", "--param", "kk=3"], "kk: unknown key (valid: k, mode"),
    (["--scheme", "kbuffer", "--param", "k=0"], "k: must be >= 1"),
    (["--scheme", "kbuffer", "--param", "k"], "--param k: expected NAME=VALUE, e.g. --param k=8"),
    (["--scheme", "kbuffer", "--param", "a.b=1"], "have no dots"),
    (["--scheme", "kbuffer", "--gpu-set", "core.sms=4"], "--gpu-set/--gpu need --fidelity LEVEL"),
    (["--scheme", "kbuffer", "--gpu", "modern"], "--gpu-set/--gpu need --fidelity LEVEL"),
    (["--scheme", "kbuffer", "--fidelity", "full", "--gpu-set", "core.smss=4"],
     "error: --gpu-set core.smss=4: core.smss: unknown key (valid: sms, warp_size"),
    (["--scheme", "kbuffer", "--fidelity", "analytic", "--gpu-set", "core.warp_size=33"],
     "--gpu-set core.warp_size=33: core.warp_size: must be a power of two"),
])
def test_replay_bad_input_is_one_line_and_leaves_no_output(trace_file, tmp_path, capsys, args, message):
    out = tmp_path / "never"
    assert main(["replay", str(trace_file), *args, "-o", str(out)]) == 2
    err = capsys.readouterr().err.strip()
    assert message in err and "\n" not in err
    assert not out.exists()


def test_replay_rejects_a_packing_run_it_cannot_do(tmp_path, capsys):
    t = make_trace([0, 1], [0, 0], [0.2, 0.3], rgba=[[1, 0, 0, 0.3], [0, 1, 0, 0.6]])
    save_trace(t, tmp_path / "a.npz")
    assert main(["replay", str(tmp_path / "a.npz"), "--scheme", "freepipe-mdts", "--param", "packing=true"]) == 2
    assert "--param alpha=" in capsys.readouterr().err


def test_schemes_lists_parameters_with_units(capsys):
    assert main(["schemes", "freepipe-mdts"]) == 0
    out = capsys.readouterr().out
    assert "layers = 20 [entries/pixel]  int: " in out and "packing = False  bool: " in out
    assert "alpha = None [1]  float | None: " in out and "direction = 'min'  'min' | 'max': " in out
    assert "<class" not in out and "typing." not in out
    assert main(["schemes", "--json"]) == 0
    table = json.loads(capsys.readouterr().out)
    assert "kbuffer" in table and table["kbuffer"]["params"][0]["name"] == "k"
    assert main(["schemes", "nope"]) == 2


def test_replay_is_deterministic(trace_file, capsys):
    runs = []
    for _ in range(2):
        main(["replay", str(trace_file), "--scheme", "linked-list", "--json"])
        rec = json.loads(capsys.readouterr().out)
        rec.pop("wall_seconds")
        runs.append(rec)
    assert runs[0] == runs[1]
    assert np.isfinite(runs[0]["error"]["rmse"])


def test_output_piped_into_a_closed_reader_exits_quietly():
    import subprocess
    import sys

    proc = subprocess.Popen([sys.executable, "-m", "gpusim", "schemes"], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE)
    proc.stdout.read(10)
    proc.stdout.close()                      # like '| head -c 10'
    err = proc.stderr.read().decode()
    proc.wait(timeout=60)
    assert "Traceback" not in err


def test_replay_thesis_fidelity_reports_cycles(trace_file, capsys):
    assert main(["replay", str(trace_file), "--scheme", "tfss", "--fidelity", "thesis", "--json"]) == 0
    timing = json.loads(capsys.readouterr().out)["timing"]
    assert timing["fidelity"] == "thesis" and timing["cycles"] == timing["memory_cycles"] + timing["compute_cycles"]
    assert main(["replay", str(trace_file), "--scheme", "r-buffer", "--fidelity", "thesis"]) == 0
    assert "cycles" in capsys.readouterr().out
    assert main(["replay", str(trace_file), "--scheme", "kbuffer", "--fidelity", "thesis"]) == 2
    err = capsys.readouterr().err
    assert "models only r-buffer, tfss, weight-factor" in err and len(err.strip().splitlines()) == 1


def test_text_output_formats_table_stats(trace_file, tmp_path, capsys):
    out = tmp_path / "out"
    assert main(["replay", str(trace_file), "--scheme", "lucidraster", "-o", str(out)]) == 0
    text = capsys.readouterr().out
    assert "stat         bins = empty=" in text and "promoted=" in text
    assert json.loads((out / "stats.json").read_text())["stats"]["bins"]["value"]["empty"] >= 0


def test_outputs_appear_together_or_not_at_all(trace_file, tmp_path, capsys, monkeypatch):
    import gpusim.report.images as images

    def full_disk(*args, **kwargs):
        raise OSError(28, "No space left on device")
    monkeypatch.setattr(images, "save_heatmap_png", full_disk)       # difference.png, after image.png
    out = tmp_path / "out"
    assert main(["replay", str(trace_file), "--scheme", "wboit", "-o", str(out)]) == 2
    assert capsys.readouterr().out == "" and not out.exists() and list(tmp_path.iterdir()) == [trace_file]


@pytest.mark.parametrize("output, message", [
    ("{tmp}/file/out", "file is a file, so nothing can be written under it"),
    ("{tmp}/file", "that is a file, not a folder"),
    ("/proc/gpusim-out", "cannot write in /proc"),
])
def test_unwritable_output_fails_before_the_run(trace_file, tmp_path, capsys, monkeypatch, output, message):
    import gpusim.cli.replay_cmd as replay_cmd

    (tmp_path / "file").write_text("keep")
    monkeypatch.setattr(replay_cmd, "replay", lambda *a: pytest.fail("ran before checking -o"))
    output = output.replace("{tmp}", str(tmp_path))
    assert main(["replay", str(trace_file), "--scheme", "wboit", "-o", output]) == 2
    err = capsys.readouterr().err
    assert err.startswith(f"gpusim: error: -o {output}: ") and message in err and err.count("\n") == 1
    assert sorted(p.name for p in tmp_path.iterdir()) == ["file", "t.npz"]
    assert (tmp_path / "file").read_text() == "keep"
