"""Helpers for schemes that keep a fixed array of entries per pixel, and the array primitives (sorts, runs,
grouping by value) that the schemes and the timing model share."""

from __future__ import annotations

from typing import Literal

import numpy as np

from gpusim.metrics.composite import run_starts

Layout = Literal["pixel-major", "layer-major"]


def entry_index(pixel: np.ndarray, slot: np.ndarray, layers: int, pixel_count: int,
                layout: str) -> np.ndarray:
    """Linear entry index of (pixel, slot) in a pixels x layers array.

    ``pixel-major``: a pixel's entries are contiguous (FreePipe's DepthArray[x][y][i]);
    ``layer-major``: slot i of every pixel is one contiguous screen-sized plane.
    """
    pixel = np.asarray(pixel, dtype=np.int64)
    slot = np.asarray(slot, dtype=np.int64)
    if layout == "pixel-major":
        return pixel * layers + slot
    return slot * pixel_count + pixel


def record_layout(hw: str) -> Layout:
    """Where a pixel's fixed array of entries lies for the unit that updates it (``hw``, a scheme's parameter).

    A programmable blender (``blender``) reads and writes the pixel's whole array in one operation, so the
    array is the pixel's own record, its entries adjacent (``pixel-major``, as a multisampled pixel's samples
    are stored). Shader read-modify-writes (``texture-rmw``, ``scoreboard``, ``rov``) access one entry texel
    at a time, one render target per entry texel (``layer-major``: the MRT planes).
    """
    return "pixel-major" if hw == "blender" else "layer-major"


def pixel_key(pix: np.ndarray, value: np.ndarray) -> np.ndarray:
    """uint64 ``pix << 32 | value``: sorting it groups by pixel and orders by the 32-bit value."""
    return (np.asarray(pix).astype(np.uint64) << np.uint64(32)) | np.asarray(value).astype(np.uint64)


def lex_order(*keys: np.ndarray) -> np.ndarray:
    """Indices sorting by ``keys[0]``, then ``keys[1]``, ...; ties keep index order (a stable sort).

    The permutation ``np.lexsort(keys[::-1])`` gives (and ``np.argsort(key, kind="stable")`` for
    one key), for integer or bool keys, built from value sorts instead: each key is shifted to
    start at 0 and packed, with the element index in the low bits, into uint64 words that
    ``np.sort`` orders (numpy's SIMD sorts: several times faster than a stable argsort on
    unordered input). Keys needing more bits than a word has beside the index are sorted
    least significant word first, each pass stable by the index it carries.
    """
    return lex_sorted(*keys)[0]


