"""The command line as a user meets it: outputs, exit codes, one-line errors, no partial files."""

from __future__ import annotations

import json
import subprocess
import sys

import numpy as np
import pytest

from gpusim.cli import main
from gpusim.trace_io import load_trace


def run(capsys, *argv):
    code = main(list(argv))
    out, err = capsys.readouterr()
    return code, out, err


def test_trace_info_show_pipeline(tmp_path, capsys):
    out = tmp_path / "d.npz"
    code, text, _ = run(capsys, "trace", "default", "-o", str(out), "--size", "96x64", "--no-progress")
    assert code == 0 and "fragments" in text
    t = load_trace(out)
    assert (t.width, t.height) == (96, 64) and t.meta["scene"] == "default"
    code, text, _ = run(capsys, "info", str(out), "--json")
    info = json.loads(text)
    assert code == 0 and info["fragments"] == len(t)
    assert info["depth_complexity"]["max"] == int(t.depth_complexity().max())
    assert sum(info["depth_complexity"]["histogram"].values()) == info["covered_pixels"]
    # primitives with fragments, and those the scene submitted (the rest fell between pixel centres or off screen)
    assert info["primitives"] == len(np.unique(t.prim)) and info["primitives_submitted"] == t.meta["primitives"]
    assert info["primitives_submitted"] > info["primitives"]
    code, text, _ = run(capsys, "info", str(out))
    assert code == 0 and "depth        max" in text
    missing = info["primitives_submitted"] - info["primitives"]
    assert f"primitives   {info['primitives_submitted']:,} submitted; {missing:,} made no fragment" in text
    code, _, _ = run(capsys, "show", str(out), "-o", str(tmp_path / "png"))
    assert code == 0
    from matplotlib import image as mpimg
    ref = mpimg.imread(tmp_path / "png" / "reference.png")
    assert ref.shape[:2] == (64, 96)
    assert (tmp_path / "png" / "depth_complexity.png").stat().st_size > 1000


def test_csv_import_through_cli(tmp_path, capsys):
    csv = tmp_path / "f.csv"
    csv.write_text("x,y,z,r,g,b,a\n0,0,0.5,1,0,0,0.5\n1,1,0.2,0,1,0,1\n")
    code, _, _ = run(capsys, "trace", "--from-csv", str(csv), "--size", "4x4", "-o", str(tmp_path / "c.npz"))
    assert code == 0 and len(load_trace(tmp_path / "c.npz")) == 2
    code, text, _ = run(capsys, "info", str(tmp_path / "c.npz"), "--json")
    assert code == 0 and json.loads(text)["primitives_submitted"] is None     # a CSV does not say
    code, text, _ = run(capsys, "info", str(tmp_path / "c.npz"))
    assert code == 0 and "submitted" not in text


