"""The exact sine-dwell simulator that the estimator tests and the demo stand on."""

import math

import numpy as np
import pytest

from dwell_plant import simulate_sine_dwell

ROLL = ([28.19], [1, 5.13, 22.93])


def test_settled_output_is_the_analytic_steady_state():
    d = simulate_sine_dwell(*ROLL, 1.0, fs_hz=200.0, cycles=3, settle_cycles=16, amplitude=2.0)
    G = np.polyval(ROLL[0], 2j * math.pi) / np.polyval(ROLL[1], 2j * math.pi)
    t = np.arange(d.u.size) / 200.0 + 16.0          # the record starts after 16 cycles of 1 s
    np.testing.assert_allclose(d.u, 2.0 * np.sin(2 * math.pi * t), atol=1e-12)
    np.testing.assert_allclose(d.y, 2.0 * abs(G) * np.sin(2 * math.pi * t + np.angle(G)),
                               atol=1e-6)


def test_starts_at_rest_and_snaps_to_an_integer_period():
    d = simulate_sine_dwell(*ROLL, 3.3, fs_hz=200.0, cycles=2)
    assert d.freq_hz == pytest.approx(200.0 / 61)
    assert d.u.size == 122 and d.y[0] == 0.0


def test_noise_is_seeded():
    a = simulate_sine_dwell(*ROLL, 1.0, cycles=1, noise_std=0.1, rng=np.random.default_rng(5))
    b = simulate_sine_dwell(*ROLL, 1.0, cycles=1, noise_std=0.1, rng=np.random.default_rng(5))
    np.testing.assert_array_equal(a.y, b.y)


def test_csv_round_trip(tmp_path):
    from heliquad.host.records.run_csv import read_run_csv

    d = simulate_sine_dwell(*ROLL, 2.0, cycles=2)
    d.to_csv(tmp_path / "run.csv")
    fs, u, y = read_run_csv(tmp_path / "run.csv")
    assert fs == pytest.approx(200.0, rel=1e-9)
    np.testing.assert_allclose(u, d.u, atol=1e-9)
