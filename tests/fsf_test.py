"""FSF estimator: accuracy, recursive/batch agreement, robustness, uncertainty."""

import math

import numpy as np
import pytest

from dwell_plant import simulate_sine_dwell
from heliquad.host.estimate.baselines import estimate_dft, estimate_h1
from heliquad.host.estimate.fsf import (RecursiveFsf, estimate_against_excitation,
                                        estimate_frequency, estimate_fsf, estimate_multisine,
                                        estimate_multisine_against_excitation, period_coherence)
from heliquad.sim.base.errors import InputError

ROLL = ([28.19], [1, 5.13, 22.93])          # the paper's chosen roll model (docs/paper.md)
FS_HZ = 200.0
#: Settling before the record: 16 of the roll model's slowest time constants (1/2.565 s),
#: so the transient left (e^-16 ~ 1e-7) is below every tolerance here.
SETTLE_S = 16 / 2.565
ACCEPT_FREQS_HZ = [0.2, 0.5, 1.0, 2.0, 5.0]


def truth(num, den, freq_hz):
    s = 2j * math.pi * freq_hz
    return np.polyval(num, s) / np.polyval(den, s)


def dwell(freq_hz, cycles=10, snr_db=None, seed=0, model=ROLL, amplitude=1.0):
    """Steady-state record of ``cycles`` periods; output noise at the given SNR."""
    settle = math.ceil(SETTLE_S * freq_hz)
    d = simulate_sine_dwell(*model, freq_hz, fs_hz=FS_HZ, cycles=cycles, settle_cycles=settle,
                            amplitude=amplitude)
    y = d.y
    if snr_db is not None:
        noise_std = np.sqrt(np.mean(y ** 2) / 10 ** (snr_db / 10))
        y = y + np.random.default_rng(seed).normal(0.0, noise_std, y.size)
    return d.u, y, d.freq_hz


@pytest.mark.parametrize("freq_hz", ACCEPT_FREQS_HZ)
def test_acceptance_20db_snr_ten_periods(freq_hz):
    # Issue 2: 200 Hz, 10 periods, 20 dB SNR -> |G| within 1 %, phase within 1 degree.
    # The estimator's own sigma at 5 Hz is ~0.7 % (complex), so 1 % is ~2 sigma per
    # component; the fixed seed makes the test repeatable and the 3-sigma check below
    # guards the estimator's honesty independent of the seed.
    u, y, f = dwell(freq_hz, snr_db=20.0, seed=int(freq_hz * 100))
    point = estimate_fsf(u, y, FS_HZ, discard_periods=0)
    G = truth(*ROLL, f)
    assert point.method == "fsf"
    assert point.freq_hz == pytest.approx(f, rel=1e-12)
    assert abs(point.magnitude / abs(G) - 1) < 0.01
    assert abs(math.degrees(np.angle(point.gain / G))) < 1.0
    assert abs(point.gain - G) < 3 * point.sigma


@pytest.mark.parametrize("freq_hz", ACCEPT_FREQS_HZ)
def test_recursive_and_batch_agree(freq_hz):
    u, y, f = dwell(freq_hz, snr_db=20.0, seed=7)
    y = y + 0.3                                   # an output offset too
    period = round(FS_HZ / f)
    p0 = 2e6
    batch = estimate_fsf(u, y, FS_HZ, freq_hz=f, discard_periods=0, p0=p0)
    rls = RecursiveFsf(period, discard_periods=0, p0=p0)
    for a, b in zip(u, y):
        rls.update(a, b)
    for l in (1,):
        assert abs(rls.gain(l) - batch.harmonics[l]) <= 1e-6 * abs(batch.harmonics[l])


@pytest.mark.parametrize("freq_hz", [0.37, 1.2345, 3.3])
def test_exact_for_noise_free_data_integer_and_non_integer_period(freq_hz):
    # A non-integer period goes to the exact sine-fit treatment; never a biased FSF.
    settle = math.ceil(SETTLE_S * freq_hz)
    d = simulate_sine_dwell(*ROLL, freq_hz, fs_hz=FS_HZ, cycles=10, settle_cycles=settle,
                            integer_period=False)
    point = estimate_fsf(d.u, d.y, FS_HZ, discard_periods=0)
    expected_method = "fsf" if float(FS_HZ / freq_hz).is_integer() else "sinefit"
    assert point.method == expected_method
    assert abs(point.gain / truth(*ROLL, freq_hz) - 1) < 1e-6


