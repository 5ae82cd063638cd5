"""The timing model gives the golden table: a regression guard of the whole model.

Every scheme (and the variants that reach the scoreboard, the blender and the
flushes) on two scenes, three GPUs and three fidelity levels: cycles, per-pass
cycles, analytic bounds, RMW hazards, and every unit's busy cycles, requests
and counters, exactly (tests/timing_golden.py records and collects them). A
deliberate change of the model regenerates the fixture and says in its commit
what changed and why; any other difference fails here.
"""

from __future__ import annotations

import json

import pytest

from timing_golden import FIXTURE, collect

FIELDS = ("cycles", "passes", "rmw_hazards", "rmw_hazard_pixels", "bounds", "error")
@pytest.fixture(scope="module")
def tables():
    return json.loads(FIXTURE.read_text()), collect()


def test_the_same_rows(tables):
    old, new = tables
    assert sorted(new) == sorted(old)


@pytest.mark.parametrize("field", FIELDS)
def test_cycles_passes_bounds_and_hazards_are_identical(tables, field):
    old, new = tables
    differ = [k for k in old if old[k].get(field) != new[k].get(field)]
    assert not differ, f"{len(differ)} rows differ in {field}, first {differ[0]}: " \
                       f"{old[differ[0]].get(field)} -> {new[differ[0]].get(field)}"


def test_unit_figures_are_identical(tables):
    old, new = tables
    problems = [f"{key}: {unit}.{stat} {value} -> {new[key]['units'].get(unit, {}).get(stat)}"
                for key, row in old.items() for unit, stats in row.get("units", {}).items()
                for stat, value in stats.items() if new[key]["units"].get(unit, {}).get(stat) != value]
    assert not problems, f"{len(problems)} differences, first: {problems[:3]}"
