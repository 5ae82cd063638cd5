"""Importing fragment traces from CSV.

Format: a header line ``x,y,z,r,g,b,a`` with optional ``prim`` and ``opaque``
columns (any order), then one row per fragment in submission order. ``x`` and
``y`` are integer pixel coordinates (OpenGL window convention, row 0 at the
bottom); ``z`` is window depth in [0, 1]; colour and alpha are floats in [0, 1].
A missing ``prim`` column makes each row its own primitive; a missing
``opaque`` column makes every fragment transparent. ``opaque`` accepts 0/1 or
true/false.

The file is read in chunks into arrays allocated once for the whole trace, so
memory stays near the size of the finished trace.
"""

from __future__ import annotations

import csv
import os
import warnings
from pathlib import Path

import numpy as np
import pandas as pd

from gpusim.errors import TraceError
from gpusim.trace import DTYPES, FragmentTrace
from gpusim.trace_io import check_input_file

REQUIRED = ("x", "y", "z", "r", "g", "b", "a")
OPTIONAL = ("prim", "opaque")
CHUNK_ROWS = 1 << 20


def _count_rows(path: Path) -> int:
    """Number of data rows (lines after the header), counted in binary blocks. A line ends, as pandas reads
    it, in LF, CRLF or a lone CR (old Mac files)."""
    lines, last = 0, b"\n"
    with open(path, "rb") as handle:
        while block := handle.read(1 << 24):
            lines += block.count(b"\n") + block.count(b"\r") - block.count(b"\r\n")
            lines -= last == b"\r" and block[:1] == b"\n"        # a CRLF split between two blocks
            last = block[-1:]
    if last not in (b"\n", b"\r"):
        lines += 1
    return max(lines - 1, 0)


def _shown(value) -> str:
    """A cell as the message shows it: numbers plain (2, not numpy's np.int64(2)), text quoted."""
    return repr(value.item() if isinstance(value, np.generic) else value)


def _field_count_error(path: Path, fields: int) -> tuple[int, int] | None:
    """The (line, field count) of the first row with more fields than the header's ``fields``, read with
    Python's csv module (quotes and CR/LF/CRLF line ends as pandas reads them); None if every row fits."""
    try:
        with open(path, newline="", encoding="utf-8", errors="replace") as handle:
            reader = csv.reader(handle, skipinitialspace=True)
            next(reader, None)
            for row in reader:
                if row and len(row) > fields:
                    return reader.line_num, len(row)
    except csv.Error:
        return None
    return None


def _numeric(chunk: pd.DataFrame, column: str, path: Path, first_row: int) -> np.ndarray:
    series = chunk[column]
    if pd.api.types.is_bool_dtype(series):     # pandas reads a column of true/false as booleans: not numbers
        series = series.astype(str)
    if not pd.api.types.is_numeric_dtype(series):
        coerced = pd.to_numeric(series, errors="coerce")
        bad = np.flatnonzero(coerced.isna().to_numpy())
        if bad.size:
            line = first_row + int(bad[0]) + 2
            raise TraceError(f"{path}:{line}: column '{column}' holds {_shown(series.iloc[bad[0]])}, "
                             "not a number; fix that row")
        series = coerced
    values = series.to_numpy(dtype=np.float64, na_value=np.nan)
    missing = np.flatnonzero(np.isnan(values))
    if missing.size:
        line = first_row + int(missing[0]) + 2
        raise TraceError(f"{path}:{line}: column '{column}' is empty or NaN; every fragment needs "
                         "a number there")
    return values


def _integers(values: np.ndarray, column: str, limit: int, path: Path, first_row: int,
              side: str | None = None) -> np.ndarray:
    """``values`` checked to be integers in 0..limit-1; ``side`` ("width", "height") marks a pixel coordinate."""
    fraction = values != np.floor(values)
    bad = np.flatnonzero(fraction | (values < 0) | (values >= limit))
    if bad.size:
        i = int(bad[0])
        value = values[i]
        where = f"{path}:{first_row + i + 2}: {column}={value:g}"
        if fraction[i] or side is None:
            raise TraceError(f"{where} is not an integer in 0..{limit - 1}; fix the row")
        raise TraceError(f"{where} puts the pixel outside the screen: coordinates must be 0 <= {column} < {limit} "
                         f"(the screen {side}); fix the row" + (" or give a larger --size" if value >= limit else ""))
    return values


def _opaque(chunk: pd.DataFrame, path: Path, first_row: int) -> np.ndarray:
    series = chunk["opaque"]
    if series.dtype == bool:
        return series.to_numpy()
    text = series.astype(str).str.strip().str.lower()
    mapped = text.map({"1": True, "0": False, "true": True, "false": False,
                       "1.0": True, "0.0": False})
    bad = np.flatnonzero(mapped.isna().to_numpy())
    if bad.size:
        line = first_row + int(bad[0]) + 2
        raise TraceError(f"{path}:{line}: opaque={_shown(series.iloc[bad[0]])} is not 0/1 or true/false; "
                         "fix the row")
    return mapped.to_numpy(dtype=bool)


