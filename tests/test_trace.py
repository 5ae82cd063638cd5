"""FragmentTrace validation and the .npz format: every bad input fails with one clear line."""

from __future__ import annotations

import zipfile

import numpy as np
import pytest

from conftest import make_trace
from gpusim.errors import TraceError
from gpusim.trace import FragmentTrace
from gpusim.trace_io import FORMAT_VERSION, load_trace, save_trace


def test_roundtrip_keeps_every_array_and_metadata(tmp_path, random_trace):
    path = save_trace(random_trace, tmp_path / "t.npz")
    back = load_trace(path)
    for name in ("x", "y", "z", "rgba", "prim", "opaque"):
        np.testing.assert_array_equal(getattr(back, name), getattr(random_trace, name))
        assert getattr(back, name).dtype == getattr(random_trace, name).dtype
    assert (back.width, back.height) == (16, 12)
    assert back.meta == random_trace.meta


def test_empty_trace_roundtrips(tmp_path):
    back = load_trace(save_trace(FragmentTrace.empty(4, 3), tmp_path / "e.npz"))
    assert len(back) == 0 and back.depth_complexity().shape == (3, 4)


def _one_line(exc: pytest.ExceptionInfo) -> str:
    msg = str(exc.value)
    assert "\n" not in msg
    return msg


@pytest.mark.parametrize("field, value, expect", [
    ("z", np.nan, "NaN depth"),
    ("z", np.inf, "infinite depth"),
    ("z", 1.5, "outside [0, 1]"),
    ("z", -0.1, "outside [0, 1]"),
    ("alpha", 1.01, "colour/alpha"),
    ("alpha", np.nan, "NaN colour/alpha"),
])
def test_out_of_range_values_name_the_fragment(field, value, expect):
    zs = np.full(5, 0.5)
    rgba = np.full((5, 4), 0.5)
    if field == "z":
        zs[3] = value
    else:
        rgba[3, 3] = value
    with pytest.raises(TraceError) as exc:
        make_trace(range(5), range(5), zs, rgba)
    assert expect in _one_line(exc) and "fragment 3" in str(exc.value)


def test_pixel_outside_screen_is_rejected():
    with pytest.raises(TraceError) as exc:
        make_trace([1, 8], [1, 1], [0.1, 0.2], width=8, height=8)
    assert "fragment 1 has x=8, outside the screen" in _one_line(exc)


def test_mismatched_lengths_and_dtypes_are_rejected():
    t = make_trace([1, 2], [1, 2], [0.1, 0.2])
    with pytest.raises(TraceError, match="has 1 entries"):
        FragmentTrace(t.x, t.y, t.z[:1], t.rgba, t.prim, t.opaque, 8, 8)
    with pytest.raises(TraceError, match="dtype float64"):
        FragmentTrace(t.x, t.y, t.z.astype(np.float64), t.rgba, t.prim, t.opaque, 8, 8)


def test_truncated_file_fails_with_one_line(tmp_path, random_trace):
    path = save_trace(random_trace, tmp_path / "t.npz")
    data = path.read_bytes()
    for cut in (len(data) // 2, len(data) - 30, 100):
        bad = tmp_path / f"cut{cut}.npz"
        bad.write_bytes(data[:cut])
        with pytest.raises(TraceError) as exc:
            load_trace(bad)
        assert "truncated or corrupted" in _one_line(exc) or "unreadable" in str(exc.value)


def test_missing_array_is_named(tmp_path, random_trace):
    path = save_trace(random_trace, tmp_path / "t.npz")
    bad = tmp_path / "bad.npz"
    with zipfile.ZipFile(path) as src, zipfile.ZipFile(bad, "w") as dst:
        for item in src.infolist():
            if item.filename != "z.npy":
                dst.writestr(item, src.read(item.filename))
    with pytest.raises(TraceError) as exc:
        load_trace(bad)
    assert "array 'z' is missing" in _one_line(exc)


def test_newer_format_version_asks_for_upgrade(tmp_path, random_trace):
    path = tmp_path / "v.npz"
    np.savez(path, format_version=np.int64(FORMAT_VERSION + 1), width=np.int64(16), height=np.int64(12),
             meta_json=np.str_("{}"), **{k: getattr(random_trace, k) for k in
                                         ("x", "y", "z", "rgba", "prim", "opaque")})
    with pytest.raises(TraceError, match="newer than this gpusim reads"):
        load_trace(path)


def test_not_a_zip_and_missing_file(tmp_path):
    junk = tmp_path / "junk.npz"
    junk.write_text("hello")
    with pytest.raises(TraceError, match="not a gpusim trace"):
        load_trace(junk)
    with pytest.raises(TraceError, match="no such trace file"):
        load_trace(tmp_path / "absent.npz")


def test_save_is_atomic_on_failure(tmp_path, random_trace, monkeypatch):
    path = save_trace(random_trace, tmp_path / "t.npz")
    before = path.read_bytes()

    def boom(*a, **k):
        raise KeyboardInterrupt
    monkeypatch.setattr(np, "savez", boom)
    with pytest.raises(KeyboardInterrupt):
        save_trace(random_trace, path)
    assert path.read_bytes() == before
    assert [p.name for p in tmp_path.iterdir()] == ["t.npz"]  # no temporary left behind


def test_depth_complexity_and_pixel_ids():
    t = make_trace([0, 0, 3], [0, 0, 2], [0.1, 0.2, 0.3], width=4, height=3)
    dc = t.depth_complexity()
    assert dc.shape == (3, 4) and dc[0, 0] == 2 and dc[2, 3] == 1 and dc.sum() == 3
    np.testing.assert_array_equal(t.pixel_ids(), [0, 0, 11])


def test_outputs_follow_the_umask(tmp_path):
    import os

    from gpusim.atomic_io import atomic_folder, write_text_atomic
    old = os.umask(0o027)
    try:
        write_text_atomic(tmp_path / "a.txt", "x")
        with atomic_folder(tmp_path / "d") as d:
            (d / "f").write_text("y")
    finally:
        os.umask(old)
    assert (tmp_path / "a.txt").stat().st_mode & 0o777 == 0o640
    assert (tmp_path / "d").stat().st_mode & 0o777 == 0o750
