"""The array helpers the schemes sort and group with (gpusim.schemes.common.arrays, sections)."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

from gpusim.schemes.common.arrays import lex_order, lex_sorted, put_rows, reversed_runs, sort_within_runs, take_rows
from gpusim.schemes.common.sections import SectionIndex

_DTYPES = [np.bool_, np.uint8, np.int8, np.uint16, np.int32, np.uint32, np.int64, np.uint64]


@st.composite
def _keys(draw):
    n = draw(st.integers(0, 80))
    keys = []
    for _ in range(draw(st.integers(1, 4))):
        dtype = np.dtype(draw(st.sampled_from(_DTYPES)))
        # few distinct values (ties) or the whole range of the type (keys split over words)
        elements = st.sampled_from([0, 1, 2]) if draw(st.booleans()) and dtype != np.bool_ else None
        keys.append(draw(hnp.arrays(dtype, n, elements=elements)))
    return keys


@settings(max_examples=300, deadline=None)
@given(_keys())
def test_lex_order_is_numpys_stable_lexsort(keys):
    want = np.lexsort(keys[::-1]) if len(keys[0]) else np.zeros(0, np.intp)
    got = lex_order(*keys)
    assert got.dtype == np.intp
    np.testing.assert_array_equal(got, want)
    perm, first = lex_sorted(*keys)            # the leading key in order, read off the sorted word
    np.testing.assert_array_equal(perm, want)
    assert first.dtype == keys[0].dtype
    np.testing.assert_array_equal(first, keys[0][want])


def test_lex_order_on_millions_of_unordered_pixel_depth_keys():
    """Over 2**21 elements the index takes 22 bits: (pixel, depth, tie-break) spans three words."""
    rng = np.random.default_rng(7)
    n = (1 << 21) + 5
    pix = rng.integers(0, 1 << 20, n)
    key = rng.integers(0x3E000000, 0x3F800000, n, dtype=np.uint32)
    key[rng.random(n) < 0.3] = 0x3F000000                       # many exact ties
    tie = rng.integers(-n, n, n)
    np.testing.assert_array_equal(lex_order(pix, key), np.lexsort((key, pix)))
    perm, pix_sorted = lex_sorted(pix, key)
    np.testing.assert_array_equal(pix_sorted, pix[perm])
    np.testing.assert_array_equal(lex_order(pix, key, tie), np.lexsort((tie, key, pix)))


def test_lex_order_rejects_floats_and_ragged_keys():
    with pytest.raises(TypeError):
        lex_order(np.zeros(3, np.float32))
    with pytest.raises(ValueError):
        lex_order(np.zeros(3, np.int64), np.zeros(2, np.int64))


def test_reversed_runs_reverses_inside_each_run_only():
    pix = np.array([0, 0, 0, 3, 5, 5])
    np.testing.assert_array_equal(reversed_runs(pix), [2, 1, 0, 3, 5, 4])
    assert len(reversed_runs(np.zeros(0, np.int64))) == 0


def test_section_index_finds_every_section_whatever_the_query_order():
    rng = np.random.default_rng(3)
    pixel = rng.integers(0, 50, 400)
    chain = np.empty(400, np.int64)
    for p in np.unique(pixel):                  # each pixel's sections: chain 0, 1, ... in allocation order
        chain[pixel == p] = np.arange(np.count_nonzero(pixel == p))
    ids = rng.permutation(400) + 1000
    index = SectionIndex(pixel, chain, ids)
    q = rng.permutation(400)
    np.testing.assert_array_equal(index(pixel[q], chain[q]), ids[q])
    chain[0] += 5                               # a gap in a pixel's chain has no place in the index
    with pytest.raises(ValueError, match="without gaps"):
        SectionIndex(pixel, chain, ids)


def test_sort_within_runs_sorts_each_run_where_it_stands():
    pix = np.array([5, 5, 5, 2, 2, 9])
    key = np.array([3, 1, 3, 7, 0, 2], np.uint32)
    np.testing.assert_array_equal(sort_within_runs(pix, key), [1, 0, 2, 4, 3, 5])
    ascending = np.sort(pix)
    np.testing.assert_array_equal(sort_within_runs(ascending, key), lex_order(ascending, key))
    assert len(sort_within_runs(np.zeros(0, np.int64), np.zeros(0, np.uint32))) == 0


@settings(max_examples=50, deadline=None)
@given(st.integers(1, 40), st.integers(1, 5), st.data())
def test_take_and_put_rows_match_fancy_indexing(n, width, data):
    src = data.draw(hnp.arrays(np.float32, (n, width), elements=st.floats(-1e6, 1e6, width=32)))
    rows = np.asarray(data.draw(st.lists(st.integers(0, n - 1), max_size=3 * n)), np.int64)
    assert np.array_equal(take_rows(src, rows), src[rows])
    assert np.array_equal(take_rows(src[:, ::-1], rows), src[:, ::-1][rows])      # not contiguous: plain indexing
    unique = np.unique(rows)
    a, b = src.copy(), src.copy()
    put_rows(a, unique, src[unique][::-1])
    b[unique] = src[unique][::-1]
    assert np.array_equal(a, b)
