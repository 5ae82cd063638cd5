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
    (["info", "{tmp}"], "is a directory, not a trace file; name the file"),
    (["info", "/dev/zero"], "/dev/zero: is a device, not a regular file"),
    (["trace", "{tmp}/bad.csv", "-o", "{tmp}/o.npz"],
     "bad.csv: a CSV fragment list is not a scene; import it with --from-csv: gpusim trace --from-csv"),
    (["replay", "{tmp}/bad.csv", "--scheme", "alpha-blend", "--fidelity", "analytic", "--gpu", "{tmp}"],
     "is a directory, not a GPU file; give a GPU .toml file or a preset (geforce7900gtx, gtx280"),
    (["replay", "{tmp}/bad.csv", "--scheme", "alpha-blend", "--fidelity", "analytic", "--gpu", "/dev/zero"],
     "--gpu /dev/zero: not a regular file"),
    (["replay", "{tmp}/bad.csv", "--scheme", "alpha-blend", "--fidelity", "analytic", "--gpu", "{tmp}/nope"],
     "no such GPU file; check the path"),
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


def test_a_fifo_given_as_a_trace_is_refused_without_blocking(tmp_path, capsys):
    import os
    os.mkfifo(tmp_path / "t.npz")                     # opening it would wait for a writer for ever
    code, out, err = run(capsys, "info", str(tmp_path / "t.npz"))
    assert code == 2 and out == "" and err.count("\n") == 1
    assert "t.npz: is a FIFO (named pipe), not a regular file" in err


def test_one_of_a_thing_is_singular(tmp_path, capsys):
    """1 fragment on 1 pixel, not "1 fragments on 1 pixels"."""
    csv = tmp_path / "one.csv"
    csv.write_text("x,y,z,r,g,b,a\n0,0,0.5,1,0,0,0.5\n")
    trace = tmp_path / "one.npz"
    code, text, err = run(capsys, "trace", "--from-csv", str(csv), "--size", "2x2", "-o", str(trace))
    assert code == 0 and ": 1 fragment, 1 covered pixel, " in text, err
    code, text, err = run(capsys, "info", str(trace))
    assert code == 0 and "1 from 1 primitive\n" in text and "covered      1 pixel (" in text, err
    code, text, err = run(capsys, "replay", str(trace), "--scheme", "alpha-blend", "--fidelity", "analytic")
    assert code == 0 and "1 fragment on 1 pixel\n" in text and "0 fragments (0 pixels lost some)" in text, err
    for plural in ("1 fragments", "1 pixels", "1 primitives", "1 replicates", "1 requests"):
        assert plural not in text


def test_an_empty_param_value_is_said_to_be_empty(tmp_path, capsys):
    csv = tmp_path / "one.csv"
    csv.write_text("x,y,z,r,g,b,a\n0,0,0.5,1,0,0,0.5\n")
    trace = tmp_path / "one.npz"
    assert run(capsys, "trace", "--from-csv", str(csv), "--size", "2x2", "-o", str(trace))[0] == 0
    code, out, err = run(capsys, "replay", str(trace), "--scheme", "kbuffer", "--param", "k=")
    assert code == 2 and out == "" and err.count("\n") == 1
    assert "k: expected an integer, got an empty value (give one after the '=')" in err and "''" not in err


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


# the child: its first output waits, written but not yet moved into place, until the test signals it
PAUSED_CHILD = """
import contextlib, pathlib, sys, time
import gpusim.atomic_io as aio
real, marker = aio.atomic_output, pathlib.Path(sys.argv[1])

@contextlib.contextmanager
def paused(path, mode="wb"):
    with real(path, mode) as handle:
        yield handle
        if not marker.exists():
            marker.touch()
            time.sleep(120)

aio.atomic_output = paused
from gpusim.cli import main
sys.exit(main(sys.argv[2:]))
"""


