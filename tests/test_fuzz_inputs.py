"""Fuzz every command with truncated, corrupted and hostile inputs.

The rule under test: bad input gets ONE line of error naming the problem (``gpusim: error: ...``), exit
status 2, no traceback, no hang, nothing on stdout and no output file or folder where ``-o`` pointed.

The commands run in this process through :func:`gpusim.cli.main`; the few inputs that ask for more memory
than a machine holds run in a child process under an address-space limit and a timeout, so a regression
fails the test instead of exhausting the machine. Corruptions are deterministic (fixed offsets, seeded
numpy generators), so a failure always reproduces.
"""

from __future__ import annotations

import io
import os
import resource
import struct
import subprocess
import sys
import zipfile
from pathlib import Path

import numpy as np
import pytest

from gpusim.cli import main

# --------------------------------------------------------------------------------------------- helpers


def assert_rejected(code, out: str, err: str, output: Path | None = None, status: int = 2) -> None:
    """The project rule for bad input: ``status``, one line on stderr, no traceback, nothing at ``output``."""
    assert code == status, f"exit {code}, expected {status}; stderr: {err!r}"
    assert "Traceback" not in err and "Traceback" not in out
    lines = err.strip("\n").split("\n")
    assert len(lines) == 1 and err.endswith("\n"), f"expected one error line, got: {err!r}"
    assert lines[0].startswith("gpusim: error: "), lines[0]
    assert out == "", f"stdout should be empty on bad input, got: {out[:200]!r}"
    if output is not None:
        assert not output.exists(), f"{output} was left behind"
        leftovers = [p.name for p in output.parent.iterdir() if p.name.startswith(f".{output.name}.")]
        assert not leftovers, f"temporary outputs left behind: {leftovers}"


def run_cli(capsys, argv: list[str]) -> tuple[int, str, str]:
    code = main([str(a) for a in argv])
    out, err = capsys.readouterr()
    return code, out, err


MEMORY_LIMIT = 4 << 30     # bytes of address space a child gets: a runaway allocation fails, the machine lives


def _limit_memory() -> None:
    resource.setrlimit(resource.RLIMIT_AS, (MEMORY_LIMIT, MEMORY_LIMIT))


def run_child(argv: list[str], cwd: Path, timeout: float = 45) -> tuple[int, str, str]:
    """``gpusim ARGV`` in a child process with at most MEMORY_LIMIT bytes of address space."""
    env = dict(os.environ, OMP_NUM_THREADS="1", OPENBLAS_NUM_THREADS="1", MKL_NUM_THREADS="1",
               PYTHONWARNINGS="ignore")
    proc = subprocess.run([sys.executable, "-m", "gpusim", *map(str, argv)], cwd=cwd, env=env,
                          capture_output=True, text=True, timeout=timeout, preexec_fn=_limit_memory)
    return proc.returncode, proc.stdout, proc.stderr


def cases(table: dict) -> list:
    """The keys of ``table`` as parameters."""
    return list(table)


@pytest.fixture(scope="module")
def valid_trace(tmp_path_factory) -> Path:
    """One small valid trace, made once by the CLI; every corrupt trace starts as a copy of it."""
    path = tmp_path_factory.mktemp("valid") / "t.npz"
    assert main(["trace", "default", "--size", "32x32", "-o", str(path), "--no-progress"]) == 0
    return path


# ------------------------------------------------------------------------------- trace (.npz) inputs


def _members(path: Path) -> dict[str, np.ndarray]:
    with np.load(path, allow_pickle=False) as npz:
        return {name: npz[name] for name in npz.files}


def _savez(dest: Path, arrays: dict) -> None:
    with open(dest, "wb") as handle:             # a handle: np.savez would append .npz to a path
        np.savez(handle, **arrays)


def _raw_npz(dest: Path, members: dict[str, bytes], compression: int = zipfile.ZIP_STORED) -> None:
    """A zip of raw ``.npy`` members (for headers np.savez would never write)."""
    with zipfile.ZipFile(dest, "w", compression) as z:
        for name, raw in members.items():
            z.writestr(f"{name}.npy", raw)


def _npy_bytes(array: np.ndarray) -> bytes:
    buf = io.BytesIO()
    np.save(buf, array)
    return buf.getvalue()


def _npy_header(text: str) -> bytes:
    """A version 1.0 ``.npy`` header holding ``text`` (padded like numpy pads it)."""
    text = text + " " * (63 - (len(text) + 10) % 64) + "\n"
    return b"\x93NUMPY\x01\x00" + struct.pack("<H", len(text)) + text.encode("latin-1")


def _columns(change):
    """A case: the valid trace's members changed by ``change(members)`` and saved with np.savez."""
    def make(valid: Path, dest: Path) -> None:
        members = _members(valid)
        change(members)
        _savez(dest, members)
    return make


def _set(**values):
    return _columns(lambda m: m.update({k: v(m) if callable(v) else v for k, v in values.items()}))


def _drop(name):
    return _columns(lambda m: m.pop(name))


def _truncated(fraction: float | None = None, keep: int | None = None, cut: int | None = None):
    def make(valid: Path, dest: Path) -> None:
        data = valid.read_bytes()
        n = keep if keep is not None else len(data) - cut if cut is not None else int(len(data) * fraction)
        dest.write_bytes(data[:n])
    return make


def _random_bytes(prefix: bytes = b"", size: int = 4096, seed: int = 0):
    def make(valid: Path, dest: Path) -> None:
        dest.write_bytes(prefix + np.random.default_rng(seed).bytes(size))
    return make


def _patched(edit):
    """A case: the valid trace's bytes changed in place by ``edit(bytearray, zip infos)``."""
    def make(valid: Path, dest: Path) -> None:
        data = bytearray(valid.read_bytes())
        with zipfile.ZipFile(valid) as z:
            infos = {i.filename: i for i in z.infolist()}
        edit(data, infos)
        dest.write_bytes(bytes(data))
    return make


def _data_offset(data: bytearray, info: zipfile.ZipInfo) -> int:
    name_len, extra_len = struct.unpack_from("<HH", data, info.header_offset + 26)
    return info.header_offset + 30 + name_len + extra_len


def _flip_array_byte(data, infos):             # a byte of x.npy's array data: the CRC no longer matches
    info = infos["x.npy"]
    data[_data_offset(data, info) + info.file_size - 3] ^= 0xFF


def _break_npy_header(data, infos):           # an unclosed '{' in z.npy's header dict
    start = _data_offset(data, infos["z.npy"]) + 10
    end = data.index(b"}", start)
    data[end] = ord(" ")


def _central_entries(data) -> list[int]:
    out, i = [], data.find(b"PK\x01\x02")
    while i >= 0:
        out.append(i)
        i = data.find(b"PK\x01\x02", i + 4)
    return out


def _unknown_compression(data, infos):       # compression method 99 (AES) in every header
    for offset in _central_entries(data):
        struct.pack_into("<H", data, offset + 10, 99)
    for info in infos.values():
        struct.pack_into("<H", data, info.header_offset + 8, 99)


