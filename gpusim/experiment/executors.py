"""Where a sweep's tasks run: in this process, in local worker processes, or on a dask.distributed cluster.

Each executor takes (task, trace) pairs and yields ``(task, outcomes)`` as
tasks finish, in completion order. The same :func:`gpusim.experiment.execute.execute`
runs in all three; the caller writes every file, so workers never need the
output directory.
"""

from __future__ import annotations

import multiprocessing
import os
import signal
import socket
import threading
import time
from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, wait
from concurrent.futures.process import BrokenProcessPool
from typing import Iterator

from gpusim import interrupt
from gpusim.errors import GpusimError
from gpusim.experiment.execute import Outcome, Task, execute


STOP_POLL_S = 0.5       # s; how often a sweep waiting on its workers looks for a stop request


def _worker_init(parent: int) -> None:
    """In a worker: leave Ctrl-C to the sweep's process (it stops the workers), and exit when that process
    is gone (killed with SIGKILL) instead of lingering."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)

    def watch():
        while True:
            if os.getppid() != parent:
                os._exit(1)
            time.sleep(0.5)
    threading.Thread(target=watch, daemon=True, name="gpusim-parent-watch").start()


class InlineExecutor:
    """Tasks one after another in this process (``--workers 1``)."""

    def __init__(self, traces: dict[str, tuple]):
        self.traces = traces                 # trace path -> (trace, reference)

    def run(self, tasks: list[Task]) -> Iterator[tuple[Task, list[Outcome]]]:
        for task in tasks:
            trace, reference = self.traces.get(task.trace_path, (None, None))
            yield task, execute(task, trace, reference)

    def close(self) -> None:
        pass


class LocalExecutor:
    """Tasks in ``workers`` spawned processes; each loads its trace from the file the sweep wrote."""

    def __init__(self, workers: int):
        self.pool = ProcessPoolExecutor(max_workers=workers, mp_context=multiprocessing.get_context("spawn"),
                                        initializer=_worker_init, initargs=(os.getpid(),))

    def run(self, tasks: list[Task]) -> Iterator[tuple[Task, list[Outcome]]]:
        # workers start during the submissions: they inherit an ignored SIGINT, so a Ctrl-C while they start
        # up stops the sweep here (which stops them) instead of printing their tracebacks
        previous = signal.signal(signal.SIGINT, signal.SIG_IGN)
        try:
            pending = {self.pool.submit(execute, task): task for task in tasks}
        finally:
            signal.signal(signal.SIGINT, previous)
        while pending:
            done, _ = wait(pending, timeout=STOP_POLL_S, return_when=FIRST_COMPLETED)
            interrupt.check()                # a SIGTERM whose KeyboardInterrupt was lost still stops the sweep
            for future in done:
                task = pending.pop(future)
                try:
                    yield task, future.result()
                except BrokenProcessPool:
                    raise GpusimError("a worker process died (killed, perhaps for lack of memory); finished runs "
                                      "are kept: rerun with fewer --workers, a smaller size or a lower fidelity") \
                        from None

    def close(self) -> None:
        self.pool.shutdown(wait=False, cancel_futures=True)
        for child in multiprocessing.active_children():
            child.terminate()
        for child in multiprocessing.active_children():
            child.join(timeout=5)


def probe(address: str) -> None:
    """Fail at once, in one line, when nothing listens at a tcp:// scheduler address (dask would retry
    until its timeout)."""
    if not address.startswith("tcp://"):
        return
    host, _, port = address.removeprefix("tcp://").rpartition(":")
    try:
        socket.create_connection((host.strip("[]"), int(port)), timeout=5).close()
    except (OSError, ValueError) as exc:
        raise GpusimError(f"--cluster {address}: cannot reach a dask scheduler there ({exc}); start one with "
                          "'dask scheduler' and workers with 'dask worker ADDRESS', or drop --cluster") from None


class DaskExecutor:
    """Tasks on a dask.distributed cluster (``--cluster tcp://HOST:PORT``). Each trace is scattered to the
    workers once, so they need neither this machine's files nor a shared filesystem (only the same gpusim)."""

    def __init__(self, address: str, traces: dict[str, tuple]):
        try:
            from distributed import Client
        except ImportError:                                      # pragma: no cover - a declared dependency
            raise GpusimError("--cluster needs dask.distributed: pip install 'distributed'") from None
        probe(address)
        try:
            self.client = Client(address, timeout="15s")
        except (OSError, TimeoutError, ValueError) as exc:
            raise GpusimError(f"--cluster {address}: cannot reach a dask scheduler there ({exc}); start one "
                              "with 'dask scheduler' and workers with 'dask worker ADDRESS', or drop --cluster") \
                from None
        self.traces = traces
        self.remote: dict[str, object] = {}

    def run(self, tasks: list[Task]) -> Iterator[tuple[Task, list[Outcome]]]:
        from distributed import as_completed
        futures = {}
        for task in tasks:
            if task.trace_path not in self.remote:
                trace, reference = self.traces[task.trace_path]
                self.remote[task.trace_path] = (self.client.scatter(trace, broadcast=True),
                                                self.client.scatter(reference, broadcast=True))
            trace, reference = self.remote[task.trace_path]
            futures[self.client.submit(execute, task, trace, reference, pure=False)] = task
        for future in as_completed(list(futures)):
            interrupt.check()
            yield futures[future], future.result()

    def close(self) -> None:
        self.client.close()


def make_executor(workers: int, cluster: str | None, traces: dict[str, tuple]):
    """``traces`` maps a saved trace's path to (trace, exact reference) for the executors that hand them over
    in memory; local worker processes read both from the files."""
    if cluster:
        return DaskExecutor(cluster, traces)
    if workers <= 1:
        return InlineExecutor(traces)
    return LocalExecutor(workers)