def lex_sorted(*keys: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``lex_order(*keys)`` and ``keys[0]`` in that order, read off the last sorted word (no
    gather) when ``keys[0]`` fits in it whole."""
    n = len(keys[0])
    ib = _index_bits(n)
    room = 64 - ib
    words: list[tuple[np.ndarray, int]] = []     # (uint64 word, bits used), least significant first
    lead = None                                   # where keys[0] sits in the last word: (shift, lowest value)
    for k, key in enumerate(reversed(keys)):
        if len(key) != n:
            raise ValueError("lex_order: keys differ in length")
        if n == 0:
            continue
        field, lo, width = _from_zero(key)
        if width == 0:                            # one value: orders nothing
            lead = (None, lo) if k == len(keys) - 1 else lead
            continue
        shift = 0
        while shift < width:
            bits = min(room, width - shift)
            piece = field >> np.uint64(shift) if shift else field
            if width - shift > bits:
                piece = piece & np.uint64((1 << bits) - 1)
            at = words[-1][1] if words and words[-1][1] + bits <= room else 0
            if k == len(keys) - 1 and bits == width:
                lead = (at, lo)
            if at:
                words[-1] = (words[-1][0] | (piece << np.uint64(at)), at + bits)
            else:
                words.append((piece, bits))
            shift += bits
    perm, packed = None, None
    for word, _ in words:
        perm, packed = _sort_word(word, ib, perm)
    first = np.asarray(keys[0])
    if perm is None:
        return np.arange(n, dtype=np.intp), first.copy()
    if lead is None:
        return perm, first[perm]
    if lead[0] is None:
        return perm, np.full(n, lead[1], first.dtype)
    packed >>= np.uint64(ib + lead[0])
    if first.dtype.kind in "ub":
        return perm, (packed + np.uint64(lead[1])).astype(first.dtype)
    return perm, (packed.view(np.int64) + np.int64(lead[1])).astype(first.dtype)


def _index_bits(n: int) -> int:
    return max(1, (n - 1).bit_length())


def _from_zero(key) -> tuple[np.ndarray, int, int]:
    """An integer or bool key shifted to start at 0, as uint64: (field, lowest value, bit width)."""
    key = np.asarray(key)
    if key.dtype.kind == "b":
        key = key.view(np.uint8)
    if key.dtype.kind not in "iu":
        raise TypeError(f"keys must be integers or bools, not {key.dtype}")
    lo, hi = int(key.min()), int(key.max())
    if key.dtype.kind == "u":
        field = key.astype(np.uint64) - np.uint64(lo)
    else:                                         # wraps modulo 2**64 to the exact key - lo
        field = (key.astype(np.int64) - np.int64(lo)).view(np.uint64)
    return field, lo, (hi - lo).bit_length()


def _sort_word(word: np.ndarray, ib: int, perm: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """One stable pass: order by ``word`` (taken in ``perm`` order) with the position in the low ``ib`` bits.
    Returns the composed permutation and the sorted packed word. ``word`` is a temporary the pass
    may overwrite."""
    packed = word if perm is None else word[perm]
    packed <<= np.uint64(ib)
    packed |= np.arange(len(packed), dtype=np.uint64)
    packed.sort()
    step = (packed & np.uint64((1 << ib) - 1)).view(np.intp)      # below 2**63: the same numbers
    return (step if perm is None else perm[step]), packed


def put_rows(dst: np.ndarray, rows: np.ndarray, values: np.ndarray) -> None:
    """``dst[rows] = values`` for a C-contiguous 2-D ``dst``: each row written as one opaque item
    (numpy's row-wise fancy assignment is several times slower)."""
    if not dst.flags.c_contiguous or dst.ndim != 2:
        dst[rows] = values
        return
    item = np.dtype((np.void, dst.dtype.itemsize * dst.shape[1]))
    src = np.ascontiguousarray(np.broadcast_to(values, (len(rows), dst.shape[1])), dtype=dst.dtype)
    dst.view(item).reshape(-1)[rows] = src.view(item).reshape(-1)


def take_rows(src: np.ndarray, rows: np.ndarray) -> np.ndarray:
    """``src[rows]`` for a C-contiguous 2-D ``src``: each row gathered as one opaque item (numpy's row-wise
    fancy indexing is several times slower on a random order)."""
    if not src.flags.c_contiguous or src.ndim != 2:
        return src[rows]
    item = np.dtype((np.void, src.dtype.itemsize * src.shape[1]))
    return src.view(item).reshape(-1)[rows].view(src.dtype).reshape(len(rows), src.shape[1])


def rank_in_runs(pix_sorted: np.ndarray) -> np.ndarray:
    """0-based position of each element inside its run of a grouped array."""
    start = run_starts(pix_sorted)
    return np.arange(len(pix_sorted)) - np.repeat(start, np.diff(np.r_[start, len(pix_sorted)]))


def unique_ids(values: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``np.unique(values, return_index=True, return_inverse=True)`` for integers, sorted by
    :func:`lex_order`: the distinct values ascending, the first index of each, and each value's id."""
    order, ordered = lex_sorted(values)
    new = np.empty(len(values), bool)
    new[:1] = True
    np.not_equal(ordered[1:], ordered[:-1], out=new[1:])
    inverse = np.empty(len(values), np.intp)
    inverse[order] = np.cumsum(new) - 1
    return ordered[new], order[new], inverse


def sort_within_runs(pix_sorted: np.ndarray, key: np.ndarray) -> np.ndarray:
    """Permutation sorting each run of a grouped ``pix_sorted`` by ``key`` (integers), ties in place
    order, the runs staying where they are (``lex_order(pix_sorted, key)`` when they ascend)."""
    if len(pix_sorted) < 2 or bool((pix_sorted[1:] >= pix_sorted[:-1]).all()):
        return lex_order(pix_sorted, key)
    start = run_starts(pix_sorted)
    return lex_order(np.repeat(np.arange(len(start)), np.diff(np.r_[start, len(pix_sorted)])), key)


def sort_short_runs(pix_sorted: np.ndarray, key: np.ndarray) -> np.ndarray:
    """:func:`sort_within_runs`, in one value sort of words packing (pixel, key, position inside the run) where
    they fit in 64 bits: ascending non-negative runs, unsigned keys of up to 32 bits, runs short enough (up to
    4,096 fragments beside 20-bit pixel ids); else :func:`sort_within_runs`. Equal keys keep their order in
    the run (the position breaks the tie)."""
    n = len(pix_sorted)
    if n < 2 or key.dtype.kind not in "u" or key.dtype.itemsize > 4:
        return sort_within_runs(pix_sorted, key)
    start = run_starts(pix_sorted)
    if len(start) > 1 and bool((pix_sorted[start[1:]] < pix_sorted[start[:-1]]).any()):
        return sort_within_runs(pix_sorted, key)
    length = np.diff(np.r_[start, n])
    lowest = int(pix_sorted[0])
    pixel_bits = (int(pix_sorted[-1]) - lowest).bit_length()
    local_bits = max(1, (int(length.max()) - 1).bit_length())
    key_bits = 8 * key.dtype.itemsize
    if lowest < 0 or pixel_bits + key_bits + local_bits > 64:
        return sort_within_runs(pix_sorted, key)
    first = np.repeat(start, length)
    word = (np.arange(n, dtype=np.int64) - first).view(np.uint64)        # position inside the run
    word |= key.astype(np.uint64) << np.uint64(local_bits)
    word |= (pix_sorted.astype(np.uint64) - np.uint64(lowest)) << np.uint64(key_bits + local_bits)
    word.sort()
    # the runs stay where they are: sorted word i belongs to the run at i
    word &= np.uint64((1 << local_bits) - 1)
    first += word.view(np.int64)
    return first


def reversed_runs(pix_sorted: np.ndarray) -> np.ndarray:
    """Permutation reversing the order inside each run of a grouped array (the runs stay where they are)."""
    start = run_starts(pix_sorted)
    length = np.diff(np.r_[start, len(pix_sorted)])
    return np.repeat(2 * start + length - 1, length) - np.arange(len(pix_sorted))


def smallest_per_pixel(pix: np.ndarray, value: np.ndarray, limit: int,
                       candidates: np.ndarray | None = None, order: np.ndarray | None = None,
                       with_pixels: bool = False):
    """Indices of the ``limit`` smallest ``value`` s of each pixel, grouped by pixel, ascending
    (and, ``with_pixels``, their pixel ids).

    Equal values keep submission (index) order. ``candidates`` restricts the
    choice to those indices (others never enter the array). ``order``, when the
    caller has it, is the candidates already in that order (``PixelGroups.by_depth``
    when ``value`` is the depth key).
    """
    if order is None:
        idx = np.arange(len(pix)) if candidates is None else np.asarray(candidates, dtype=np.int64)
        perm, order_pix = lex_sorted(pix[idx], value[idx])
        order = idx[perm]
    else:
        order_pix = pix[order]
    keep = rank_in_runs(order_pix) < limit
    return (order[keep], order_pix[keep]) if with_pixels else order[keep]


def count_before_in_pixel(pix: np.ndarray, by_arrival: np.ndarray, flag: np.ndarray) -> np.ndarray:
    """For each fragment: how many *earlier* fragments of its pixel have ``flag`` set."""
    f = flag[by_arrival].astype(np.int64)
    csum = np.cumsum(f) - f
    start = run_starts(pix[by_arrival])
    base = np.repeat(csum[start], np.diff(np.r_[start, len(by_arrival)]))
    out = np.empty(len(pix), np.int64)
    out[by_arrival] = csum - base
    return out


def split_by(values: np.ndarray) -> list[tuple[int, np.ndarray]]:
    """Each distinct value of an integer array with the indices holding it (ascending), in value order:
    one stable sort, not one scan per value (a k-buffer batch run has thousands of passes)."""
    if not len(values):
        return []
    order = (np.arange(len(values)) if len(values) < 2 or bool((values[1:] >= values[:-1]).all())
             else np.argsort(_narrow(values), kind="stable"))
    v = values[order]
    bounds = [0, *(np.flatnonzero(v[1:] != v[:-1]) + 1).tolist(), len(v)]
    return [(int(v[a]), order[a:b]) for a, b in zip(bounds[:-1], bounds[1:])]


def _narrow(values: np.ndarray) -> np.ndarray:
    """Integer ``values`` in the narrowest of uint8 and int16 that holds them (numpy sorts those by radix, the
    same order in a fraction of the time), else as they are."""
    lo, hi = int(values.min()), int(values.max())
    if 0 <= lo and hi < 256:
        return values.astype(np.uint8)
    if -2**15 <= lo and hi < 2**15:
        return values.astype(np.int16)
    return values