@pytest.mark.parametrize("argv, expect", [
    (["trace", "nope-scene", "-o", "{tmp}/o.npz"], "unknown scene 'nope-scene'"),
    (["trace", "default", "-o", "{tmp}/o.png"], "must end in .npz"),
    (["trace", "default", "--size", "12", "-o", "{tmp}/o.npz"], "expected WIDTHxHEIGHT"),
    (["trace", "default", "--size", "0x5", "-o", "{tmp}/o.npz"], "each side must lie in"),
    (["trace", "default", "--set", "camera.zoom=3", "-o", "{tmp}/o.npz"], "camera.zoom: unknown key"),
    (["trace", "default", "--set", "camera.fovy=60", "-o", "{tmp}/o.npz"],
     "error: --set camera.fovy=60: camera.fovy: unknown key (valid: eye, target"),
    (["trace", "thesis-frame60", "--size", "8x8", "-o", "{tmp}/o.npz"], "error: --size 8x8: "),
    (["trace", "default", "-o", "{tmp}/bad.csv/o.npz"], "bad.csv is a file, so nothing can be written under it"),
    (["trace", "default", "-o", "/proc/o.npz"], "cannot write in /proc"),
    (["trace", "--from-csv", "{tmp}/neg.csv", "--size", "4x4", "-o", "{tmp}/o.npz"],
     "neg.csv:2: x=-1 puts the pixel outside the screen: coordinates must be 0 <= x < 4 (the screen width)"),
    (["trace", "default", "--alpha", "0.5", "-o", "{tmp}/o.npz"], "--alpha applies to mesh files only"),
    (["trace", "--from-csv", "{tmp}/bad.csv", "-o", "{tmp}/o.npz"], "needs the screen size"),
    (["trace", "--from-csv", "{tmp}/bad.csv", "--size", "4x4", "-o", "{tmp}/o.npz"], "bad.csv:2: column 'z' is empty or NaN"),
    (["info", "{tmp}/missing.npz"], "no such trace file"),
    (["show", "{tmp}/bad.csv", "-o", "{tmp}/png"], "not a gpusim trace (.npz) file"),
])
def test_bad_input_is_one_line_nonzero_and_leaves_no_output(tmp_path, capsys, argv, expect):
    (tmp_path / "bad.csv").write_text("x,y,z,r,g,b,a\n0,0,,1,1,1,1\n")
    (tmp_path / "neg.csv").write_text("x,y,z,r,g,b,a\n-1,0,0.5,1,1,1,1\n")
    argv = [a.replace("{tmp}", str(tmp_path)) for a in argv]
    code, out, err = run(capsys, *argv)
    assert code == 2 and expect in err
    assert err.count("\n") == 1 and err.startswith("gpusim: error:")
    assert not (tmp_path / "o.npz").exists() and not (tmp_path / "png").exists()


def test_usage_errors_are_one_line():
    proc = subprocess.run([sys.executable, "-m", "gpusim", "trace"], capture_output=True, text=True)
    assert proc.returncode == 2
    assert proc.stderr.strip().count("\n") == 0 and "required: -o/--output" in proc.stderr
    assert "Traceback" not in proc.stderr


def test_console_script_runs_and_nan_depth_csv_is_rejected(tmp_path):
    csv = tmp_path / "n.csv"
    csv.write_text("x,y,z,r,g,b,a\n0,0,0.5,1,0,0,0.5\n0,0,nan,1,0,0,0.5\n")
    proc = subprocess.run([sys.executable, "-m", "gpusim", "trace", "--from-csv", str(csv), "--size", "2x2",
                           "-o", str(tmp_path / "n.npz")], capture_output=True, text=True)
    assert proc.returncode == 2 and "n.csv:3: column 'z' is empty or NaN" in proc.stderr
    assert "Traceback" not in proc.stderr and not (tmp_path / "n.npz").exists()


def test_existing_output_survives_a_failed_run(tmp_path, capsys):
    out = tmp_path / "keep.npz"
    run(capsys, "trace", "coplanar", "-o", str(out), "--no-progress")
    before, trace = out.read_bytes(), load_trace(out)
    code, _, _ = run(capsys, "trace", "coplanar", "--set", "objects.0.alpha=7", "-o", str(out))
    assert code == 2 and out.read_bytes() == before
    after = load_trace(out)                            # still the first run's trace, and it loads
    assert len(after) == len(trace) > 0
    for column in ("x", "y", "z", "rgba", "prim", "opaque"):
        np.testing.assert_array_equal(getattr(after, column), getattr(trace, column))


def test_sigterm_during_trace_leaves_no_partial_file(tmp_path):
    # SIGTERM while the output is being written (its hidden temporary file exists): before, the process died at
    # once and left the temporary file (hundreds of MB) beside the output
    import signal
    import time
    out = tmp_path / "big.npz"
    proc = subprocess.Popen([sys.executable, "-m", "gpusim", "trace", "foliage", "--size", "1200x1200", "-o", str(out),
                             "--no-progress"], stderr=subprocess.PIPE, text=True)
    deadline = time.monotonic() + 120
    while not list(tmp_path.glob(".big.npz.*")) and proc.poll() is None and time.monotonic() < deadline:
        time.sleep(0.02)
    proc.send_signal(signal.SIGTERM)
    _, err = proc.communicate(timeout=60)
    assert proc.returncode == 130 and "interrupted" in err and "Traceback" not in err
    assert list(tmp_path.iterdir()) == []             # neither the output nor a hidden temporary file
