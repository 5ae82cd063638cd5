"""What a report needs of a results directory's tables, checked before anything is drawn.

``gpusim run`` writes tables that pass. A table that was edited, cut down into another valid
Parquet file, or written by something else fails here in one line naming the file, the column
and the fix, instead of deep inside pandas or matplotlib (and before any output is written).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd

from gpusim.errors import GpusimError
from gpusim.experiment.store import FIGURE_COLUMNS, LEAD_COLUMNS, STATS_COLUMNS

STATUSES = ("ok", "failed", "skipped", "pending")
#: columns of text (``error`` may be empty)
TEXT_COLUMNS = ("run", "status", "error", "scene", "trace", "gpu", "fidelity", "scheme", "variant")
#: columns of whole numbers every row has
WHOLE_COLUMNS = ("index", "width", "height")
#: figures that may be +inf (an exact image)
MAY_BE_INFINITE = ("psnr",)


def check_tables(root: Path, results: pd.DataFrame, stats: pd.DataFrame) -> None:
    """Raise a one-line :class:`GpusimError` unless ``results`` and ``stats`` (read from ``root``) hold the
    columns the report reads, of the kinds it reads, with values a run can give."""
    fix = f"run the experiment into it again (gpusim run {root / 'resolved.toml'} -o {root}) to rewrite them"
    where = root / "results.parquet"

    def fail(path: Path, problem: str) -> None:
        raise GpusimError(f"{path}: {problem}; not a results table gpusim wrote: {fix}")

    missing = [c for c in (*LEAD_COLUMNS, *FIGURE_COLUMNS) if c not in results]
    if missing:
        fail(where, f"no column {', '.join(repr(c) for c in missing[:4])}"
                    + (f" (and {len(missing) - 4} more)" if len(missing) > 4 else ""))
    for c in TEXT_COLUMNS:
        values = results[c]
        wrong = [v for v in values if not (isinstance(v, str) or (c == "error" and _missing(v)))]
        if wrong:
            fail(where, f"column '{c}' holds {wrong[0]!r} where text belongs")
    odd = sorted(set(results["status"]) - set(STATUSES))
    if odd:
        fail(where, f"column 'status' holds {odd[0]!r} (valid: {', '.join(STATUSES)})")
    for c in (*WHOLE_COLUMNS, *FIGURE_COLUMNS):
        values = _numbers(results[c])
        if values is None:
            fail(where, f"column '{c}' holds {_first_text(results[c])!r} where numbers belong")
        if c in WHOLE_COLUMNS:
            bad = np.isnan(values) | (values != np.round(values)) | (values < (0 if c == "index" else 1))
        else:
            bad = ~np.isnan(values) & ((values < 0) | (np.isinf(values) & (c not in MAY_BE_INFINITE)))
        if bad.any():
            row = int(np.flatnonzero(bad)[0])
            fail(where, f"column '{c}' holds {float(values[row])!r} (row {row}), which no run gives")
    where = root / "stats.parquet"
    missing = [c for c in STATS_COLUMNS if c not in stats]
    if missing:
        fail(where, f"no column {', '.join(repr(c) for c in missing)}")
    if _numbers(stats["value"]) is None:
        fail(where, f"column 'value' holds {_first_text(stats['value'])!r} where numbers belong")


def _missing(value) -> bool:
    return value is None or (isinstance(value, float) and np.isnan(value)) or value is pd.NA


def _numbers(column: pd.Series) -> np.ndarray | None:
    """The column as floats (NaN where missing), or None when it holds anything but numbers."""
    if pd.api.types.is_bool_dtype(column) or not pd.api.types.is_numeric_dtype(column):
        return None if column.notna().any() else np.full(len(column), np.nan)
    return column.to_numpy(dtype="float64", na_value=np.nan)


def _first_text(column: pd.Series):
    return next(v for v in column if not _missing(v))
