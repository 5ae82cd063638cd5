"""tests/conftest.py's SLOW_FIRST names test modules that exist: a renamed one would silently fall back to the
end of the order, where it runs alone after the other worker is done."""

from __future__ import annotations

from pathlib import Path

from conftest import SLOW_FIRST


def test_every_slow_module_named_first_exists():
    here = Path(__file__).parent
    assert [name for name in SLOW_FIRST if not (here / name).is_file()] == []
    assert len(set(SLOW_FIRST)) == len(SLOW_FIRST)


def test_the_collection_runs_them_first(request):
    order = list(dict.fromkeys(item.path.name for item in request.session.items))
    present = [name for name in SLOW_FIRST if name in order]
    assert order[:len(present)] == present