def _encrypted(data, infos):                 # the "encrypted" flag bit on every member
    for offset in _central_entries(data):
        data[offset + 8] |= 1
    for info in infos.values():
        data[info.header_offset + 6] |= 1


def _declared_shape(name: str, shape: tuple, descr: str):
    """A case: member ``name`` claims ``shape`` in its header but holds 64 bytes."""
    def make(valid: Path, dest: Path) -> None:
        members = {k: _npy_bytes(v) for k, v in _members(valid).items()}
        members[name] = _npy_header(f"{{'descr': '{descr}', 'fortran_order': False, 'shape': {shape!r}, }}")
        members[name] += b"\0" * 64
        _raw_npz(dest, members)
    return make


def _with_meta(text: str):
    return _set(meta_json=np.str_(text))


GIANT = 10**9

NPZ_CASES = {
    # truncated at several offsets (inside the magic, a local header, a member, the central directory)
    "truncated-empty": _truncated(keep=0),
    "truncated-3-bytes": _truncated(keep=3),
    "truncated-after-magic": _truncated(keep=4),
    "truncated-in-first-header": _truncated(keep=40),
    "truncated-at-1k": _truncated(keep=1000),
    "truncated-at-10pct": _truncated(0.1),
    "truncated-at-half": _truncated(0.5),
    "truncated-at-90pct": _truncated(0.9),
    "truncated-in-end-record": _truncated(cut=10),
    "truncated-last-byte": _truncated(cut=1),
    # random and corrupted bytes
    "random-bytes": _random_bytes(),
    "random-after-zip-magic": _random_bytes(prefix=b"PK\x03\x04", seed=1),
    "csv-text-named-npz": lambda valid, dest: dest.write_text("x,y,z,r,g,b,a\n0,0,0.5,1,1,1,1\n"),
    "crc-mismatch": _patched(_flip_array_byte),
    "malformed-npy-header": _patched(_break_npy_header),
    "unknown-compression": _patched(_unknown_compression),
    "encrypted-members": _patched(_encrypted),
    # a valid npz whose columns are wrong
    "x-float32": _set(x=lambda m: m["x"].astype(np.float32)),
    "z-float64": _set(z=lambda m: m["z"].astype(np.float64)),
    "rgba-float16": _set(rgba=lambda m: m["rgba"].astype(np.float16)),
    "opaque-uint8": _set(opaque=lambda m: m["opaque"].astype(np.uint8)),
    "x-int16-negative": _set(x=lambda m: np.r_[np.int16(-1), m["x"][1:].astype(np.int16)]),
    "x-int64-negative": _set(x=lambda m: np.r_[-5, m["x"][1:].astype(np.int64)]),
    "x-object-array": _columns(lambda m: m.update(x=m["x"].astype(object))),
    "x-two-dimensional": _set(x=lambda m: m["x"].reshape(-1, 1)),
    "rgba-three-channels": _set(rgba=lambda m: m["rgba"][:, :3].copy()),
    "z-nan": _set(z=lambda m: np.r_[m["z"][:5], np.float32("nan"), m["z"][6:]].astype(np.float32)),
    "z-inf": _set(z=lambda m: np.r_[np.float32("inf"), m["z"][1:]].astype(np.float32)),
    "z-minus-inf": _set(z=lambda m: np.r_[m["z"][:-1], np.float32("-inf")].astype(np.float32)),
    "z-above-one": _set(z=lambda m: np.r_[m["z"][:-1], np.float32(1.5)].astype(np.float32)),
    "alpha-negative": _set(rgba=lambda m: np.r_[[[0.5, 0.5, 0.5, -0.25]], m["rgba"][1:]].astype(np.float32)),
    "x-at-width": _set(x=lambda m: np.r_[np.uint16(32), m["x"][1:]].astype(np.uint16)),
    "y-max-uint16": _set(y=lambda m: np.r_[m["y"][:-1], np.uint16(65535)].astype(np.uint16)),
    "y-shorter-than-x": _set(y=lambda m: m["y"][:-1]),
    "rgba-longer-than-x": _set(rgba=lambda m: np.r_[m["rgba"], m["rgba"][:1]]),
    "missing-prim": _drop("prim"),
    "missing-width": _drop("width"),
    "missing-meta": _drop("meta_json"),
    "only-one-member": _columns(lambda m: [m.pop(k) for k in list(m) if k != "x"]),
    # the screen
    "giant-screen": _set(width=np.int64(GIANT), height=np.int64(GIANT)),
    "giant-width": _set(width=np.int64(GIANT)),
    "max-int64-height": _set(height=np.int64(2**63 - 1)),
    "zero-width": _set(width=np.int64(0)),
    "negative-height": _set(height=np.int64(-32)),
    "fractional-width": _set(width=np.float64(32.5)),
    "width-vector": _set(width=np.array([32, 32])),
    "width-text": _set(width=np.str_("32")),
    # the format version and the metadata
    "version-from-the-future": _set(format_version=np.int64(99)),
    "version-zero": _set(format_version=np.int64(0)),
    "meta-not-json": _with_meta("{scene: default"),
    "meta-a-list": _with_meta("[1, 2, 3]"),
    "meta-nested-too-deep": _with_meta("[" * 100_000 + "]" * 100_000),
    "background-text": _with_meta('{"background": "white"}'),
    "background-table": _with_meta('{"background": {"r": 1}}'),
    "background-nan": _with_meta('{"background": [NaN, 0, 0]}'),
    "background-out-of-range": _with_meta('{"background": [5, -3, 0]}'),
    "background-two-channels": _with_meta('{"background": [1, 1]}'),
    # headers that declare more data than the file holds (or any machine)
    "x-declares-1e9-entries": _declared_shape("x", (GIANT,), "<u2"),
    "x-declares-1e12-entries": _declared_shape("x", (10**12,), "<u2"),
    "rgba-declares-1e9-by-1e9": _declared_shape("rgba", (GIANT, GIANT), "<f4"),
    "z-declares-2-to-62-entries": _declared_shape("z", (2**62,), "<f4"),
}

TRACE_COMMANDS = {
    "info": lambda trace, out: ["info", trace],
    "info-json": lambda trace, out: ["info", trace, "--json"],
    "replay": lambda trace, out: ["replay", trace, "--scheme", "alpha-blend", "-o", out],
    "show": lambda trace, out: ["show", trace, "-o", out],
}


@pytest.mark.parametrize("command", ["info", "replay", "show"])
@pytest.mark.parametrize("case", NPZ_CASES)
def test_corrupt_trace_is_rejected_in_one_line(valid_trace, tmp_path, capsys, case, command):
    bad = tmp_path / "bad.npz"
    NPZ_CASES[case](valid_trace, bad)
    out = tmp_path / "out"
    code, stdout, stderr = run_cli(capsys, TRACE_COMMANDS[command](bad, out))
    assert_rejected(code, stdout, stderr, out)
    assert str(bad) in stderr or "bad.npz" in stderr, "the error should name the file"


def test_the_valid_trace_passes_every_command(valid_trace, tmp_path, capsys):
    """The corruptions above are what fails, not the commands."""
    for name, argv in TRACE_COMMANDS.items():
        code, stdout, stderr = run_cli(capsys, argv(valid_trace, tmp_path / name))
        assert code == 0 and stdout, (name, stderr)


