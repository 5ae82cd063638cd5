"""Helpers shared by the CLI commands."""

from __future__ import annotations

import argparse
import json
import os
import sys
import tempfile
from pathlib import Path

from gpusim.errors import GpusimError
from gpusim.replay import jsonable
from gpusim.text import counted  # noqa: F401  (the commands' wording, re-exported)
from gpusim.trace import MAX_SCREEN_SIDE


def parse_size(text: str) -> tuple[int, int]:
    """``WxH`` -> (width, height) in pixels."""
    try:
        w, h = (int(v) for v in text.lower().split("x"))
    except ValueError:
        raise GpusimError(f"--size {text}: expected WIDTHxHEIGHT in pixels, e.g. --size 512x512") from None
    if not (1 <= w <= MAX_SCREEN_SIDE and 1 <= h <= MAX_SCREEN_SIDE):
        raise GpusimError(f"--size {text}: each side must lie in 1..{MAX_SCREEN_SIDE} pixels")
    return w, h


def check_output(text: str, folder: bool = False) -> Path:
    """The ``-o`` path (a file, or with ``folder`` a folder), checked before any work so that a path that
    cannot be written fails at once with one line; creates nothing."""
    path = Path(text)
    kind = "folder" if folder else "file"
    if path.exists() and path.is_dir() != folder:
        raise GpusimError(f"-o {text}: that is a {'file' if folder else 'folder'}, not a {kind}; "
                          f"give a {kind} path (a missing folder is created)")
    parent = next((p for p in ((path, *path.parents) if folder else path.parents) if p.exists()), Path("."))
    if not parent.is_dir():
        raise GpusimError(f"-o {text}: {parent} is a file, so nothing can be written under it; "
                          f"give a {kind} path inside a folder")
    try:
        fd, probe = tempfile.mkstemp(prefix=".gpusim-probe.", dir=parent)
        os.close(fd)
        os.unlink(probe)
    except OSError as exc:
        raise GpusimError(f"-o {text}: cannot write in {parent} ({exc.strerror or exc}); "
                          f"choose a folder you can write to") from None
    return path


def print_json(obj) -> None:
    """One JSON object on stdout; infinities become the strings "inf"/"-inf"."""
    json.dump(jsonable(obj), sys.stdout, indent=2, sort_keys=False)
    sys.stdout.write("\n")


class Parser(argparse.ArgumentParser):
    """argparse that reports usage mistakes as one line and exit status 2."""

    def error(self, message: str):  # noqa: D401 - argparse API
        self.exit(2, f"{self.prog}: error: {message} (see '{self.prog} --help')\n")
