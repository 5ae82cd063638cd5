"""CSV import: format, defaults, and one-line errors naming the line."""

from __future__ import annotations

import numpy as np
import pytest

from gpusim.errors import TraceError
from gpusim.trace_csv import read_csv_trace


def write(tmp_path, text, name="f.csv"):
    path = tmp_path / name
    path.write_text(text)
    return path


def test_minimal_columns_default_prim_and_opaque(tmp_path):
    path = write(tmp_path, "x,y,z,r,g,b,a\n0,0,0.5,1,0,0,0.5\n3,2,0.25,0,1,0,1\n")
    t = read_csv_trace(path, 4, 3)
    np.testing.assert_array_equal(t.x, [0, 3])
    np.testing.assert_array_equal(t.prim, [0, 1])
    assert not t.opaque.any()
    np.testing.assert_allclose(t.rgba[1], [0, 1, 0, 1])


def test_optional_columns_any_order_and_booleans(tmp_path):
    path = write(tmp_path, "opaque,prim,a,b,g,r,z,y,x\ntrue,7,1,0,0,1,0.1,1,1\n0,7,0.5,1,0,0,0.2,1,2\n")
    t = read_csv_trace(path, 4, 4)
    np.testing.assert_array_equal(t.opaque, [True, False])
    np.testing.assert_array_equal(t.prim, [7, 7])
    np.testing.assert_array_equal(t.x, [1, 2])


def test_chunked_reading_matches(tmp_path, monkeypatch):
    import gpusim.trace_csv as mod
    rng = np.random.default_rng(0)
    n = 1000
    rows = "\n".join(f"{rng.integers(0, 9)},{rng.integers(0, 9)},{rng.random():.6f},0.1,0.2,0.3,0.4"
                     for _ in range(n))
    path = write(tmp_path, "x,y,z,r,g,b,a\n" + rows + "\n")
    full = read_csv_trace(path, 9, 9)
    monkeypatch.setattr(mod, "CHUNK_ROWS", 37)
    chunked = read_csv_trace(path, 9, 9)
    assert len(full) == n
    np.testing.assert_array_equal(full.z, chunked.z)
    np.testing.assert_array_equal(full.prim, np.arange(n))


@pytest.mark.parametrize("body, expect", [
    ("x,y,z,r,g,b\n0,0,0.5,1,1,1\n", "missing column(s) a"),
    ("x,y,z,r,g,b,a,depth\n0,0,0.5,1,1,1,1,3\n", "unknown column(s) depth"),
    ("x,y,z,r,g,b,a\n0,0,nan,1,1,1,1\n", "f.csv:2: column 'z' is empty or NaN"),
    ("x,y,z,r,g,b,a\n0,0,0.5,1,1,1,1\n0,0,abc,1,1,1,1\n", "f.csv:3: column 'z' holds 'abc'"),
    ("x,y,z,r,g,b,a\n9,0,0.5,1,1,1,1\n", "x=9 puts the pixel outside the screen: coordinates must be 0 <= x < 4 "
                                         "(the screen width); fix the row or give a larger --size"),
    ("x,y,z,r,g,b,a\n0,4,0.5,1,1,1,1\n", "y=4 puts the pixel outside the screen: coordinates must be 0 <= y < 4 "
                                         "(the screen height)"),
    ("x,y,z,r,g,b,a\n1.5,0,0.5,1,1,1,1\n", "x=1.5 is not an integer"),
    ("x,y,z,r,g,b,a\n-1,0,0.5,1,1,1,1\n", "x=-1 puts the pixel outside the screen: coordinates must be "
                                          "0 <= x < 4 (the screen width); fix the row"),
    ("x,y,z,r,g,b,a\n0,0,1.5,1,1,1,1\n", "f.csv:2: fragment 0 has depth 1.5 outside [0, 1]"),
    ("x,y,z,r,g,b,a\n0,0,0.5,1,1,1,2\n", "colour/alpha"),
    ("x,y,z,r,g,b,a,opaque\n0,0,0.5,1,1,1,1,maybe\n", "opaque='maybe'"),
    ("x,y,z,r,g,b,a,opaque\n0,0,0.5,1,1,1,1,2\n", "f.csv:2: opaque=2 is not 0/1 or true/false"),
    ("x,y,z,r,g,b,a,z\n0,0,0.5,1,1,1,1,0.5\n", "f.csv: column z appears twice in the header; keep one"),
    ("x,y,z,r,g,b,a,a,z\n0,0,0.5,1,1,1,1,1,1\n", "columns z, a each appear more than once in the header"),
    ("x,y,z,r,g,b,a,\n0,0,0.5,1,1,1,1,\n", "empty column name (field 8"),
    ("x,y,z,r,g,b,a\n0,0,0.5,1,1,1,1,9,9\n", "f.csv:2: malformed CSV: 9 fields where the header has 7"),
    ("x,y,z,r,g,b,a\n0,0,0.5,1,1,1,1\n0,0,0.5,1,1,1,1,9\n", "f.csv:3: malformed CSV: 8 fields where the header has 7"),
    ('x,y,z,r,g,b,a\n0,0,"0.\n5",1,1,1,1\n0,0,0.5,1,1,1,1,9\n', "f.csv:4: malformed CSV: 8 fields"),
    ("", "not a CSV file"),
])
def test_bad_csv_fails_with_one_line(tmp_path, body, expect):
    path = write(tmp_path, body)
    with pytest.raises(TraceError) as exc:
        read_csv_trace(path, 4, 4)
    assert expect in str(exc.value)
    assert "\n" not in str(exc.value) and "np." not in str(exc.value) and "z.1" not in str(exc.value)


def test_extra_field_in_a_later_chunk_names_its_line(tmp_path, monkeypatch):
    import gpusim.trace_csv as mod
    monkeypatch.setattr(mod, "CHUNK_ROWS", 3)
    path = write(tmp_path, "x,y,z,r,g,b,a\n" + "0,0,0.5,1,1,1,1\n" * 7 + "0,0,0.5,1,1,1,1,9\n")
    with pytest.raises(TraceError, match=r"f\.csv:9: malformed CSV: 8 fields where the header has 7"):
        read_csv_trace(path, 4, 4)


@pytest.mark.parametrize("kind", ["directory", "fifo", "device"])
def test_a_csv_that_is_not_a_regular_file_says_what_it_is(tmp_path, kind):
    import os
    path = tmp_path / "f.csv"
    if kind == "directory":
        path.mkdir()
        expect = "f.csv: is a directory, not a CSV file"
    elif kind == "fifo":
        os.mkfifo(path)                         # opening it would wait for a writer for ever
        expect = "f.csv: is a FIFO (named pipe), not a regular file"
    else:
        path = "/dev/zero"                      # reading it never ends
        expect = "/dev/zero: is a device, not a regular file"
    with pytest.raises(TraceError) as exc:
        read_csv_trace(path, 4, 4)
    assert expect in str(exc.value) and "no such" not in str(exc.value)
