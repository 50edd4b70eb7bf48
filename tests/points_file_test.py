"""A frequency point is one type from the estimator through points.csv to the fit: what the
estimator measured comes back from the file as the same FrequencyPoint, to the file's digits,
and a file with fewer columns gives points that say what they do not know."""

import math

import numpy as np
import pytest

from heliquad.host.estimate.fsf import estimate_against_excitation, estimate_fsf
from heliquad.host.estimate.models import fit_orders, point_weights
from heliquad.host.records.points import (FrequencyPoint, frequency_points, known_column,
                                          read_points_csv, read_points_table, write_points_csv,
                                          write_points_table)

FS_HZ = 200.0
ROLL = ([28.19], [1.0, 5.13, 22.93])


def response(omega):
    s = 1j * np.asarray(omega)
    return np.polyval(ROLL[0], s) / np.polyval(ROLL[1], s)


def sine_run(freq_hz, periods=6, seed=0):
    """An input sine and the roll model's steady-state response, with a little noise."""
    n = int(round(periods * FS_HZ / freq_hz))
    t = np.arange(n) / FS_HZ
    w = 2 * math.pi * freq_hz
    g = response(w)
    rng = np.random.default_rng(seed)
    u = np.sin(w * t)
    y = abs(g) * np.sin(w * t + np.angle(g)) + 1e-3 * rng.standard_normal(n)
    return u, y


def stored(point):
    return (point.omega_rad_s, point.gain, point.sigma, point.coherence, point.coherence_ry,
            point.coherence_ru, point.lost_share, point.estimate)


@pytest.mark.parametrize("against_excitation", [False, True])
def test_the_estimators_points_come_back_from_points_csv_as_the_same_points(tmp_path,
                                                                           against_excitation):
    points = []
    for i, f in enumerate((0.5, 1.0, 2.0, 4.0)):
        u, y = sine_run(f, seed=i)
        if against_excitation:
            p = estimate_against_excitation(u, u, y, FS_HZ, f)
        else:
            p = estimate_fsf(u, y, FS_HZ, f)
        points.append(FrequencyPoint(**{**p.__dict__, "lost_share": 0.01 * i}))
    path = tmp_path / "points.csv"
    write_points_csv(path, points[::-1])                 # written in order of frequency
    back = read_points_csv(path)
    assert [type(p) for p in back] == [FrequencyPoint] * 4
    for got, want in zip(back, points):
        g, w = stored(got), stored(want)
        np.testing.assert_allclose(g[:2], w[:2], rtol=1e-11)        # written with 12 digits
        np.testing.assert_allclose(g[2:7], w[2:7], rtol=1e-5, equal_nan=True)   # with 6
        assert g[7] == w[7] == ("excitation" if against_excitation else "input")
        # the estimator's diagnostics are not stored: a read point says it does not know them
        assert math.isnan(got.period_samples) and got.n_periods == 0 and got.method == ""
    # the fit takes either the estimator's points or the file's and finds the same model
    direct = fit_orders(points, [(0, 2)])
    again = fit_orders(back, [(0, 2)])
    np.testing.assert_allclose(again.models[0].den, direct.models[0].den, rtol=1e-4)
    assert again.weights == direct.weights == "sigma"


def test_a_points_file_without_the_optional_columns_gives_points_that_know_no_more(tmp_path):
    path = tmp_path / "points.csv"
    omega = np.array([3.0, 6.0, 12.0, 24.0])
    F = response(omega)
    path.write_text("omega_rad_s,magnitude,phase_rad\n" + "".join(
        f"{float(w)!r},{float(abs(g))!r},{float(np.angle(g))!r}\n" for w, g in zip(omega, F)))
    back = read_points_csv(path)
    np.testing.assert_allclose(known_column(back, "gain"), F, rtol=1e-12)
    for name in ("sigma", "coherence", "coherence_ry", "coherence_ru"):
        assert known_column(back, name) is None, name
    np.testing.assert_array_equal(known_column(back, "lost_share"), np.zeros(4))
    assert {p.estimate for p in back} == {"input"}
    weights, mode = point_weights(back)
    assert mode == "none"
    np.testing.assert_allclose(weights, 1 / np.abs(F))


def test_points_from_arrays_are_the_same_type_and_keep_what_is_given():
    omega = np.array([1.0, 2.0])
    points = frequency_points(omega, response(omega), sigma=[0.1, 0.2], coherence=None)
    assert [p.sigma for p in points] == [0.1, 0.2]
    assert known_column(points, "coherence") is None
    assert point_weights(points)[1] == "sigma"


def test_the_points_table_reads_back_as_printed(tmp_path):
    omega = np.array([3.0, 6.0])
    points = frequency_points(omega, response(omega), coherence=[0.99, math.nan])
    write_points_table(tmp_path / "t.csv", points)
    table = read_points_table(tmp_path / "t.csv")
    np.testing.assert_allclose(table.omega_rad_s, omega)
    np.testing.assert_allclose(table.freq_hz, omega / (2 * math.pi), rtol=1e-5)
    np.testing.assert_allclose(table.real + 1j * table.imag, response(omega), rtol=1e-5)
    assert table.coherence[0] == 0.99 and math.isnan(table.coherence[1])
    assert table.column("phase_deg") is table.phase_deg