def test_a_one_pixel_wide_screen_draws(tmp_path, capsys):
    """A 1 x 16384 screen is valid: its heat maps must not ask matplotlib for a figure 10 million pixels tall."""
    from gpusim.trace import FragmentTrace
    from gpusim.trace_io import save_trace

    trace = save_trace(FragmentTrace.empty(1, 16384), tmp_path / "tall.npz")
    for argv in (["show", trace, "-o", tmp_path / "show"],
                 ["replay", trace, "--scheme", "alpha-blend", "-o", tmp_path / "replay"]):
        code, _, stderr = run_cli(capsys, argv)
        assert code == 0, stderr
    assert (tmp_path / "show" / "depth_complexity.png").is_file()
    assert (tmp_path / "replay" / "difference.png").is_file()


def test_show_leaves_no_half_output(valid_trace, tmp_path, capsys, monkeypatch):
    """show writes two images: when the second fails, the first must not be left alone."""
    from gpusim.report import images

    def full_disk(*args, **kwargs):
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(images, "save_heatmap_png", full_disk)
    out = tmp_path / "out"
    assert_rejected(*run_cli(capsys, ["show", valid_trace, "-o", out]), out)


def test_randomly_mutated_traces_never_crash(valid_trace, tmp_path, capsys):
    """600 seeded mutations (bytes overwritten in headers, data and the central directory, or the file cut):
    each either loads (a harmless byte, e.g. a timestamp) or fails in one line with exit 2."""
    data = valid_trace.read_bytes()
    with zipfile.ZipFile(valid_trace) as z:
        hot = sorted({0, len(data) - 22, *(i.header_offset for i in z.infolist()), *_central_entries(data)})
    rng = np.random.default_rng(20240601)
    bad = tmp_path / "m.npz"
    alphabet = np.frombuffer(b"{}()[]'\",:0123456789-+eLjx <>|u2f4\n\\", np.uint8)
    outcomes = {0: 0, 2: 0}
    for i in range(600):
        b = bytearray(data)
        kind = i % 4
        if kind == 0:                               # a few random bytes anywhere
            for _ in range(rng.integers(1, 8)):
                b[rng.integers(0, len(b))] = rng.integers(0, 256)
        elif kind == 1:                             # near a header (local, central, end record)
            base = hot[rng.integers(0, len(hot))]
            for _ in range(rng.integers(1, 4)):
                b[min(len(b) - 1, base + int(rng.integers(0, 140)))] = rng.integers(0, 256)
        elif kind == 2:                             # npy header text: plausible characters
            base = hot[rng.integers(0, len(hot) - 1)] + 40
            for _ in range(rng.integers(1, 6)):
                b[min(len(b) - 1, base + int(rng.integers(0, 100)))] = alphabet[rng.integers(0, alphabet.size)]
        else:
            b = b[: rng.integers(0, len(b))]
        bad.write_bytes(bytes(b))
        code, stdout, stderr = run_cli(capsys, ["info", bad, "--json"])
        assert code in outcomes, f"mutation {i}: exit {code}: {stderr[-500:]}"
        outcomes[code] += 1
        if code == 2:
            assert_rejected(code, stdout, stderr)
    assert outcomes[2] > 500


# ------------------------------------------------------------------------------------------- CSV traces

HEADER = "x,y,z,r,g,b,a\n"
ROW = "0,0,0.5,1,1,1,1\n"

CSV_CASES = {
    "empty-file": b"",
    "blank-lines": b"\n\n\n",
    "bad-header": b"a,b,c\n1,2,3\n",
    "header-missing-alpha": b"x,y,z,r,g,b\n0,0,0.5,1,1,1\n",
    "unknown-column": b"x,y,z,r,g,b,a,w\n0,0,0.5,1,1,1,1,1\n",
    "duplicate-column": b"x,y,z,r,g,b,a,a\n0,0,0.5,1,1,1,1,1\n",
    "duplicate-depth-column": b"x,y,z,r,g,b,a,z\n0,0,0.5,1,1,1,1,0.5\n",
    "empty-column-name": b"x,y,z,r,g,b,a,\n0,0,0.5,1,1,1,1,\n",
    "extra-field-first-row": (HEADER + "0,0,0.5,1,1,1,1,9\n").encode(),
    "opaque-two": b"x,y,z,r,g,b,a,opaque\n0,0,0.5,1,1,1,1,2\n",
    "semicolon-separated": b"x;y;z;r;g;b;a\n0;0;0.5;1;1;1;1\n",
    "extra-field": (HEADER + ROW + "0,0,0.5,1,1,1,1,9\n").encode(),
    "missing-field": (HEADER + ROW + "0,0,0.5,1,1,1\n").encode(),
    "text-in-x": (HEADER + "left,0,0.5,1,1,1,1\n").encode(),
    "text-in-z": (HEADER + ROW + "0,0,deep,1,1,1,1\n").encode(),
    "hex-in-x": (HEADER + "0x1,0,0.5,1,1,1,1\n").encode(),
    "boolean-in-x": (HEADER + "True,0,0.5,1,1,1,1\n").encode(),
    "boolean-in-z": (HEADER + "0,0,false,1,1,1,1\n").encode(),
    "nan-depth": (HEADER + "0,0,nan,1,1,1,1\n").encode(),
    "empty-depth": (HEADER + "0,0,,1,1,1,1\n").encode(),
    "inf-depth": (HEADER + "0,0,inf,1,1,1,1\n").encode(),
    "minus-inf-depth": (HEADER + ROW + "0,0,-inf,1,1,1,1\n").encode(),
    "depth-above-one": (HEADER + "0,0,2,1,1,1,1\n").encode(),
    "alpha-negative": (HEADER + "0,0,0.5,1,1,1,-0.1\n").encode(),
    "nan-x": (HEADER + "nan,0,0.5,1,1,1,1\n").encode(),
    "inf-x": (HEADER + "inf,0,0.5,1,1,1,1\n").encode(),
    "negative-x": (HEADER + "-1,0,0.5,1,1,1,1\n").encode(),
    "negative-y": (HEADER + ROW + "0,-7,0.5,1,1,1,1\n").encode(),
    "x-at-width": (HEADER + "8,0,0.5,1,1,1,1\n").encode(),
    "y-huge": (HEADER + "0,1e30,0.5,1,1,1,1\n").encode(),
    "x-beyond-int64": (HEADER + "99999999999999999999999999,0,0.5,1,1,1,1\n").encode(),
    "x-fractional": (HEADER + "1.5,0,0.5,1,1,1,1\n").encode(),
    "opaque-maybe": b"x,y,z,r,g,b,a,opaque\n0,0,0.5,1,1,1,1,maybe\n",
    "prim-negative": b"x,y,z,r,g,b,a,prim\n0,0,0.5,1,1,1,1,-1\n",
    "prim-beyond-uint32": b"x,y,z,r,g,b,a,prim\n0,0,0.5,1,1,1,1,4294967296\n",
    "binary-file": np.random.default_rng(1).bytes(2000),
    "binary-rows": (HEADER + ROW).encode() + np.random.default_rng(2).bytes(2000),
    "latin1-row": (HEADER + "0,0,0.5,1,1,1,\xe9\n").encode("latin-1"),
    "utf16-file": (HEADER + ROW).encode("utf-16"),
    "nul-bytes": (HEADER + "0,0,0.5,1,1,1,1\x00\n").encode(),
    "unterminated-quote": (HEADER + '0,0,"0.5,1,1,1,1\n').encode(),
    "quoted-newline": (HEADER + '0,0,"0.\n5",1,1,1,1\n').encode(),
    "cr-line-ends-bad-row": (HEADER + ROW + "9,0,0.5,1,1,1,1\n").replace("\n", "\r").encode(),
}


