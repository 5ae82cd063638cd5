"""Items dealt round robin over a workgroup's lanes (gpusim.schemes.common.workgroups)."""

import numpy as np
import pytest

from gpusim.schemes.common.workgroups import Spread


def test_items_are_dealt_round_robin_and_every_item_once():
    # owner 7 has 5 items over 4 lanes (2, 1, 1, 1), owner 9 has 2 (two lanes of 1), owner 3 none
    sp = Spread(np.array([7, 9, 3]), np.array([5, 2, 0]), 4)
    assert sp.threads.tolist() == [28, 29, 30, 31, 36, 37]
    assert sp.counts.tolist() == [2, 1, 1, 1, 1, 1]
    i = np.repeat(np.arange(len(sp.counts)), sp.counts)
    s = np.arange(len(i)) - np.repeat(np.cumsum(sp.counts) - sp.counts, sp.counts)
    owner, item = sp.item(i, s)
    assert sorted(zip(owner.tolist(), item.tolist())) == [(0, 0), (0, 1), (0, 2), (0, 3), (0, 4), (1, 0), (1, 1)]


def test_a_workgroup_needs_a_lane():
    with pytest.raises(ValueError, match="size"):
        Spread(np.array([0]), np.array([1]), 0)
