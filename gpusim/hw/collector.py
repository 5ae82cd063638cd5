"""Python's cyclic garbage collector paused while a timing level runs.

The levels make many short-lived containers (events, pass records) and no reference cycles that must be freed
before they end; the collector's passes over every object of the process (numpy's, numba's, pandas' modules
among them) would then cost a large share of the run. The previous state is restored on the way out.
"""

from __future__ import annotations

import gc
from contextlib import contextmanager


@contextmanager
def collector_paused():
    collecting = gc.isenabled()
    gc.disable()
    try:
        yield
    finally:
        if collecting:
            gc.enable()