@pytest.mark.parametrize("command", ["trace", "replay", "show", "run", "report"])
def test_sigterm_while_an_output_is_written_leaves_no_partial_file(tmp_path, capsys, command):
    # SIGTERM while a temporary file is open beside the output: before, the process died at once and left it
    # (618 MB for a 2048x2048 trace); now every command removes it and exits with 130 and one line
    import signal
    import time
    work = tmp_path / "work"
    work.mkdir()
    trace = work / "t.npz"
    results = work / "results"
    if command in ("replay", "show", "report"):
        assert main(["trace", "default", "--size", "16x16", "-o", str(trace), "--no-progress"]) == 0
    if command in ("run", "report"):
        (work / "e.toml").write_text('scenes = ["default"]\nsize = "8x8"\nfidelity = ["none"]\n'
                                     "[schemes.alpha-blend]\n")
    if command == "report":
        assert main(["run", str(work / "e.toml"), "-o", str(results), "--workers", "1", "--quiet"]) == 0
    capsys.readouterr()
    before = {p: p.read_bytes() for p in work.rglob("*") if p.is_file()}
    out = work / "out"
    argv = {"trace": ["trace", "default", "--size", "16x16", "-o", f"{out}.npz", "--no-progress"],
            "replay": ["replay", str(trace), "--scheme", "kbuffer", "-o", str(out)],
            "show": ["show", str(trace), "-o", str(out)],
            "run": ["run", str(work / "e.toml"), "-o", str(out), "--workers", "1", "--quiet"],
            "report": ["report", str(results)]}[command]
    marker = tmp_path / "writing"
    proc = subprocess.Popen([sys.executable, "-c", PAUSED_CHILD, str(marker), *argv], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True)
    deadline = time.monotonic() + 120
    while not marker.exists() and proc.poll() is None and time.monotonic() < deadline:
        time.sleep(0.01)
    assert proc.poll() is None, f"the command ended before it wrote an output: {proc.communicate()}"
    assert [p for p in work.rglob(".*") if ".tmp" in p.name], "no temporary output while writing"
    proc.send_signal(signal.SIGTERM)
    _, err = proc.communicate(timeout=60)
    assert proc.returncode == 130 and err.count("\n") == 1 and err.startswith("gpusim: interrupted; "), err
    assert not [p for p in work.rglob(".*")], "a hidden temporary file or folder was left"
    after = {p: p.read_bytes() for p in work.rglob("*") if p.is_file()}
    if command == "run":                 # the finished parts stay for the resume; nothing else changed
        assert {p: b for p, b in after.items() if out not in p.parents} == before
        assert "run the same command again to resume" in err
    else:                                # no output at all, and the old report is whole
        assert after == before and not out.exists() and not out.with_suffix(".npz").exists()


def _stderr_on_a_terminal(argv, columns=120):
    """Run ``gpusim ARGV`` with stderr on a pseudo-terminal of ``columns``; returns (exit status, stderr)."""
    import fcntl
    import os
    import pty
    import struct
    import termios
    master, slave = pty.openpty()
    fcntl.ioctl(slave, termios.TIOCSWINSZ, struct.pack("HHHH", 40, columns, 0, 0))
    proc = subprocess.Popen([sys.executable, "-m", "gpusim", *argv], stdout=subprocess.DEVNULL, stderr=slave)
    os.close(slave)
    chunks = []
    while True:
        try:
            chunk = os.read(master, 65536)
        except OSError:                     # EIO: the child closed the terminal
            break
        if not chunk:
            break
        chunks.append(chunk)
    os.close(master)
    return proc.wait(timeout=120), b"".join(chunks).decode(errors="replace")


def test_long_work_shows_a_progress_bar_on_a_terminal_only(tmp_path, capsys):
    trace = tmp_path / "t.npz"
    code, err = _stderr_on_a_terminal(["trace", "default", "--size", "48x48", "-o", str(trace)])
    assert code == 0 and "rasterize:" in err and "frag/s" in err, err
    code, err = _stderr_on_a_terminal(["trace", "default", "--size", "48x48", "-o", str(trace), "--no-progress"])
    assert code == 0 and err == "", err
    code, err = _stderr_on_a_terminal(["replay", str(trace), "--scheme", "depth-peeling", "--fidelity", "full"])
    assert code == 0 and "full level" in err and "warp" in err, err
    code, _, err = run(capsys, "trace", "default", "--size", "48x48", "-o", str(trace))
    assert code == 0 and err == ""                                # not a terminal: no bar