@pytest.mark.parametrize("case", CSV_CASES)
def test_bad_csv_is_rejected_in_one_line(tmp_path, capsys, case):
    csv = tmp_path / "f.csv"
    csv.write_bytes(CSV_CASES[case])
    out = tmp_path / "o.npz"
    code, stdout, stderr = run_cli(capsys, ["trace", "--from-csv", csv, "--size", "8x8", "-o", out])
    assert_rejected(code, stdout, stderr, out)
    assert "f.csv" in stderr, "the error should name the file"


@pytest.mark.parametrize("size", ["1000000000x1000000000", "0x8", "8x-8", "8", "eightxeight", "16385x1", ""])
def test_csv_import_rejects_a_bad_size(tmp_path, capsys, size):
    csv = tmp_path / "f.csv"
    csv.write_text(HEADER + ROW)
    out = tmp_path / "o.npz"
    assert_rejected(*run_cli(capsys, ["trace", "--from-csv", csv, "--size", size, "-o", out]), out)


def test_csv_with_old_mac_line_ends_imports(tmp_path, capsys):
    """Lines ended by a lone CR are rows too (pandas reads them so): the import counts them the same way."""
    csv = tmp_path / "cr.csv"
    csv.write_bytes((HEADER + ROW + "1,1,0.25,0,1,0,0.5\n").replace("\n", "\r").encode())
    code, _, stderr = run_cli(capsys, ["trace", "--from-csv", csv, "--size", "8x8", "-o", tmp_path / "o.npz"])
    assert code == 0, stderr


# ----------------------------------------------------------------------------------- scene files (TOML)

SCENE = """name = "fuzz"
[screen]
width = 16
height = 16
[[objects]]
kind = "sphere"
"""


def _scene(extra_top: str = "", screen: str = "", obj: str = "", camera: str = "") -> str:
    text = extra_top + SCENE.replace("height = 16\n", f"height = 16\n{screen}") + obj
    return text + (f"[camera]\n{camera}" if camera else "")


NESTED = "[" * 5000 + "]" * 5000

SCENE_CASES = {
    "empty-file": "",
    "only-a-comment": "# nothing here\n",
    "invalid-toml": "[screen\nwidth = 16\n",
    "unclosed-string": 'name = "fuzz\n',
    "not-utf8": b"name = \"\xff\xfe\"\n",
    "deeply-nested-array": f"name = {NESTED}\n",
    "unknown-top-key": _scene("zoom = 3\n"),
    "unknown-screen-key": _scene(screen="depth = 3\n"),
    "unknown-object-key": _scene(obj="wobble = 1\n"),
    "unknown-object-kind": SCENE.replace('"sphere"', '"teapot"'),
    "object-without-kind": SCENE.replace('kind = "sphere"\n', "radius = 1.0\n"),
    "no-objects": SCENE.split("[[objects]]")[0],
    "objects-not-a-list": 'objects = 5\n',
    "screen-not-a-table": 'screen = 5\n[[objects]]\nkind = "sphere"\n',
    "width-text": SCENE.replace("width = 16", 'width = "wide"'),
    "width-float": SCENE.replace("width = 16", "width = 16.5"),
    "width-bool": SCENE.replace("width = 16", "width = true"),
    "width-zero": SCENE.replace("width = 16", "width = 0"),
    "width-negative": SCENE.replace("width = 16", "width = -16"),
    "height-huge": SCENE.replace("height = 16", "height = 1000000000"),
    "width-beyond-int64": SCENE.replace("width = 16", "width = 99999999999999999999999999"),
    "background-out-of-range": _scene(screen="background = [2.0, 0.0, 0.0]\n"),
    "background-two-channels": _scene(screen="background = [1.0, 1.0]\n"),
    "radius-negative": _scene(obj="radius = -1.0\n"),
    "radius-inf": _scene(obj="radius = inf\n"),
    "alpha-nan": _scene(obj="alpha = nan\n"),
    "segments-huge": _scene(obj="segments = 1000000000\n"),
    "color-out-of-range": _scene(obj="color = [1.5, 0.0, 0.0]\n"),
    "fov-zero": _scene(camera="fov_y_deg = 0.0\n"),
    "far-before-near": _scene(camera="near = 10.0\nfar = 1.0\n"),
    "eye-on-target": _scene(camera="eye = [0.0, 0.0, 0.0]\ntarget = [0.0, 0.0, 0.0]\n"),
    "up-along-view": _scene(camera="eye = [0.0, 0.0, 5.0]\nup = [0.0, 0.0, 1.0]\n"),
    "up-zero": _scene(camera="up = [0.0, 0.0, 0.0]\n"),
    "scale-zero": _scene(obj="scale = [0.0, 0.0, 0.0]\n"),
    "scale-flat-lambert": _scene(obj="scale = [1.0, 1.0, 0.0]\n"),
    "mesh-missing": SCENE.replace('kind = "sphere"', 'kind = "mesh"\npath = "nowhere.obj"'),
    "histogram-negative-count": 'kind = "histogram"\ntransparent_per_pixel = [-1]\n[screen]\nwidth = 8\nheight = 8\n',
    "histogram-more-pixels-than-screen":
        'kind = "histogram"\ntransparent_per_pixel = [1000000000000]\n[screen]\nwidth = 8\nheight = 8\n',
}


@pytest.mark.parametrize("case", SCENE_CASES)
def test_bad_scene_file_is_rejected_in_one_line(tmp_path, capsys, case):
    scene = tmp_path / "s.toml"
    text = SCENE_CASES[case]
    scene.write_bytes(text if isinstance(text, bytes) else text.encode())
    out = tmp_path / "o.npz"
    code, stdout, stderr = run_cli(capsys, ["trace", scene, "-o", out, "--no-progress"])
    assert_rejected(code, stdout, stderr, out)
    assert "s.toml" in stderr, "the error should name the file"


def test_flat_scale_with_flat_shading_is_fine(tmp_path, capsys):
    """A zero scale is only a problem for the normals of Lambert shading."""
    scene = tmp_path / "s.toml"
    scene.write_text(_scene(obj='scale = [1.0, 1.0, 0.0]\nshading = "flat"\n'))
    code, _, stderr = run_cli(capsys, ["trace", scene, "-o", tmp_path / "o.npz", "--no-progress"])
    assert code == 0, stderr


