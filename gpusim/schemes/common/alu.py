"""ALU instruction counts of the schemes' thread programs (OpPlan.compute), from what each step does.

Counts are scalar instructions of one thread, as a GPU compiler would emit
them for the step; the timing model issues them at the SM's lanes, a warp
lasting as long as its busiest thread. They describe the schemes' programs,
not a GPU: the same counts serve every preset.
"""

from __future__ import annotations

import numpy as np

#: one compare-exchange of a register sort on (depth, payload) pairs: compare, two selects per register
COMPARE_EXCHANGE = 5
#: compositing one fragment front to back: 4 multiply-adds of the colour, the transmittance update, its test
COMPOSITE = 6
#: unpacking an 8-bit RGBA colour from a 32-bit word: 4 shifts/masks and 4 conversions
UNPACK_RGBA8 = 8
#: packing depth and colour into one word (FreePipe section 4.1.2): scale, convert, shift, mask, or
PACK_DEPTH_COLOUR = 6
#: a weight or blend factor evaluation (WBOIT's weight, an alpha blend): a few multiply-adds
WEIGHT = 6
#: count leading zeros of the four colour channels and the section's Length-table entry (TFSS, seed 003)
LEADING_ZEROS = 10


def insertion_compares(length: np.ndarray, inversions: np.ndarray | None = None) -> np.ndarray:
    """Compares of an insertion sort per list: ``length - 1`` plus its inversions (all of them, the worst
    case, when ``inversions`` is None: n (n - 1) / 2)."""
    length = np.asarray(length, np.int64)
    if inversions is None:
        return length * (length - 1) // 2
    return np.maximum(length - 1, 0) + np.asarray(inversions, np.int64)


def bitonic_compares(length: np.ndarray) -> np.ndarray:
    """Compare-exchanges of a bitonic network per list: on the next power of two m >= n,
    (m / 2) log2(m) (log2(m) + 1) / 2; none for a list of 0 or 1."""
    length = np.asarray(length, np.int64)
    m = np.ones_like(length)
    big = length > 1
    m[big] = 1 << np.ceil(np.log2(length[big])).astype(np.int64)
    log = np.log2(m).astype(np.int64)
    return (m // 2) * log * (log + 1) // 2


def sort_compares(length: np.ndarray, method: str) -> np.ndarray:
    """Compare-exchanges per list of ``length`` elements sorted in registers by ``method`` (insertion sort at
    its worst case: lists loaded in arrival order are unsorted in general)."""
    if method == "bitonic":
        return bitonic_compares(length)
    if method == "insertion":
        return insertion_compares(length)
    raise ValueError(f"unknown sort {method!r} (valid: insertion, bitonic)")
