"""Frequency responses from any record (host/estimate/composite.py): a chirp through the
paper's roll model, open and closed loop, noise and its stated random error."""

import math

import numpy as np
import pytest
import scipy.signal

from heliquad.host.estimate.composite import (MIN_COHERENCE, composite_response,
                                              default_windows_s, independent_averages)
from heliquad.host.records import paper
from heliquad.sim.base.errors import InputError

FS = 200.0
ROLL = paper.MODELS["roll"][(0, 2)]
FREQS = np.geomspace(0.5, 4.5, 15)


def chirp(duration_s=60.0, f0=0.3, f1=6.0, fade_s=2.0):
    """A log sweep from f0 to f1, faded in and out (the excitation ArduPilot's SystemID mode
    and heliquad's firmware fly)."""
    t = np.arange(int(duration_s * FS)) / FS
    k = math.log(f1 / f0) / duration_s
    fade = np.clip(np.minimum(t, duration_s - t) / fade_s, 0.0, 1.0)
    return fade * np.sin(2 * math.pi * f0 * np.expm1(k * t) / k)


def plant():
    """The roll model held at 200 Hz (zero-order hold): its difference equation and its
    exact frequency response at FREQS (the hold's response is exact in discrete time)."""
    b, a, _ = scipy.signal.cont2discrete(ROLL, 1 / FS, method="zoh")
    b = np.squeeze(b)
    z = np.exp(2j * math.pi * FREQS / FS)
    return b, a, np.polyval(b, z) / np.polyval(a, z)


def errors(points, truth):
    H = np.array([p.gain for p in points])
    ratio = H / truth
    return (np.abs(20 * np.log10(np.abs(ratio))), np.abs(np.degrees(np.angle(ratio))),
            np.abs(H - truth) / np.array([p.sigma for p in points]))


def test_a_noise_free_chirp_gives_the_model_within_a_quarter_dB_and_one_and_a_half_deg():
    b, a, truth = plant()
    u = chirp()
    points = composite_response(scipy.signal.lfilter(b, a, u), u, FS, FREQS)
    assert len(points) == FREQS.size
    db, deg, _ = errors(points, truth)
    # the windows' taper smears a sweep whose frequency moves within them: 0.20 dB, 1.25 deg
    assert db.max() < 0.25 and deg.max() < 1.5
    assert all(p.method == "composite" and p.estimate == "input" for p in points)
    assert min(p.coherence for p in points) > 0.98       # 0.982: the same smear


def test_the_stated_random_error_is_the_error_found_over_twenty_noisy_records():
    b, a, truth = plant()
    u = chirp()
    y0 = scipy.signal.lfilter(b, a, u)
    ratios = []
    for seed in range(20):
        y = y0 + 0.05 * np.random.default_rng(seed).normal(size=u.size)
        ratios.append(errors(composite_response(y, u, FS, FREQS), truth)[2])
    rms = np.sqrt(np.mean(np.square(ratios), axis=0))
    # per frequency over 20 records (sampling spread of an RMS of 20: about +/- 30 %) and
    # the bias above: the error over sigma between 0.35 and 1.6, 0.97 over all of them
    assert np.all((rms > 0.35) & (rms < 1.6)), rms
    assert 0.7 < math.sqrt(np.mean(np.square(ratios))) < 1.3


def closed_loop(seed, disturbance):
    """The roll model under a proportional rate loop (kp = KP) whose measured rate carries a
    low-frequency disturbance of the given size (turbulence-like: the loop feeds it back
    into the input), the chirp injected at the loop's input. Returns (r, u, y) as logged,
    y the measured rate, and the model's response at FREQS."""
    b, a, truth = plant()
    r = chirp()
    d = scipy.signal.lfilter([0.02], [1, -0.98],
                             np.random.default_rng(seed).normal(size=r.size)) * disturbance
    zi = np.zeros(max(len(a), len(b)) - 1)
    u, y = np.zeros(r.size), np.zeros(r.size)
    for k in range(r.size):
        u[k] = r[k] - KP * (y[k - 1] if k else 0.0)
        out, zi = scipy.signal.lfilter(b, a, [u[k]], zi=zi)
        y[k] = out[0] + d[k]
    return r, u, y, truth