def test_frequency_found_from_input_matches_the_excitation():
    u, y, f = dwell(1.37, snr_db=20.0)
    assert estimate_frequency(u, FS_HZ) == pytest.approx(f, rel=1e-7)


def test_offsets_do_not_bias_the_estimate():
    u, y, f = dwell(1.0)
    clean = estimate_fsf(u, y, FS_HZ, discard_periods=0)
    shifted = estimate_fsf(u + 2.0, y - 5.0, FS_HZ, discard_periods=0)
    assert abs(shifted.gain / clean.gain - 1) < 1e-7
    # Without an input DC the offset term alone carries the output's shift.
    assert estimate_fsf(u, y - 5.0, FS_HZ, discard_periods=0).offset == pytest.approx(-5.0)


def test_unexcited_harmonics_are_reported_as_nan_and_excited_ones_estimated():
    u, y, f = dwell(1.0)
    point = estimate_fsf(u, y, FS_HZ, discard_periods=0)
    assert all(np.isnan(point.harmonics[l]) for l in (2, 3))
    # Input with a second harmonic: both are estimated.
    d1 = simulate_sine_dwell(*ROLL, 1.0, fs_hz=FS_HZ, cycles=10, settle_cycles=7)
    d2 = simulate_sine_dwell(*ROLL, 2.0, fs_hz=FS_HZ, cycles=20, settle_cycles=14,
                             amplitude=0.5)
    point = estimate_fsf(d1.u + d2.u, d1.y + d2.y, FS_HZ, freq_hz=1.0, discard_periods=0)
    assert abs(point.harmonics[2] / truth(*ROLL, 2.0) - 1) < 1e-6
    assert np.isnan(point.harmonics[3])


def test_sigma_matches_the_actual_scatter():
    f = 2.0
    G = truth(*ROLL, f)
    errors, sigmas = [], []
    for seed in range(60):
        u, y, _ = dwell(f, snr_db=20.0, seed=seed)
        p = estimate_fsf(u, y, FS_HZ, discard_periods=0)
        errors.append(p.gain - G)
        sigmas.append(p.sigma)
    empirical = math.sqrt(np.mean(np.abs(errors) ** 2))
    # 60 complex samples: the RMS estimate itself is good to about +/-13 % (1 sigma).
    assert empirical == pytest.approx(np.mean(sigmas), rel=0.35)


def test_coherence_is_one_without_noise_and_drops_with_noise():
    u, y, _ = dwell(1.0)
    assert estimate_fsf(u, y, FS_HZ, discard_periods=0).coherence == pytest.approx(1, abs=1e-9)
    u, y, _ = dwell(1.0, snr_db=-10.0)
    assert estimate_fsf(u, y, FS_HZ, discard_periods=0).coherence < 0.9
    # One segment says nothing: coherence is 1 by construction, so it is NaN.
    assert math.isnan(period_coherence(u, y, 2 * math.pi / 200, [0], 200))


def test_discarding_settling_periods_removes_the_transient():
    d = simulate_sine_dwell(*ROLL, 2.0, fs_hz=FS_HZ, cycles=30, settle_cycles=0)
    G = truth(*ROLL, d.freq_hz)
    raw = estimate_fsf(d.u, d.y, FS_HZ, discard_periods=0)
    settled = estimate_fsf(d.u, d.y, FS_HZ, discard_periods=10)
    assert abs(settled.gain / G - 1) < 1e-4
    assert abs(raw.gain / G - 1) > abs(settled.gain / G - 1)


@pytest.mark.parametrize("u, y, match", [
    (np.ones(400), np.ones(400), "constant"),
    (np.sin(np.arange(30) * 0.1), np.zeros(30), "too short|fewer than"),
    (np.sin(np.arange(100) * 0.5), np.zeros(99), "equal length"),
    (np.r_[np.sin(np.arange(99) * 0.5), np.nan], np.zeros(100), "NaN"),
])
def test_bad_signals_raise_input_error(u, y, match):
    with pytest.raises(InputError, match=match):
        estimate_fsf(u, y, FS_HZ)


@pytest.mark.parametrize("u", [np.zeros(2000), np.full(2000, 0.3)])
def test_an_input_without_excitation_at_the_given_frequency_is_refused(u):
    # A logged window whose excitation never ran (zero or a constant): one clear error, not
    # a singular linear system.
    y = np.random.default_rng(0).normal(size=u.size)
    with pytest.raises(InputError, match="no component at 2 Hz"):
        estimate_fsf(u, y, FS_HZ, freq_hz=2.0)