def _fill(path: Path, columns: list[str], n: int, width: int, height: int, out: dict) -> int:
    """Read the CSV chunk by chunk into the preallocated ``out`` arrays; returns the row count."""
    pos = 0
    try:
        reader = pd.read_csv(path, chunksize=CHUNK_ROWS, skipinitialspace=True, index_col=False,
                             skip_blank_lines=False, names=columns, header=0)
        for chunk in reader:
            rows = len(chunk)
            if pos + rows > n:
                raise TraceError(f"{path}: the file changed while it was read; try again")
            sl = slice(pos, pos + rows)
            out["x"][sl] = _integers(_numeric(chunk, "x", path, pos), "x", width, path, pos, "width")
            out["y"][sl] = _integers(_numeric(chunk, "y", path, pos), "y", height, path, pos, "height")
            out["z"][sl] = _numeric(chunk, "z", path, pos)
            for i, c in enumerate("rgba"):
                out["rgba"][sl, i] = _numeric(chunk, c, path, pos)
            if "prim" in columns:
                prim = _numeric(chunk, "prim", path, pos)
                out["prim"][sl] = _integers(prim, "prim", 2**32, path, pos)
            else:
                out["prim"][sl] = np.arange(pos, pos + rows, dtype=np.uint32)
            out["opaque"][sl] = _opaque(chunk, path, pos) if "opaque" in columns else False
            pos += rows
    except (pd.errors.ParserError, pd.errors.ParserWarning) as exc:
        found = _field_count_error(path, len(columns))
        if found:                         # pandas' own text may lack the line (an extra field in the first row)
            line, fields = found
            raise TraceError(f"{path}:{line}: malformed CSV: {fields} fields where the header has {len(columns)}; "
                             f"give every row exactly {len(columns)} fields") from None
        raise TraceError(f"{path}: malformed CSV ({str(exc).strip().splitlines()[0]}); every row needs "
                         f"exactly {len(columns)} fields") from None
    except UnicodeDecodeError as exc:
        raise TraceError(f"{path}: holds bytes that are not UTF-8 text ({exc.reason}); save the CSV as UTF-8 "
                         f"text") from None
    return pos


def read_csv_trace(path: str | os.PathLike, width: int, height: int,
                   meta: dict | None = None) -> FragmentTrace:
    """Read a CSV fragment list (format in the module docstring) into a FragmentTrace."""
    path = Path(path)
    check_input_file(path, "CSV file", "check the path")
    try:                                  # the header as data: pandas would rename a repeated name (z -> z.1)
        header = pd.read_csv(path, header=None, nrows=1, dtype=str, keep_default_na=False).iloc[0]
    except (pd.errors.EmptyDataError, UnicodeDecodeError) as exc:
        raise TraceError(f"{path}: not a CSV file with a header line x,y,z,r,g,b,a ({exc})") from None
    except pd.errors.ParserError as exc:   # e.g. a quote left open: pandas reads past the header to find its end
        raise TraceError(f"{path}: malformed CSV ({str(exc).strip().splitlines()[0]}); close every quote "
                         f"and give every row the header's fields") from None
    columns = [str(c).strip() for c in header]
    repeated = list(dict.fromkeys(c for c in columns if columns.count(c) > 1))
    if repeated:
        if len(repeated) == 1:
            times = columns.count(repeated[0])
            which = f"column {repeated[0]} appears {'twice' if times == 2 else f'{times} times'}"
        else:
            which = f"columns {', '.join(repeated)} each appear more than once"
        raise TraceError(f"{path}: {which} in the header; keep one of each")
    if "" in columns:
        raise TraceError(f"{path}: the header has an empty column name (field {columns.index('') + 1}; a "
                         "trailing comma?); name every column: x,y,z,r,g,b,a (optional: prim, opaque)")
    missing = [c for c in REQUIRED if c not in columns]
    if missing:
        raise TraceError(f"{path}: missing column(s) {', '.join(missing)}; the header must hold "
                         f"x,y,z,r,g,b,a (optional: prim, opaque)")
    unknown = [c for c in columns if c not in REQUIRED + OPTIONAL]
    if unknown:
        raise TraceError(f"{path}: unknown column(s) {', '.join(unknown)}; valid columns are "
                         f"{', '.join(REQUIRED + OPTIONAL)}")

    n = _count_rows(path)
    out = {name: np.empty((n, 4) if name == "rgba" else n, dtype=dt) for name, dt in DTYPES.items()}
    with warnings.catch_warnings():
        warnings.simplefilter("error", pd.errors.ParserWarning)  # extra fields: an error, not a warning
        pos = _fill(path, columns, n, width, height, out)
    if pos != n:  # fewer rows than lines (a quoted field held a newline): trim the views
        out = {k: v[:pos] for k, v in out.items()}
    meta = {"generator": "gpusim trace --from-csv", "source_csv": path.name, **(meta or {})}
    try:
        return FragmentTrace(**out, width=width, height=height, meta=meta, source=str(path))
    except TraceError as exc:  # name the CSV line, not only the fragment index
        if exc.fragment is None:
            raise
        raise TraceError(f"{path}:{exc.fragment + 2}: {exc.problem}") from None
