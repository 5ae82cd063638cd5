"""Saving and loading fragment traces as ``.npz`` files.

Layout (format version 1): one uncompressed zip member per array of
:data:`gpusim.trace.DTYPES`, plus ``format_version`` (int64 scalar), ``width``,
``height`` (int64 scalars) and ``meta_json`` (a unicode scalar holding the
metadata as JSON). Pickle is never used. Each array is read straight into its
final numpy buffer, so loading needs the trace's size in memory once.
"""

from __future__ import annotations

import json
import os
import stat
import tokenize
import zipfile
import zlib
from pathlib import Path

import numpy as np

from gpusim.atomic_io import atomic_output
from gpusim.errors import TraceError
from gpusim.trace import DTYPES, FragmentTrace

FORMAT_VERSION = 1
_SCALARS = ("format_version", "width", "height", "meta_json")


def check_input_file(path: Path, kind: str, missing: str) -> None:
    """Refuse, in one line, an input ``path`` that is missing (``missing`` says what to do), a directory,
    or not a regular file (a FIFO, a device such as /dev/zero, a socket: reading one may never end)."""
    try:
        mode = path.stat().st_mode
    except (FileNotFoundError, NotADirectoryError):
        raise TraceError(f"{path}: no such {kind}; {missing}") from None
    except OSError as exc:
        raise TraceError(f"{path}: cannot read it ({exc.strerror or exc}); check the path") from None
    if stat.S_ISDIR(mode):
        raise TraceError(f"{path}: is a directory, not a {kind}; name the file")
    if not stat.S_ISREG(mode):
        what = ("a FIFO (named pipe)" if stat.S_ISFIFO(mode) else "a socket" if stat.S_ISSOCK(mode)
                else "a device" if stat.S_ISCHR(mode) or stat.S_ISBLK(mode) else "a special file")
        raise TraceError(f"{path}: is {what}, not a regular file; give a {kind} saved on disk")


def save_trace(trace: FragmentTrace, path: str | os.PathLike) -> Path:
    """Write ``trace`` to ``path`` (``.npz``) atomically; returns the path."""
    path = Path(path)
    if path.suffix != ".npz":
        raise TraceError(f"{path}: a trace file must end in .npz; name the output like trace.npz")
    arrays = {name: getattr(trace, name) for name in DTYPES}
    with atomic_output(path) as handle:
        np.savez(handle, format_version=np.int64(FORMAT_VERSION), width=np.int64(trace.width),
                 height=np.int64(trace.height), meta_json=np.str_(json.dumps(trace.meta)),
                 **arrays)
    return path


def load_trace(path: str | os.PathLike) -> FragmentTrace:
    """Load and validate a trace; raise :class:`TraceError` with one clear line on any problem."""
    path = Path(path)
    fix = "re-create it with 'gpusim trace'"
    check_input_file(path, "trace file", "check the path or create one with 'gpusim trace'")
    with open(path, "rb") as handle:
        if handle.read(4) != b"PK\x03\x04":
            raise TraceError(f"{path}: not a gpusim trace (.npz) file; give a trace written by 'gpusim trace'")
    try:
        with np.load(path, allow_pickle=False) as npz:
            members = set(npz.files)
            for name in (*_SCALARS, *DTYPES):
                if name not in members:
                    raise TraceError(f"{path}: not a gpusim trace, array '{name}' is missing; {fix}")
            version = int(npz["format_version"])
            if version > FORMAT_VERSION:
                raise TraceError(f"{path}: trace format version {version} is newer than this gpusim "
                                 f"reads ({FORMAT_VERSION}); upgrade gpusim")
            if version < 1:
                raise TraceError(f"{path}: invalid trace format version {version}; {fix}")
            dims = [npz["width"], npz["height"]]
            if any(d.shape != () or d.dtype.kind not in "iu" for d in dims):
                raise TraceError(f"{path}: the screen width and height are not integers "
                                 f"({dims[0]!r:.40}, {dims[1]!r:.40}); {fix}")
            width, height = (int(d) for d in dims)
            meta = json.loads(str(npz["meta_json"]))
            arrays = {name: npz[name] for name in DTYPES}
    except TraceError:
        raise
    except (zipfile.BadZipFile, zlib.error, EOFError, NotImplementedError, RuntimeError) as exc:
        # NotImplementedError: a compression method zipfile lacks; RuntimeError: a member marked encrypted,
        # or metadata nested too deep for the JSON parser (RecursionError)
        raise TraceError(f"{path}: truncated or corrupted trace file ({exc}); {fix}") from None
    except tokenize.TokenError:        # numpy tokenizes an array header it cannot parse
        raise TraceError(f"{path}: corrupted trace file (an array header is malformed); {fix}") from None
    except MemoryError:                # an array header declares a size beyond memory
        raise TraceError(f"{path}: an array in the file declares more data than memory holds; the file is "
                         f"corrupted, or too large for this machine") from None
    except (ValueError, OSError, json.JSONDecodeError, TypeError) as exc:
        msg = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
        raise TraceError(f"{path}: unreadable trace file ({msg}); {fix}") from None
    if not isinstance(meta, dict):
        raise TraceError(f"{path}: trace metadata is not a JSON object; {fix}")
    return FragmentTrace(**arrays, width=width, height=height, meta=meta, source=str(path))
