"""A stop request that outlives a lost KeyboardInterrupt.

A signal handler that raises KeyboardInterrupt can lose it: when the signal
lands while Python runs a finalizer (``__del__``, a weakref callback during a
garbage collection), the exception is printed as "ignored" and the program runs
on. :func:`handle` therefore records the signal before it raises, and the long
loops (a sweep's task loop, its wait for workers) call :func:`check`, which
raises again while a stop is pending. The record belongs to one command:
:func:`clear` starts and ends each.
"""

from __future__ import annotations

import signal

_pending: list[int] = []               # the signals received since clear(); a list so handlers can append


def handle(signum: int, frame) -> None:
    """A signal handler: record the stop, then raise KeyboardInterrupt as Ctrl-C does."""
    _pending.append(signum)
    raise KeyboardInterrupt


def check() -> None:
    """Raise KeyboardInterrupt if a stop was requested (and perhaps lost) since :func:`clear`."""
    if _pending:
        raise KeyboardInterrupt(f"stopped by {signal.Signals(_pending[0]).name}")


def pending() -> bool:
    """Whether a stop was requested since :func:`clear`."""
    return bool(_pending)


def clear() -> None:
    """Forget the stops requested so far (a new command starts)."""
    _pending.clear()