# ------------------------------------------------------------------------------- mesh files (OBJ, PLY, ...)

TRIANGLE = "v 0 0 0\nv 1 0 0\nv 0 1 0\n"
PLY_HEADER = ("ply\nformat {fmt} 1.0\nelement vertex {n}\nproperty float x\nproperty float y\nproperty float z\n"
              "element face 1\nproperty list uchar int vertex_indices\nend_header\n")

MESH_CASES = {
    "empty.obj": b"",
    "random-bytes.obj": np.random.default_rng(3).bytes(3000),
    "text-coordinates.obj": b"v a b c\nf 1 2 3\n",
    "two-coordinates.obj": b"v 0 0 0\nv 1 0\nf 1 2 3\n",
    "face-beyond-vertices.obj": (TRIANGLE + "f 1 2 9\n").encode(),
    "face-negative-index.obj": (TRIANGLE + "f -7 2 3\n").encode(),
    "vertex-nan.obj": (TRIANGLE.replace("v 0 0 0", "v nan 0 0") + "f 1 2 3\n").encode(),
    "vertex-inf.obj": (TRIANGLE.replace("v 0 0 0", "v inf 0 0") + "f 1 2 3\n").encode(),
    "vertex-beyond-float.obj": b"v 1e308 0 0\nv -1e308 0 0\nv 0 1e308 0\nf 1 2 3\n",
    "face-beyond-vertices.ply": (PLY_HEADER.format(fmt="ascii", n=3) + "0 0 0\n1 0 0\n0 1 0\n3 0 1 7\n").encode(),
    "1e12-vertices.ply": (PLY_HEADER.format(fmt="ascii", n=10**12) + "0 0 0\n").encode(),
    "1e10-binary-vertices.ply": PLY_HEADER.format(fmt="binary_little_endian", n=10**10).encode() + bytes(1000),
    "truncated-binary.ply": PLY_HEADER.format(fmt="binary_little_endian", n=3).encode(),
    "face-beyond-vertices.off": b"OFF\n3 1 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1 5\n",
    "1e11-vertices.off": b"OFF\n99999999999 1 0\n0 0 0\n",
    "short-facet.stl": b"solid x\nfacet normal 0 0 1\nouter loop\nvertex 0 0 0\nvertex 1 0\nendloop\nendfacet\nendsolid\n",
    "4e9-triangles.stl": bytes(80) + struct.pack("<I", 4_000_000_000) + bytes(50),
    "truncated-binary.stl": np.random.default_rng(4).bytes(84),
}


@pytest.mark.parametrize("case", cases(MESH_CASES))
def test_bad_mesh_file_is_rejected_in_one_line(tmp_path, capsys, case):
    """A mesh file as the scene, and named by a scene file: each fails naming the file, never with a
    traceback, numpy's warnings or an empty trace (a NaN vertex used to give one, with warnings)."""
    mesh = tmp_path / case
    mesh.write_bytes(MESH_CASES[case])
    scene = tmp_path / "s.toml"
    scene.write_text(SCENE.replace('kind = "sphere"', f'kind = "mesh"\npath = "{case}"'))
    out = tmp_path / "o.npz"
    for source in (mesh, scene):
        code, stdout, stderr = run_cli(capsys, ["trace", source, "-o", out, "--no-progress"])
        assert_rejected(code, stdout, stderr, out)
        assert case in stderr, "the error should name the mesh file"


def test_a_valid_mesh_file_traces(tmp_path, capsys):
    """The mesh cases fail for what they break, not for the command."""
    mesh = tmp_path / "ok.obj"
    mesh.write_text(TRIANGLE + "f 1 2 3\n")
    code, _, stderr = run_cli(capsys, ["trace", mesh, "--size", "16x16", "-o", tmp_path / "o.npz", "--no-progress"])
    assert code == 0 and stderr == "", stderr


# ----------------------------------------------------------------------------------------- GPU configs

GPU_CASES = {
    "empty-file": "",
    "only-a-comment": "# nothing\n",
    "invalid-toml": "[core\nsms = 30\n",
    "not-utf8": b"[core]\nname = \"\xff\"\n",
    "deeply-nested-array": f"[core]\nsms = {NESTED}\n",
    "unknown-section": "[warp]\nsize = 32\n",
    "unknown-key": "[core]\nsms = 30\nturbo = true\n",
    "section-not-a-table": "core = 30\n",
    "name-not-a-string": "name = 5\n[core]\nsms = 30\n",
    "sms-text": '[core]\nsms = "many"\n',
    "sms-float": "[core]\nsms = 1.5\n",
    "sms-zero": "[core]\nsms = 0\n",
    "sms-negative": "[core]\nsms = -4\n",
    "warp-size-33": "[core]\nwarp_size = 33\n",
    "warp-size-zero": "[core]\nwarp_size = 0\n",
    "latency-negative": "[dram]\nlatency = -1\n",
    "clock-zero": "[core]\nclock_mhz = 0.0\n",
    "clock-nan": "[core]\nclock_mhz = nan\n",
    "clock-inf": "[core]\nclock_mhz = inf\n",
    "thread-mapping-unknown": '[core]\nthread_mapping = "diagonal"\n',
    "sample-fraction-above-one": "[sample]\nfraction = 2.0\n",
    "levels-not-a-list": '[memory]\nlevels = "dram"\n',
    "levels-start-with-dram": '[memory]\nlevels = ["dram"]\n',
    "levels-twice": '[memory]\nlevels = ["coalescer", "coalescer", "dram"]\n',
    "levels-unknown": '[memory]\nlevels = ["coalescer", "l7", "dram"]\n',
    "levels-empty": "[memory]\nlevels = []\n",
    "scoreboard-smaller-than-warp": "[scoreboard]\nentries = 1\n",
    "no-progress-below-latency": "[runner]\nno_progress_cycles = 1\n",
}


def _replay_full(trace, out, *extra):
    return ["replay", trace, "--scheme", "alpha-blend", "--fidelity", "full", "-o", out, *extra]


@pytest.mark.parametrize("case", cases(GPU_CASES))
def test_bad_gpu_file_is_rejected_in_one_line(valid_trace, tmp_path, capsys, case):
    gpu = tmp_path / "g.toml"
    text = GPU_CASES[case]
    gpu.write_bytes(text if isinstance(text, bytes) else text.encode())
    out = tmp_path / "out"
    code, stdout, stderr = run_cli(capsys, _replay_full(valid_trace, out, "--gpu", gpu))
    assert_rejected(code, stdout, stderr, out)
    assert "g.toml" in stderr, "the error should name the file"


GPU_SET_CASES = {
    "no-equals": "core.sms",
    "empty-key": "=30",
    "empty-key-part": "core..sms=30",
    "unknown-section": "warp.size=32",
    "unknown-key": "core.turbo=true",
    "section-set-to-a-value": "core=30",
    "key-below-a-value": "core.sms.x=1",
    "sms-text": "core.sms=many",
    "sms-zero": "core.sms=0",
    "warp-size-33": "core.warp_size=33",
    "latency-negative": "dram.latency=-1",
    "clock-inf": "core.clock_mhz=inf",
    "levels-start-with-dram": 'memory.levels=["dram"]',
    "deeply-nested-value": f"core.sms={NESTED}",
    "levels-empty": "memory.levels=[]",
}


