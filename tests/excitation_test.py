"""The firmware's sine excitation (firmware/core/excitation.cpp)."""

import math

import numpy as np
import pytest

from heliquad import _firmware as fw

LOOP_HZ = 200.0


def config(freq, amp=1.0, cycles=10, fade=1, axis=fw.Axis.ROLL, inj=fw.Injection.MIXER):
    c = fw.ExcitationConfig()
    c.freq_hz, c.amplitude, c.cycles, c.fade_cycles, c.axis, c.injection = freq, amp, cycles, fade, axis, inj
    return c


@pytest.mark.parametrize("requested, period", [(1.0, 200), (0.15, 1333), (4.5, 44), (4.8, 42),
                                               (1.234, 162)])
def test_integer_period_and_exact_frequency(requested, period):
    ex = fw.Excitation()
    assert ex.start(config(requested), LOOP_HZ)
    assert ex.period_samples == period
    assert ex.actual_freq_hz == pytest.approx(LOOP_HZ / period, rel=1e-6)


def test_signal_is_periodic_with_fades_and_full_cycles_between():
    ex = fw.Excitation()
    ex.start(config(2.0, amp=0.3, cycles=4, fade=2), LOOP_HZ)
    n = ex.period_samples
    assert ex.total_samples == n * (4 + 2 * 2)
    values, measuring = [], []
    while ex.active:
        measuring.append(ex.measuring)
        values.append(ex.next())
    values = np.array(values[:ex.total_samples])
    k = np.arange(values.size)
    full = 0.3 * np.sin(2 * math.pi * (k % n) / n)
    mid = slice(2 * n, 6 * n)
    np.testing.assert_allclose(values[mid], full[mid], atol=1e-6)
    assert values[0] == 0.0 and abs(values[-1]) < 1e-3
    assert np.all(np.abs(values[:2 * n]) <= np.abs(full[:2 * n]) + 1e-7)
    assert sum(measuring) == 4 * n
    assert ex.next() == 0.0 and not ex.active


@pytest.mark.parametrize("freq, cycles", [(0.0, 10), (-1.0, 10), (60.0, 10), (1.0, 0)])
def test_impossible_requests_are_refused(freq, cycles):
    ex = fw.Excitation()
    assert not ex.start(config(freq, cycles=cycles), LOOP_HZ)
    assert not ex.active and ex.next() == 0.0


def test_stop():
    ex = fw.Excitation()
    ex.start(config(1.0), LOOP_HZ)
    ex.next()
    ex.stop()
    assert not ex.active and ex.next() == 0.0
