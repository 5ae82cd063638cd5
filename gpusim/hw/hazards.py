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


def rmw_windows(program: Program, service: np.ndarray, threads: int):
    """(read cycle, write cycle) of each fragment thread (-1 where it has no RMW); ``service``: per row of the
    coalescer's instructions, the cycle its partition served it (Coalescer.rmw_service_cycles)."""
    read = np.full(threads, np.iinfo(np.int64).max, np.int64)
    write = np.full(threads, -1, np.int64)
    rows = program.rows_of("coalescer")
    r = rows.op == RMW_READ
    w = rows.op == RMW_WRITE
    np.minimum.at(read, rows.thread[r], service[r])
    np.maximum.at(write, rows.thread[w], service[w])
    read[read == np.iinfo(np.int64).max] = -1
    return read, write


def count_hazards(pixel: np.ndarray, read: np.ndarray, write: np.ndarray) -> tuple[int, int]:
    """(fragments that read an obsolete value, pixels with at least one such fragment)."""
    has = (read >= 0) & (write >= 0)
    idx = np.flatnonzero(has)
    if not len(idx):
        return 0, 0
    order = idx[np.lexsort((read[idx], pixel[idx]))]
    pix, rd, wr = pixel[order], read[order], write[order]
    # running maximum of earlier readers' writes inside each pixel
    start = np.r_[True, pix[1:] != pix[:-1]]
    seg = np.cumsum(start) - 1
    offset = seg * (int(wr.max()) + 2)            # keep the running max inside each pixel
    run = np.maximum.accumulate(wr + offset) - offset
    prev = np.r_[-1, run[:-1]]
    prev[start] = -1
    hazard = rd < prev
    return int(hazard.sum()), int(len(np.unique(pix[hazard])))
