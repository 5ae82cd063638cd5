"""Atomic output: a file is either absent or complete, never partial.

Outputs are written to a temporary file beside the target and moved into place
with :func:`os.replace`, so an interrupted run leaves the previous file (or no
file) and never a truncated one.
"""

from __future__ import annotations

import contextlib
import os
import shutil
import tempfile
from pathlib import Path
from typing import IO, Iterator


def _mode(full: int) -> int:
    """``full`` (0o666 for a file, 0o777 for a folder) less the process's umask: the mode ``open`` gives."""
    mask = os.umask(0)
    os.umask(mask)
    return full & ~mask


@contextlib.contextmanager
def atomic_output(path: str | os.PathLike, mode: str = "wb") -> Iterator[IO]:
    """Open a temporary file beside ``path``; on success move it onto ``path``.

    On any exception (KeyboardInterrupt included) the temporary file is removed
    and ``path`` is left untouched.
    """
    target = Path(path)
    target.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{target.name}.", suffix=".tmp", dir=target.parent)
    os.chmod(tmp, _mode(0o666))            # as open() would make it (mkstemp makes it private)
    try:
        with os.fdopen(fd, mode) as handle:
            yield handle
            handle.flush()
            os.fsync(handle.fileno())
        os.replace(tmp, target)
    except BaseException:
        with contextlib.suppress(FileNotFoundError):
            os.unlink(tmp)
        raise


def write_text_atomic(path: str | os.PathLike, text: str) -> None:
    """Write ``text`` (UTF-8) to ``path`` atomically."""
    with atomic_output(path, "w") as handle:
        handle.write(text)


@contextlib.contextmanager
def atomic_folder(path: str | os.PathLike) -> Iterator[Path]:
    """A temporary folder beside ``path`` to write a set of outputs into; on success they all move into
    ``path`` (created if absent), on any exception the folder is removed and ``path`` left untouched. A
    folder among the outputs (a report's ``figures/``) replaces the one of that name in ``path`` whole."""
    target = Path(path)
    target.parent.mkdir(parents=True, exist_ok=True)
    tmp = Path(tempfile.mkdtemp(prefix=f".{target.name}.", suffix=".tmp", dir=target.parent))
    try:
        yield tmp
        if target.is_dir():
            for item in list(tmp.iterdir()):
                dest = target / item.name
                if item.is_dir() and dest.is_dir():          # os.replace cannot move onto a folder with files
                    os.replace(dest, tmp / f".{item.name}.old")
                os.replace(item, dest)
            shutil.rmtree(tmp)
        else:
            os.chmod(tmp, _mode(0o777))        # an ordinary folder (mkdtemp makes it private)
            os.replace(tmp, target)
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