def test_frequency_above_nyquist_is_refused():
    u, y, _ = dwell(1.0)
    with pytest.raises(InputError, match="Nyquist"):
        estimate_fsf(u, y, FS_HZ, freq_hz=150.0)


@pytest.mark.parametrize("estimator", [estimate_dft, estimate_h1])
def test_baselines_agree_with_fsf_on_clean_data(estimator):
    u, y, f = dwell(1.0, cycles=40)
    base = estimator(u, y, FS_HZ, f, discard_periods=0)
    assert abs(base.gain / truth(*ROLL, f) - 1) < 1e-6


def roll_zoh():
    """The roll model sampled with a zero-order hold at FS_HZ: (Ad, Bd, Cd)."""
    import scipy.signal as sig

    A, B, C, D = sig.tf2ss(*ROLL)
    Ad, Bd, Cd, _, _ = sig.cont2discrete((A, B, C, D), 1 / FS_HZ, method="zoh")
    return Ad, Bd, Cd


def sampled_truth(z):
    Ad, Bd, Cd = roll_zoh()
    return np.array([(Cd @ np.linalg.solve(zi * np.eye(2) - Ad, Bd)).item()
                     for zi in np.atleast_1d(z)])


def closed_loop(period, cycles, kp, gust_std, seed, amplitude=1.0, r=None):
    """The roll model (ZOH at FS_HZ) under proportional rate feedback ``u = r - kp y`` with
    slow gusts added to the plant input: (r, u, y), one sample per loop, and the sampled truth
    at the excitation's frequency. ``r``: another excitation (of ``period * cycles``
    samples) than the sine of that period."""
    import scipy.signal as sig

    Ad, Bd, Cd = roll_zoh()
    n = period * cycles
    gust = sig.lfilter([0.03], [1, -0.97], np.random.default_rng(seed).normal(0, gust_std, n))
    if r is None:
        r = amplitude * np.sin(2 * np.pi * np.arange(n) / period)
    x, u, y = np.zeros(2), np.zeros(n), np.zeros(n)
    for k in range(n):
        y[k] = Cd[0] @ x
        u[k] = r[k] - kp * y[k]
        x = Ad @ x + Bd[:, 0] * (u[k] + gust[k])
    return r, u, y, sampled_truth(np.exp(2j * np.pi / period))[0]