def test_a_valid_gpu_file_replays(valid_trace, tmp_path, capsys):
    """The GPU cases fail for what they change, not for the command."""
    gpu = tmp_path / "g.toml"
    gpu.write_text("[core]\nsms = 30\n")
    code, stdout, stderr = run_cli(capsys, _replay_full(valid_trace, tmp_path / "out", "--gpu", gpu,
                                                        "--gpu-set", "core.sms=16"))
    assert code == 0 and "cycles" in stdout, stderr


@pytest.mark.parametrize("case", cases(GPU_SET_CASES))
def test_bad_gpu_set_is_rejected_in_one_line(valid_trace, tmp_path, capsys, case):
    out = tmp_path / "out"
    code, stdout, stderr = run_cli(capsys, _replay_full(valid_trace, out, "--gpu-set", GPU_SET_CASES[case]))
    assert_rejected(code, stdout, stderr, out)


@pytest.mark.parametrize("gpu", ["nowhere.toml", "{tmp}", "no-such-preset"])
def test_missing_gpu_is_rejected_in_one_line(valid_trace, tmp_path, capsys, gpu):
    out = tmp_path / "out"
    gpu = gpu.replace("{tmp}", str(tmp_path / "folder.toml"))
    (tmp_path / "folder.toml").mkdir()
    assert_rejected(*run_cli(capsys, _replay_full(valid_trace, out, "--gpu", gpu)), out)


# ------------------------------------------------------------------------------------ experiment files

EXPERIMENT = """name = "fuzz"
scenes = ["default"]
size = "16x16"
gpus = ["gtx280"]
fidelity = ["none"]
"""
SCHEME = "[schemes.alpha-blend]\n"

EXPERIMENT_CASES = {
    "empty-file": "",
    "only-a-comment": "# nothing\n",
    "invalid-toml": EXPERIMENT + "[schemes.alpha-blend\n",
    "not-utf8": b"name = \"\xff\"\n",
    "deeply-nested-array": f"scenes = {NESTED}\n",
    "unknown-top-key": "turbo = true\n" + EXPERIMENT + SCHEME,
    "unknown-scheme": EXPERIMENT + "[schemes.teleport]\n",
    "unknown-scheme-parameter": EXPERIMENT + "[schemes.kbuffer]\nkk = [2]\n",
    "scheme-parameter-wrong-type": EXPERIMENT + '[schemes.kbuffer]\nk = "two"\n',
    "scheme-parameter-out-of-range": EXPERIMENT + "[schemes.kbuffer]\nk = [0]\n",
    "scheme-parameter-huge": EXPERIMENT + "[schemes.kbuffer]\nk = 1000000000\n",
    "schemes-not-a-table": EXPERIMENT + 'schemes = "alpha-blend"\n',
    "unknown-gpu": EXPERIMENT.replace('"gtx280"', '"gtx9999"') + SCHEME,
    "missing-gpu-file": EXPERIMENT.replace('"gtx280"', '"nowhere.toml"') + SCHEME,
    "bad-gpu-file": EXPERIMENT.replace('"gtx280"', '"bad-gpu.toml"') + SCHEME,
    "unknown-scene": EXPERIMENT.replace('"default"', '"atlantis"') + SCHEME,
    "bad-scene-file": EXPERIMENT.replace('"default"', '"bad-scene.toml"') + SCHEME,
    "unknown-fidelity": EXPERIMENT.replace('"none"', '"warp9"') + SCHEME,
    "missing-trace-file": 'traces = ["nowhere.npz"]\n' + EXPERIMENT.replace('scenes = ["default"]\n', "")
                          .replace('size = "16x16"\n', "") + SCHEME,
    "scenes-wrong-type": EXPERIMENT.replace('["default"]', "5") + SCHEME,
    "size-not-a-string": EXPERIMENT.replace('"16x16"', "16") + SCHEME,
    "size-zero": EXPERIMENT.replace('"16x16"', '"0x0"') + SCHEME,
    "size-huge": EXPERIMENT.replace('"16x16"', '"1000000000x1000000000"') + SCHEME,
    "name-escapes-folder": EXPERIMENT.replace('"fuzz"', '"../../escape"') + SCHEME,
    "description-two-lines": 'description = """one\ntwo"""\n' + EXPERIMENT + SCHEME,
    "include-missing": 'include = "nowhere.toml"\n' + EXPERIMENT + SCHEME,
    "include-itself": 'include = "e.toml"\n' + EXPERIMENT + SCHEME,
    "unknown-paper": 'paper = "seed-999"\n' + EXPERIMENT + SCHEME,
    "value-listed-twice": EXPERIMENT + "[schemes.kbuffer]\nk = [2, 2]\n",
    "gpu-set-unknown-key": EXPERIMENT + SCHEME + '[gpu-set]\n"core.turbo" = [true]\n',
    "gpu-set-impossible-value": EXPERIMENT + SCHEME + '[gpu-set]\n"core.warp_size" = [33]\n',
    "gpu-set-not-a-table": 'gpu-set = 3\n' + EXPERIMENT + SCHEME,
    "scene-set-unknown-key": EXPERIMENT + SCHEME + '[scene-set]\n"camera.zoom" = [2.0]\n',
    "scene-set-zero-scale": EXPERIMENT + SCHEME + '[scene-set]\n"objects.0.scale" = [[0.0, 0.0, 0.0]]\n',
    # an empty grid, every way
    "no-schemes": EXPERIMENT,
    "empty-schemes-table": EXPERIMENT + "[schemes]\n",
    "empty-parameter-axis": EXPERIMENT + "[schemes.kbuffer]\nk = []\n",
    "empty-scenes": EXPERIMENT.replace('["default"]', "[]") + SCHEME,
    "empty-gpus": EXPERIMENT.replace('["gtx280"]', "[]") + SCHEME,
    "empty-fidelity": EXPERIMENT.replace('["none"]', "[]") + SCHEME,
    "empty-gpu-set-axis": EXPERIMENT + SCHEME + '[gpu-set]\n"rop.units" = []\n',
    "gpu-set-empty-levels": EXPERIMENT + SCHEME + '[gpu-set]\n"memory.levels" = [[]]\n',
}


def _write_experiment(tmp_path: Path, case: str) -> Path:
    (tmp_path / "bad-gpu.toml").write_text("[core]\nwarp_size = 33\n")
    (tmp_path / "bad-scene.toml").write_text("[screen\n")
    path = tmp_path / "e.toml"
    text = EXPERIMENT_CASES[case]
    path.write_bytes(text if isinstance(text, bytes) else text.encode())
    return path


@pytest.mark.parametrize("case", cases(EXPERIMENT_CASES))
def test_bad_experiment_is_rejected_by_run_in_one_line(tmp_path, capsys, case, monkeypatch):
    monkeypatch.chdir(tmp_path)             # a default output (reports/<name>/) would land here, not in the repo
    experiment = _write_experiment(tmp_path, case)
    out = tmp_path / "out"
    code, stdout, stderr = run_cli(capsys, ["run", experiment, "-o", out, "--workers", "1", "--quiet",
                                            "--no-report"])
    assert_rejected(code, stdout, stderr, out)
    assert not (tmp_path / "reports").exists()


