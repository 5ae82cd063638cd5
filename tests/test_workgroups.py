"""Work items on a workgroup's lanes (gpusim.schemes.common.workgroups)."""

import numpy as np

from gpusim.schemes.common.workgroups import Lanes, thread_totals


def test_lanes_give_each_thread_its_items_in_program_order():
    # items 0..4 on threads 5, 3, 5, 3, 9; within a thread by the order key, then item number
    ln = Lanes(np.array([5, 3, 5, 3, 9]), np.array([2, 1, 0, 1, 0]))
    assert ln.threads.tolist() == [3, 5, 9] and ln.counts.tolist() == [2, 2, 1]
    i, s = np.array([0, 0, 1, 1, 2]), np.array([0, 1, 0, 1, 0])
    assert ln.item(i, s).tolist() == [1, 3, 2, 0, 4]


def test_thread_totals_sum_a_threads_work():
    threads, totals = thread_totals(np.array([7, 2, 7, 7]), np.array([1, 5, 2, 3]))
    assert threads.tolist() == [2, 7] and totals.tolist() == [5, 6]
    assert [a.tolist() for a in thread_totals(np.zeros(0, np.int64), np.zeros(0))] == [[], []]
