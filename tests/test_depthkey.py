"""The float-to-ordered-integer depth mapping used by atomicMin, and FreePipe's packing."""

from __future__ import annotations

import numpy as np
import pytest

from gpusim.schemes.common.depthkey import EMPTY, colour24, colour24_rgb, depth_key, key_depth, packed_depth

ONE_BITS = 0x3F800000   # bit pattern of 1.0f


def test_depth_key_is_exact_and_strictly_monotone_over_every_float_in_unit_interval():
    step = 1 << 26
    previous_last = None
    for lo in range(0, ONE_BITS + 1, step):            # all 1,065,353,217 floats in [0, 1], in chunks
        bits = np.arange(lo, min(lo + step, ONE_BITS + 1), dtype=np.uint32)
        z = bits.view(np.float32)
        key = depth_key(z)
        assert np.all(np.diff(key.astype(np.int64)) > 0)             # strictly increasing with z
        assert np.array_equal(key_depth(key), z)                       # exact: the depth comes back
        if previous_last is not None:
            assert key[0] > previous_last
        previous_last = key[-1]
    assert previous_last == ONE_BITS and previous_last < EMPTY


def test_depth_key_rejects_nan_and_negative_and_merges_signed_zeros():
    with pytest.raises(ValueError, match="NaN"):
        depth_key(np.array([0.5, np.nan], np.float32))
    with pytest.raises(ValueError, match="negative"):
        depth_key(np.array([-0.25], np.float32))
    assert depth_key(np.array([-0.0, 0.0], np.float32)).tolist() == [0, 0]
    assert depth_key(np.array([0.3, 0.3], np.float32))[0] == depth_key(np.array([0.3], np.float32))[0]


def test_packed_depth_keeps_order_with_20_bits_and_frees_12():
    z = np.linspace(0, 1, 100_001, dtype=np.float32)
    packed = packed_depth(z)
    assert np.all(packed & 0xFFF == 0)
    assert np.all(np.diff(packed.astype(np.int64)) >= 0)              # monotone (not strictly: 20 bits)
    assert packed[-1] > packed[-2] > 0 and packed[0] == 0             # z = 1 does not wrap to the key of 0
    # resolution: depths 2**-19 apart stay distinct; 2**-22 apart may collide
    assert packed_depth(np.float32([0.5]))[0] != packed_depth(np.float32([0.5 + 2 ** -19]))[0]
    assert packed_depth(np.float32([0.5]))[0] == packed_depth(np.float32([0.5 + 2 ** -22]))[0]


def test_colour24_round_trips_8_bit_colours():
    rgb = np.array([[0, 0, 0], [1, 1, 1], [0.2, 0.4, 0.6]])
    c = colour24(rgb)
    assert c[1] == 0xFFFFFF
    assert np.abs(colour24_rgb(c) - rgb).max() <= 0.5 / 255