@pytest.mark.parametrize("case", cases(EXPERIMENT_CASES))
def test_bad_experiment_is_rejected_by_config_in_one_line(tmp_path, capsys, case, monkeypatch):
    monkeypatch.chdir(tmp_path)
    assert_rejected(*run_cli(capsys, ["config", _write_experiment(tmp_path, case)]))


def test_the_valid_experiment_passes_config(tmp_path, capsys):
    path = tmp_path / "e.toml"
    path.write_text(EXPERIMENT + SCHEME)
    code, stdout, stderr = run_cli(capsys, ["config", path])
    assert code == 0 and "1 run" in stdout and "1 runs" not in stdout, stderr


def test_experiment_with_a_corrupt_trace_is_rejected_in_one_line(valid_trace, tmp_path, capsys):
    (tmp_path / "cut.npz").write_bytes(valid_trace.read_bytes()[:5000])
    experiment = tmp_path / "e.toml"
    experiment.write_text('traces = ["cut.npz"]\nfidelity = ["none"]\n' + SCHEME)
    out = tmp_path / "out"
    code, stdout, stderr = run_cli(capsys, ["run", experiment, "-o", out, "--workers", "1", "--quiet",
                                            "--no-report"])
    assert_rejected(code, stdout, stderr, out)
    assert "cut.npz" in stderr


# ------------------------------------------------------------------------- values on the command line

ARGV_CASES = {
    "param-nan": ["replay", "{trace}", "--scheme", "kbuffer", "--param", "k=nan", "-o", "{out}"],
    "param-inf": ["replay", "{trace}", "--scheme", "wboit", "--param", "near=-inf", "-o", "{out}"],
    "param-beyond-int64": ["replay", "{trace}", "--scheme", "kbuffer", "--param", "k=99999999999999999999",
                           "-o", "{out}"],
    "param-a-list": ["replay", "{trace}", "--scheme", "kbuffer", "--param", "k=[1, 2]", "-o", "{out}"],
    "param-a-table": ["replay", "{trace}", "--scheme", "kbuffer", "--param", "k={a = 1}", "-o", "{out}"],
    "param-bool-for-int": ["replay", "{trace}", "--scheme", "kbuffer", "--param", "k=true", "-o", "{out}"],
    "param-unknown-choice": ["replay", "{trace}", "--scheme", "kbuffer", "--param", "mode=7", "-o", "{out}"],
    "param-empty": ["replay", "{trace}", "--scheme", "kbuffer", "--param", "k=", "-o", "{out}"],
    "gpu-a-directory": ["replay", "{trace}", "--scheme", "kbuffer", "--fidelity", "analytic", "--gpu", "/",
                        "-o", "{out}"],
    "trace-a-csv-as-scene": ["trace", "{experiment}.csv", "-o", "{out}.npz"],
    "fidelity-unknown": ["replay", "{trace}", "--scheme", "kbuffer", "--fidelity", "warp", "-o", "{out}"],
    "thesis-for-other-scheme": ["replay", "{trace}", "--scheme", "kbuffer", "--fidelity", "thesis", "-o", "{out}"],
    "gpu-set-nan": ["replay", "{trace}", "--scheme", "kbuffer", "--fidelity", "sampled", "--gpu-set",
                    "sample.fraction=nan", "-o", "{out}"],
    "schemes-unknown": ["schemes", "teleport"],
    "trace-set-nan-width": ["trace", "default", "--set", "screen.width=nan", "-o", "{out}.npz"],
    "trace-set-inf-alpha": ["trace", "default", "--set", "objects.0.alpha=inf", "-o", "{out}.npz"],
    "trace-set-negative-index": ["trace", "default", "--set", "objects.-1.alpha=1", "-o", "{out}.npz"],
    "trace-size-beyond-int64": ["trace", "default", "--size", "99999999999999999999x5", "-o", "{out}.npz"],
    "trace-size-negative": ["trace", "default", "--size", "-5x5", "-o", "{out}.npz"],
    "run-set-size-huge": ["run", "{experiment}", "--set", "size=99999x99999", "-o", "{out}", "--quiet"],
    "run-set-param-inf": ["run", "{experiment}", "--set", "schemes.kbuffer.k=inf", "-o", "{out}", "--quiet"],
    "run-set-gpus-number": ["run", "{experiment}", "--set", "gpus=[5]", "-o", "{out}", "--quiet"],
    "run-set-trace-not-npz": ["run", "{experiment}", "--set", 'traces=["{experiment}"]', "-o", "{out}", "--quiet"],
    "run-set-gpu-set-nan": ["run", "{experiment}", "--set", "gpu-set.sample.fraction=[nan]", "-o", "{out}",
                            "--quiet"],
    "config-set-fidelity-number": ["config", "{experiment}", "--set", "fidelity=5"],
}


@pytest.mark.parametrize("case", cases(ARGV_CASES))
def test_hostile_command_line_values_are_rejected_in_one_line(valid_trace, tmp_path, capsys, case, monkeypatch):
    monkeypatch.chdir(tmp_path)
    experiment = tmp_path / "e.toml"
    experiment.write_text(EXPERIMENT + SCHEME + "[schemes.kbuffer]\nk = 2\n")
    out = tmp_path / "out"
    argv = [a.replace("{trace}", str(valid_trace)).replace("{out}", str(out)).replace("{experiment}", str(experiment))
            for a in ARGV_CASES[case]]
    output = Path(argv[argv.index("-o") + 1]) if "-o" in argv else None
    try:
        code, stdout, stderr = run_cli(capsys, argv)
    except SystemExit as exc:                 # a usage error: argparse's one line, "gpusim COMMAND: error: ..."
        stdout, stderr = capsys.readouterr()
        prefix = f"gpusim {argv[0]}: error: "
        assert exc.code == 2 and stderr.startswith(prefix) and stderr.count("\n") == 1, stderr
        code, stderr = 2, stderr.replace(prefix, "gpusim: error: ")
    assert_rejected(code, stdout, stderr, output)


def _cpus() -> int:
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:                   # pragma: no cover - platforms without affinity
        return os.cpu_count() or 1


@pytest.mark.parametrize("workers", ["{cpus+1}", "100000"])
def test_more_workers_than_cpus_are_refused_in_one_line(tmp_path, capsys, monkeypatch, workers):
    """Each local worker holds a model in memory: more than the CPUs here would only exhaust memory."""
    monkeypatch.chdir(tmp_path)
    experiment = tmp_path / "e.toml"
    experiment.write_text(EXPERIMENT + SCHEME)
    out = tmp_path / "out"
    workers = workers.replace("{cpus+1}", str(_cpus() + 1))
    code, stdout, stderr = run_cli(capsys, ["run", experiment, "-o", out, "--workers", workers, "--quiet"])
    assert_rejected(code, stdout, stderr, out)
    assert f"--workers {workers}" in stderr and f"1..{_cpus()}" in stderr and "--cluster" in stderr, stderr


