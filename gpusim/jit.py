"""Compiling a kernel with numba, where numba is installed.

numba is an optional speed-up: every compiled kernel has a numpy path that gives the same
results bit for bit, taken when numba cannot be imported or ``NUMBA_DISABLE_JIT`` is set.
Kernels are compiled without ``fastmath`` (LLVM then contracts no multiply-add and reorders
no float operation, so float32 and float64 results equal numpy's), with numpy's IEEE error
model (a division by zero gives inf or nan), and cached on disk where numba finds a writable
place (``NUMBA_CACHE_DIR`` chooses one); otherwise compiled in each process.
"""

from __future__ import annotations

from typing import Callable


def numba_usable() -> bool:
    """Whether numba imports and is not disabled (``NUMBA_DISABLE_JIT``)."""
    try:
        import numba
    except ImportError:
        return False
    return not numba.config.DISABLE_JIT


def njit(func: Callable) -> Callable | None:
    """``func`` compiled with numba, or None when numba is not usable."""
    if not numba_usable():
        return None
    import numba
    options = {"error_model": "numpy", "nogil": True}
    func = getattr(func, "py_func", func)      # compiled before (a test reset a kernel cache)
    try:
        return numba.njit(cache=True, **options)(func)
    except RuntimeError:     # "cannot cache function ...: no locator available"
        return numba.njit(**options)(func)


def compiled_once(cache: list, func: Callable) -> Callable | None:
    """``func`` compiled with :func:`njit` (or None), made on the first call and kept in ``cache``, a module's
    one-element list (a test sets it to ``[None]`` to take the numpy path)."""
    if not cache:
        cache.append(njit(func))
    return cache[0]


def _ping(value: int) -> int:
    return value + 1


_STARTED: list = []     # [True] once :func:`start` has run in this process


def start() -> None:
    """Start numba in this process, where it is usable: its import and its compiler (a one-line kernel, from
    numba's cache where it has one), about 0.2 s. A process's first compiled kernel then costs its own cache
    load only (a few ms), not numba's start-up. An experiment's task calls it before anything it times, so
    that start-up lands in no run's wall time."""
    if _STARTED:
        return
    _STARTED.append(True)
    kernel = njit(_ping)
    if kernel is not None:
        kernel(1)
