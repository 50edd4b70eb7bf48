"""LoopLoad: the loop-timing figures HQ_FW_STATUS carries once a second."""

import numpy as np

from heliquad import _firmware as fw


def test_median_and_max_of_one_second_of_loops():
    rng = np.random.default_rng(3)
    cycles = rng.integers(20_000, 40_000, size=200)
    cycles[17] = 590_000                      # one slow loop
    load = fw.LoopLoad()
    for c in cycles:
        load.record(int(c), 2)
    median, largest, overruns = load.take()
    srt = np.sort(cycles)
    assert median == srt[len(srt) // 2]      # the upper median of an even count
    assert largest == 590_000 and overruns == 2


def test_each_report_covers_only_the_loops_since_the_last():
    load = fw.LoopLoad()
    for c in (5, 6, 7):
        load.record(c, 0)
    assert load.take() == (6, 7, 0)
    load.record(100, 1)
    assert load.take() == (100, 100, 1)
    assert load.take() == (0, 0, 1)           # no loops: zeros, overruns stay cumulative


def test_more_loops_than_the_buffer_keep_the_max_exact():
    load = fw.LoopLoad()
    for i in range(fw.LoopLoad.capacity + 50):
        load.record(1000 + i, 0)
    median, largest, _ = load.take()
    assert largest == 1000 + fw.LoopLoad.capacity + 49
    assert 1000 <= median < 1000 + fw.LoopLoad.capacity