def test_as_many_workers_as_cpus_run(tmp_path, capsys, monkeypatch):
    monkeypatch.chdir(tmp_path)
    experiment = tmp_path / "e.toml"
    experiment.write_text(EXPERIMENT + SCHEME)
    code, stdout, stderr = run_cli(capsys, ["run", experiment, "-o", tmp_path / "out", "--workers", _cpus(),
                                            "--quiet", "--no-report"])
    assert code == 0, stderr


# ------------------------------------------------------------------- results directories (gpusim report)


@pytest.fixture(scope="module")
def results_dir(tmp_path_factory) -> Path:
    """A finished sweep of two functional runs with its report; every damaged one starts as a copy."""
    root = tmp_path_factory.mktemp("results")
    (root / "e.toml").write_text(EXPERIMENT.replace("16x16", "8x8") + SCHEME + "[schemes.kbuffer]\nk = 2\n")
    assert main(["run", str(root / "e.toml"), "-o", str(root / "out"), "--workers", "1", "--quiet"]) == 0
    return root / "out"


def _edit_table(name: str, change):
    """A case: ``name``.parquet read, changed by ``change(frame)`` (which returns the new frame), written back."""
    def make(root: Path) -> None:
        import pandas as pd
        change(pd.read_parquet(root / f"{name}.parquet")).to_parquet(root / f"{name}.parquet")
    return make


def _set_column(name: str, column: str, value):
    return _edit_table(name, lambda d: d.assign(**{column: value}))


def _each_file(pattern: str, write):
    """A case: every file matching ``pattern`` under the directory rewritten by ``write(path)``."""
    def make(root: Path) -> None:
        paths = sorted(root.glob(pattern))
        assert paths, pattern
        for path in paths:
            write(path)
    return make


def _small_png(path: Path) -> None:
    from gpusim.report.images import save_rgb8_png
    save_rgb8_png(np.zeros((3, 5, 3), np.uint8), path)


def _grey_png(path: Path) -> None:
    from PIL import Image
    Image.fromarray(np.zeros((8, 8), np.uint8), "L").save(path, format="png")


REPORT_CASES = {
    "results-truncated": _each_file("results.parquet", lambda p: p.write_bytes(p.read_bytes()[:500])),
    "results-empty-file": _each_file("results.parquet", lambda p: p.write_bytes(b"")),
    "results-is-csv-text": _each_file("results.parquet", lambda p: p.write_text("run,status\nx,ok\n")),
    "stats-missing": _each_file("stats.parquet", Path.unlink),
    "stats-truncated": _each_file("stats.parquet", lambda p: p.write_bytes(p.read_bytes()[:300])),
    "results-without-cycles": _edit_table("results", lambda d: d.drop(columns=["cycles"])),
    "results-without-lead-columns": _edit_table("results", lambda d: d[["cycles"]]),
    "cycles-text": _set_column("results", "cycles", "many"),
    "cycles-inf": _set_column("results", "cycles", float("inf")),
    "rmse-negative": _set_column("results", "rmse", -1.0),
    "status-unknown": _set_column("results", "status", "weird"),
    "status-missing": _set_column("results", "status", None),
    "scheme-a-number": _set_column("results", "scheme", 5),
    "width-zero": _set_column("results", "width", 0),
    "height-missing": _set_column("results", "height", float("nan")),
    "index-fractional": _set_column("results", "index", 0.5),
    "stats-value-text": _set_column("stats", "value", "x"),
    "stats-without-unit": _edit_table("stats", lambda d: d.drop(columns=["unit"])),
    "run-image-truncated": _each_file("runs/*/image.png", lambda p: p.write_bytes(p.read_bytes()[:100])),
    "run-image-wrong-size": _each_file("runs/*/image.png", _small_png),
    "run-image-greyscale": _each_file("runs/*/image.png", _grey_png),
    "reference-image-truncated": _each_file("traces/*.png", lambda p: p.write_bytes(p.read_bytes()[:100])),
}


def _report_state(root: Path) -> dict:
    return {p.relative_to(root).as_posix(): p.read_bytes() for p in [root / "index.md", *root.glob("figures/*")]}


@pytest.mark.parametrize("case", cases(REPORT_CASES))
def test_damaged_results_are_rejected_by_report_in_one_line(results_dir, tmp_path, capsys, case):
    """Into a new folder: nothing is made there. In place: the old report (index.md, figures/) stays."""
    import shutil
    root = tmp_path / "res"
    shutil.copytree(results_dir, root)
    before = _report_state(root)
    assert "figures/images-default.png" in before
    REPORT_CASES[case](root)
    out = tmp_path / "report"
    assert_rejected(*run_cli(capsys, ["report", root, "-o", out]), out)
    code, stdout, stderr = run_cli(capsys, ["report", root])
    assert_rejected(code, stdout, stderr)
    assert str(root) in stderr, "the error should name the directory or its file"
    assert _report_state(root) == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["res"]          # no temporary folder left


def test_report_rewrites_a_report_whole(results_dir, tmp_path, capsys):
    """The undamaged copy reports; a figure the new report does not draw goes with the old figures."""
    import shutil
    root = tmp_path / "res"
    shutil.copytree(results_dir, root)
    (root / "figures" / "stale.png").write_bytes(b"old")
    code, stdout, stderr = run_cli(capsys, ["report", root])
    assert code == 0 and stderr == "" and stdout == f"wrote {root / 'index.md'}\n"
    assert not (root / "figures" / "stale.png").exists() and (root / "figures" / "images-default.png").is_file()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["res"]


# ------------------------------------------------------------------- inputs that would exhaust memory

HUGE_GPU_SETS = ["core.sms=1000000000", "rop.units=1000000000", "memory.partitions=1000000000"]


@pytest.mark.parametrize("argv", [
    *[["replay", "{trace}", "--scheme", "alpha-blend", "--fidelity", "full", "--gpu-set", s, "-o", "{out}"]
      for s in HUGE_GPU_SETS],
    ["trace", "{tmp}/h.toml", "-o", "{out}.npz", "--no-progress"],
    ["trace", "default", "--size", "16384x16384", "-o", "{out}.npz", "--no-progress"],
], ids=[*(s.split("=")[0] for s in HUGE_GPU_SETS), "histogram-1e12-fragments", "largest-screen"])
def test_requests_beyond_memory_fail_in_one_line(valid_trace, tmp_path, argv):
    """Run in a child limited to MEMORY_LIMIT bytes: out of memory is one line, not a traceback or a
    machine brought to its knees."""
    (tmp_path / "h.toml").write_text('kind = "histogram"\ntransparent_per_pixel = [1]\nfragments = 1000000000000\n'
                                     "[screen]\nwidth = 16\nheight = 16\n")
    out = tmp_path / "out"
    argv = [a.format(trace=valid_trace, tmp=tmp_path, out=out) for a in argv]
    code, stdout, stderr = run_child(argv, tmp_path)
    assert_rejected(code, stdout, stderr, Path(argv[argv.index("-o") + 1]))