def test_against_the_excitation_is_exact_in_a_noise_free_closed_loop():
    for period in (400, 40):
        # 32 s from rest, the first 16 s discarded: the transient left is far below 1e-5
        r, u, y, g = closed_loop(period, 6400 // period, kp=3.0, gust_std=0.0, seed=0)
        p = estimate_against_excitation(r, u, y, FS_HZ, FS_HZ / period,
                                        discard_periods=3200 // period)
        assert abs(p.gain / g - 1) < 1e-5 and p.estimate == "excitation"
        assert p.coherence_ry == pytest.approx(1.0) and p.coherence_ru == pytest.approx(1.0)
        assert p.coherence == min(p.coherence_ry, p.coherence_ru)


def test_against_the_excitation_is_unbiased_where_the_direct_estimate_is_not():
    # Gusts move y, the controller answers with u = -kp y: regressing y on u pulls the
    # estimate towards -1/kp (here 7 dB low at 0.5 Hz, averaged over 20 records). Against
    # the excitation, which the gusts do not touch, the mean is the truth within its own
    # scatter (3 standard errors) and the reported sigma describes the scatter (RMS
    # error/sigma within 0.5..2).
    direct, against, z = [], [], []
    for seed in range(20):
        r, u, y, g = closed_loop(400, 10, kp=3.0, gust_std=3.0, seed=seed)
        direct.append(estimate_fsf(u, y, FS_HZ, 0.5, discard_periods=1).gain / g)
        p = estimate_against_excitation(r, u, y, FS_HZ, 0.5)
        against.append(p.gain / g)
        z.append(abs(p.gain - g) / p.sigma)
    assert 20 * math.log10(abs(np.mean(direct))) < -4.0
    assert abs(np.mean(direct) - 1) > 3 * np.std(direct) / math.sqrt(len(direct))
    assert abs(np.mean(against) - 1) < 3 * np.std(against) / math.sqrt(len(against))
    assert 0.5 < math.sqrt(np.mean(np.square(z))) < 2.0


def test_an_excitation_the_input_does_not_follow_is_refused():
    r, _, y, _ = closed_loop(100, 4, kp=1.0, gust_std=0.0, seed=0)
    with pytest.raises(InputError, match="does not follow the excitation"):
        estimate_against_excitation(r, np.zeros_like(r), y, FS_HZ, 2.0)
    with pytest.raises(InputError, match="the logged excitation: the input is zero"):
        estimate_against_excitation(np.zeros_like(r), r, y, FS_HZ, 2.0)


# --- multisine: every line from one record ----------------------------------------------------

#: A 10 s base period (the roll model's impulse response is e^-25 of its start after it, so
#: the FSF's finite-impulse-response form is exact to round-off) and lines 0.3-5.5 Hz.
MS_PERIOD = 2000
MS_ORDERS = (3, 5, 8, 13, 21, 34, 55)


def multisine_input(periods, seed=0):
    k = np.arange(MS_PERIOD * periods)
    phases = np.random.default_rng(seed).uniform(0, 2 * np.pi, len(MS_ORDERS))
    return sum(0.2 * np.sin(2 * np.pi * h * k / MS_PERIOD + p) for h, p in zip(MS_ORDERS, phases))


def open_loop(u):
    import scipy.signal as sig

    Ad, Bd, Cd = roll_zoh()
    num, den = sig.ss2tf(Ad, Bd, Cd, np.zeros((1, 1)))
    return sig.lfilter(num[0], den, u)


def test_every_line_of_a_noise_free_multisine_is_exact_from_one_record():
    u = multisine_input(3)
    y = open_loop(u) + 0.2                        # from rest, with an output offset
    points = estimate_multisine(u, y, FS_HZ, MS_PERIOD, MS_ORDERS)
    assert [p.order for p in points] == list(MS_ORDERS)
    want = sampled_truth(np.exp(2j * np.pi * np.array(MS_ORDERS) / MS_PERIOD))
    got = np.array([p.gain for p in points])
    np.testing.assert_allclose(got / want, 1.0, atol=1e-6)
    assert [p.freq_hz for p in points] == pytest.approx(
        [FS_HZ * h / MS_PERIOD for h in MS_ORDERS], rel=1e-12)
    assert all(p.coherence == pytest.approx(1.0) for p in points)
    assert all(p.offset == pytest.approx(0.2, abs=1e-6) for p in points)


def test_the_recursive_and_batch_fsf_agree_on_a_multisine():
    u = multisine_input(3, seed=1)
    y = open_loop(u) + np.random.default_rng(2).normal(0, 0.05, u.size)
    p0 = 1e5
    batch = estimate_multisine(u, y, FS_HZ, MS_PERIOD, MS_ORDERS, p0=p0)
    rls = RecursiveFsf(MS_PERIOD, harmonics=MS_ORDERS, discard_periods=0, p0=p0)
    for a, b in zip(u, y):
        rls.update(a, b)
    for p in batch:
        assert abs(rls.gain(p.order) - p.gain) <= 1e-6 * abs(p.gain)


def test_each_line_s_sigma_describes_its_scatter_under_noise():
    z = []
    want = sampled_truth(np.exp(2j * np.pi * np.array(MS_ORDERS) / MS_PERIOD))
    for seed in range(10):
        u = multisine_input(4)
        y = open_loop(u) + np.random.default_rng(seed).normal(0, 0.2, u.size)
        points = estimate_multisine(u, y, FS_HZ, MS_PERIOD, MS_ORDERS)
        z += [abs(p.gain - w) / p.sigma for p, w in zip(points, want)]
        assert all(0 < p.coherence < 1 for p in points)
    assert 0.6 < math.sqrt(np.mean(np.square(z))) < 1.6


def test_a_closed_loop_multisine_against_the_excitation_is_exact_and_unbiased():
    want = sampled_truth(np.exp(2j * np.pi * np.array(MS_ORDERS) / MS_PERIOD))
    r = multisine_input(4)
    r, u, y, _ = closed_loop(MS_PERIOD, 4, kp=3.0, gust_std=0.0, seed=0, r=r)
    points = estimate_multisine_against_excitation(r, u, y, FS_HZ, MS_PERIOD, MS_ORDERS)
    np.testing.assert_allclose(np.array([p.gain for p in points]) / want, 1.0, atol=1e-5)
    assert all(p.estimate == "excitation" and p.coherence == pytest.approx(1.0) for p in points)
    # Gusts (as strong against each 0.2 line as the sine test's against its 1.0 sine): the
    # direct estimate is pulled towards -1/kp at the low lines; against the
    # excitation the mean over records is the truth within 3 standard errors.
    direct, against = [], []
    for seed in range(8):
        r, u, y, _ = closed_loop(MS_PERIOD, 4, kp=3.0, gust_std=0.6, seed=seed, r=r)
        direct.append([p.gain for p in estimate_multisine(u, y, FS_HZ, MS_PERIOD, MS_ORDERS)])
        against.append([p.gain for p in estimate_multisine_against_excitation(
            r, u, y, FS_HZ, MS_PERIOD, MS_ORDERS)])
    direct, against = np.array(direct) / want, np.array(against) / want
    low = direct[:, :3].ravel()                   # the three lowest lines, where gusts are
    assert abs(np.mean(low) - 1) > 3 * np.std(low) / math.sqrt(len(low))
    spread = np.std(against, axis=0) / math.sqrt(len(against))
    assert np.all(np.abs(np.mean(against, axis=0) - 1) < 3 * spread + 1e-9)


@pytest.mark.parametrize("period, orders, match", [
    (2000, (5, 3), "strictly increasing"),
    (2000, (0, 3), "positive"),
    (100, (3, 30), "at least 4 per cycle"),
    (1999.5, (3, 5), "whole number"),
])
def test_a_multisine_s_bad_lines_or_period_are_refused(period, orders, match):
    u = multisine_input(3)
    with pytest.raises(InputError, match=match):
        estimate_multisine(u, u, FS_HZ, period, orders)


# --- Records with samples lost on the link -----------------------------------------------

def lose(n, share, seed, keep_first_period=0):
    """A mask of the samples that arrived: each lost with probability ``share``."""
    present = np.random.default_rng(seed).random(n) >= share
    present[:keep_first_period] = True
    return present


def test_a_record_with_lost_samples_is_exact_without_noise():
    # 5 % of the samples lost at random (their values overwritten with garbage, which must not
    # be read): the excitation is completed from its period, the lost rows are left out,
    # and a noise-free closed loop's point is still exact, for a sine and for a multisine.
    r, u, y, g = closed_loop(40, 160, kp=3.0, gust_std=0.0, seed=0)
    present = lose(r.size, 0.05, seed=1)
    r, u, y = (np.where(present, x, 1e6) for x in (r, u, y))
    p = estimate_against_excitation(r, u, y, FS_HZ, FS_HZ / 40, discard_periods=80,
                                    present=present)
    assert abs(p.gain / g - 1) < 1e-5
    assert p.coherence_ry == pytest.approx(1.0) and p.coherence_ru == pytest.approx(1.0)
    period, orders = 200, (1, 3, 7)
    k = np.arange(period * 32)
    ms = sum(np.sin(2 * np.pi * l * k / period + l) for l in orders) / 3
    r, u, y, _ = closed_loop(period, 32, kp=3.0, gust_std=0.0, seed=0, r=ms)
    present = lose(r.size, 0.05, seed=2)
    full = estimate_multisine_against_excitation(r, u, y, FS_HZ, period, orders,
                                                 discard_periods=16)
    lossy = estimate_multisine_against_excitation(
        *(np.where(present, x, -1e6) for x in (r, u, y)), FS_HZ, period, orders,
        discard_periods=16, present=present)
    for a, b in zip(full, lossy):
        assert abs(b.gain / a.gain - 1) < 1e-5


def test_the_sigma_of_a_record_with_lost_samples_covers_its_error():
    # Gusts in the loop and 10 % of the samples lost: over 40 records the point's error
    # against the truth, over its sigma, has an RMS near one (0.7..1.4): the loss neither
    # hides nor invents precision. Without the loss correction the scatter of the filled
    # periods claims too much (the filled samples carry no noise), which the same bound
    # with 30 % lost would show.
    for share in (0.1, 0.3):
        z = []
        for seed in range(40):
            r, u, y, g = closed_loop(100, 20, kp=3.0, gust_std=3.0, seed=seed)
            present = lose(r.size, share, seed=100 + seed)
            p = estimate_against_excitation(r, u, y, FS_HZ, 2.0, present=present)
            z.append(abs(p.gain - g) / p.sigma)
        assert 0.7 < math.sqrt(np.mean(np.square(z))) < 1.4, share


def test_a_phase_lost_in_every_period_is_refused():
    from heliquad.host.estimate.fsf import complete_excitation

    present = np.ones(400, dtype=bool)
    present[7::40] = False
    with pytest.raises(InputError, match="same phase in every period"):
        complete_excitation(np.zeros(400), present, 40)
