"""Wording shared by the command line and the reports."""

from __future__ import annotations


def counted(n: int, word: str, plural: str | None = None) -> str:
    """``n`` with thousands separators and ``word`` in the singular for one, else the plural
    (``word`` + "s" unless given): ``counted(1, "pixel")`` is "1 pixel", ``counted(2, "pixel")`` "2 pixels"."""
    return f"{n:,} {word if n == 1 else plural or word + 's'}"
