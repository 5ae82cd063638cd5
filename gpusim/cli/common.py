"""Helpers shared by the CLI commands."""

from __future__ import annotations

import argparse
import json
import sys

from gpusim.errors import GpusimError
from gpusim.replay import jsonable
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


def print_json(obj) -> None:
    """One JSON object on stdout; infinities become the strings "inf"/"-inf"."""
    json.dump(jsonable(obj), sys.stdout, indent=2, sort_keys=False)
    sys.stdout.write("\n")


class Parser(argparse.ArgumentParser):
    """argparse that reports usage mistakes as one line and exit status 2."""

    def error(self, message: str):  # noqa: D401 - argparse API
        self.exit(2, f"{self.prog}: error: {message} (see '{self.prog} --help')\n")