KP = 0.6


def test_in_closed_loop_the_estimate_against_the_excitation_keeps_its_stated_error():
    r, u, y, truth = closed_loop(3, 1.0)
    points = composite_response(y, u, FS, FREQS, r=r)
    assert all(p.estimate == "excitation" and p.coherence == min(p.coherence_ry, p.coherence_ru)
               for p in points)
    coherent = np.array([p.coherence for p in points]) >= MIN_COHERENCE
    assert coherent.sum() >= 11                  # the top ones fall to the disturbance
    over_sigma = errors(points, truth)[2][coherent]
    assert over_sigma.max() < 3.0 and np.sqrt(np.mean(over_sigma ** 2)) < 2.0
    # U/R is the loop's sensitivity to the injection, 1 / (1 + kp G)
    got = np.array([p.input_gain for p in points])
    assert np.max(np.abs(got * (1 + KP * truth) - 1)[coherent]) < 0.1


def test_in_closed_loop_the_direct_estimate_is_biased_and_the_one_against_the_excitation_is_not():
    # A disturbance the loop feeds back pulls the direct estimate G_uy / G_uu towards
    # -1 / kp; conditioned on the excitation it is not pulled. Means of 10 records at the
    # six lowest frequencies, where the disturbance lives.
    low = FREQS[:6]
    against_r, direct = [], []
    for seed in range(10):
        r, u, y, truth = closed_loop(seed, 6.0)
        against_r.append([p.gain for p in composite_response(y, u, FS, low, r=r)])
        direct.append([p.gain for p in composite_response(y, u, FS, low)])
    truth = truth[:6]
    phase = lambda found: np.degrees(np.angle(np.mean(found, axis=0) / truth))  # noqa: E731
    db = lambda found: 20 * np.log10(np.abs(np.mean(found, axis=0) / truth))     # noqa: E731
    assert np.all(np.abs(db(against_r)) < 1.5) and np.all(np.abs(phase(against_r)) < 5.0)
    assert np.all(phase(direct) < -7.0)          # 7-18 deg behind, every frequency


def test_windows_and_their_independent_averages():
    w = default_windows_s(60.0, 0.5, 4.5)
    assert w[0] == 30.0 and w.size == 5 and np.all(np.diff(w) < 0)
    assert w[-1] == pytest.approx(max(20 / 4.5, 30 / 16))
    # no overlap: every window independent; 80 % overlap with a Hann taper: Welch's figure
    assert independent_averages(100, 100, 6) == pytest.approx(6.0)
    overlapped = independent_averages(1000, 200, 21)
    assert 8.0 < overlapped < 12.0


def test_a_record_too_short_for_its_lowest_window_is_one_line():
    u = chirp(duration_s=6.0)
    with pytest.raises(InputError, match=r"the record \(6 s\) is too short for 0.5 Hz: its "
                                         r"longest window \(0.5 of the record\) must hold 2 "
                                         r"periods, so the record at least 8 s"):
        composite_response(u, u, FS, FREQS)


@pytest.mark.parametrize("case, match", [
    ("nyquist", "100 Hz is not below the record's Nyquist frequency"),
    ("lengths", "must be equally long"),
    ("nan", "the record has samples that are not numbers"),
])
def test_bad_records_are_refused_in_one_line(case, match):
    u = chirp()
    y, freqs = u.copy(), FREQS
    if case == "nyquist":
        freqs = [1.0, 100.0]
    elif case == "lengths":
        y = y[:-1]
    else:
        y[5] = np.nan
    with pytest.raises(InputError, match=match):
        composite_response(y, u, FS, freqs)
