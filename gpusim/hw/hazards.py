"""Read-modify-write hazards of unsynchronised RMW schemes (seed 004 section 3.2).

A fragment thread's RMW window runs from the cycle its first ``rmw_read`` is
served at memory to the cycle its last ``rmw_write`` lands. Taking a pixel's
fragments in the order their reads were served, a fragment whose read comes
before the write of an earlier reader has landed reads an obsolete value: a
*hazard*. The scheme's own program is then replayed on the values in event
order (``SchemeResult.extras["rmw_replay"]``), so the image carries the lost
entries the hazards cause.
"""

from __future__ import annotations

import numpy as np

from gpusim.hw.program import Program
from gpusim.opplan import OPS

RMW_READ, RMW_WRITE = OPS.index("rmw_read"), OPS.index("rmw_write")


def rmw_operations(program: Program, machine):
    """The RMW operations a machine served: (pass, thread, service cycle) of the ``rmw_read`` rows and of
    the ``rmw_write`` rows of the coalescer (the cycle its partition served each:
    Coalescer.rmw_service_cycles); None when it served none."""
    coalescer = machine.units.get("coalescer")
    service = coalescer.rmw_service_cycles() if coalescer is not None else None
    if service is None or not (service >= 0).any():
        return None
    rows = program.rows_of("coalescer")
    row_pass = program.wi_pass[program.storage("coalescer")[2]]
    return tuple((row_pass[m], rows.thread[m], service[m]) for m in (rows.op == RMW_READ, rows.op == RMW_WRITE))


def rmw_windows(reads: tuple, writes: tuple, threads: int, own: bool = False):
    """(read cycle, write cycle) of each fragment thread (-1 where it has no RMW), from the RMW operations
    (:func:`rmw_operations`; a run replayed a chunk of passes at a time gathers them from each chunk).

    A thread that read-modify-writes in several passes (a multi-pass k-buffer's peel passes) has a window in
    each, and passes are barriers: then both are (passes, threads) arrays, a row per pass that holds RMW
    operations, in pass order.

    ``own``: the windows of the threads the operations name only (a sample's, a few of the run's ``threads``),
    and those threads, ascending: (read, write, threads). (A row per pass over every thread of the run took
    a multi-pass sample longer to fill than its hazards took to count.)"""
    (read_pass, read_thread, read_at), (write_pass, write_thread, write_at) = reads, writes
    if own:
        ids = np.unique(np.concatenate([read_thread, write_thread]))
        reads = read_pass, np.searchsorted(ids, read_thread), read_at
        writes = write_pass, np.searchsorted(ids, write_thread), write_at
        return (*rmw_windows(reads, writes, len(ids)), ids)
    slot, passes = _pass_slots(np.concatenate([read_pass, write_pass]), np.concatenate([read_thread, write_thread]),
                               threads)
    read = np.full((passes, threads), np.iinfo(np.int64).max, np.int64)
    write = np.full((passes, threads), -1, np.int64)
    np.minimum.at(read, (slot[:len(read_pass)], read_thread), read_at)
    np.maximum.at(write, (slot[len(read_pass):], write_thread), write_at)
    read[read == np.iinfo(np.int64).max] = -1
    return (read[0], write[0]) if passes == 1 else (read, write)


def _pass_slots(rp: np.ndarray, th: np.ndarray, threads: int):
    """Per RMW operation (its pass ``rp``, thread ``th``), the row of its window (0 for every operation unless
    some thread read-modify-writes in more than one pass: then the rank of its pass among the passes with RMW
    operations), and the count."""
    zero = np.zeros(len(rp), np.int64)
    if not len(rp) or rp.min() == rp.max():
        return zero, 1
    lo = np.full(threads, np.iinfo(np.int64).max, np.int64)
    hi = np.full(threads, -1, np.int64)
    np.minimum.at(lo, th, rp)
    np.maximum.at(hi, th, rp)
    if not ((hi >= 0) & (lo != hi)).any():     # each thread in one pass (k-buffer batches): one window each
        return zero, 1
    passes = np.unique(rp)
    return np.searchsorted(passes, rp), len(passes)


def machine_windows(program: Program, machine, threads: int, own: bool = False):
    """The RMW windows (:func:`rmw_windows`, of its own threads where ``own``) of a program a machine replayed,
    or None when it served no RMW instruction."""
    ops = rmw_operations(program, machine)
    return None if ops is None else rmw_windows(*ops, threads, own)


def count_hazards(pixel: np.ndarray, read: np.ndarray, write: np.ndarray) -> tuple[int, int]:
    """(fragments that read an obsolete value, pixels with at least one such fragment); windows per pass
    (:func:`rmw_windows`) count a fragment once per pass it read an obsolete value in."""
    if read.ndim == 1:
        hazards = _hazard_threads(pixel, read, write)
        return len(hazards), int(len(np.unique(pixel[hazards])))
    hazards = np.concatenate([_hazard_threads(pixel, r, w) for r, w in zip(read, write)])
    return len(hazards), int(len(np.unique(pixel[hazards])))


def _hazard_threads(pixel: np.ndarray, read: np.ndarray, write: np.ndarray) -> np.ndarray:
    """The threads that read before an earlier reader of their pixel had written."""
    has = (read >= 0) & (write >= 0)
    idx = np.flatnonzero(has)
    if not len(idx):
        return idx
    order = idx[np.lexsort((read[idx], pixel[idx]))]
    pix, rd, wr = pixel[order], read[order], write[order]
    # running maximum of earlier readers' writes inside each pixel
    start = np.r_[True, pix[1:] != pix[:-1]]
    seg = np.cumsum(start) - 1
    offset = seg * (int(wr.max()) + 2)            # keep the running max inside each pixel
    run = np.maximum.accumulate(wr + offset) - offset
    prev = np.r_[-1, run[:-1]]
    prev[start] = -1
    return order[rd < prev]
