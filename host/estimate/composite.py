"""Frequency responses from any record: overlapped, tapered windows of several lengths,
combined into one composite response with its coherence and random error per frequency.

The periodic estimators (:mod:`heliquad.host.estimate.fsf`) need an excitation whose period
is known: a dwell or a multisine. A chirp, a pilot's inputs or turbulence have none. For
those, the estimate rotorcraft engineers expect is CIFER's (Tischler and Remple, *Aircraft
and Rotorcraft System Identification*, 2nd ed., 2012, ch. 7-8): for each of several window
lengths ``T_w``, the record is cut into windows overlapping by :data:`OVERLAP`, each tapered
(Hann) and transformed, and the auto- and cross-spectra are averaged over the windows
(Welch). Each window length gives, at every frequency it resolves (at least
:data:`MIN_PERIODS` periods in a window), an estimate with its coherence ``gamma^2`` and its
normalised random error

    eps = sqrt(1 - gamma^2) / (|gamma| sqrt(2 n_d))

(Bendat and Piersol), ``n_d`` the number of independent averages: the windows' count
reduced for their overlap by Welch's formula for the taper (:func:`independent_averages`).
Long windows resolve low frequencies, short ones average more and are less noisy higher up;
the composite takes, at each frequency, the estimates of every length that resolves it,
each weighted by ``1 / eps^2``, and keeps the smallest ``eps`` as its own (the windows share
their data, so the estimates are not independent: their combination is no better than its
best part, said so rather than claimed).

The transform is evaluated at the requested frequencies themselves (a direct DFT of each
tapered window at those frequencies, as the chirp-z transform does), so no point is
interpolated between bins.

With an excitation ``r`` (a designed signal injected in a closed loop), the response is
conditioned on it as the periodic estimates are: ``G = G_ry / G_ru``, unbiased by the
loop's feedback of the disturbance; the coherence is the smaller of ``r``'s with ``y`` and
with ``u``, and the random errors of the two add in quadrature. Without one, ``G = G_uy /
G_uu`` (the H1 estimate, right for open-loop data or a loop whose input is not fed by the
output's noise).

A point's ``sigma`` (the standard deviation of the complex gain, as every point carries) is
``sqrt(2) eps |G|``: ``eps`` is the random error of the magnitude and, in radians, of the
phase.
"""

from __future__ import annotations

import math

import numpy as np

from ...sim.base.errors import InputError
from ..records.points import FrequencyPoint

__all__ = ["composite_response", "default_windows_s", "independent_averages",
           "window_estimates", "OVERLAP", "MIN_PERIODS", "WINDOWS"]

#: Windows overlap by this share of their length (CIFER's default).
OVERLAP = 0.8
#: A window length resolves a frequency with at least this many of its periods in a window.
MIN_PERIODS = 2.0
#: Window lengths by default, log-spaced between the longest and the shortest.
WINDOWS = 5
#: The longest window by default: this share of the record (so that it averages several).
LONGEST_SHARE = 0.5
#: The shortest window by default holds this many periods of the highest frequency (and is
#: never below 1/16 of the longest).
SHORTEST_PERIODS = 20.0
#: Coherence below this is too little for a point (CIFER's guideline for the composite).
MIN_COHERENCE = 0.6


def default_windows_s(duration_s: float, lo_hz: float, hi_hz: float,
                      count: int = WINDOWS) -> np.ndarray:
    """``count`` window lengths, log-spaced from half the record down to
    ``SHORTEST_PERIODS`` periods of ``hi_hz`` (or 1/16 of the longest); an InputError when
    even the longest cannot hold ``MIN_PERIODS`` periods of ``lo_hz``."""
    longest = LONGEST_SHARE * duration_s
    if longest * lo_hz < MIN_PERIODS:
        need = MIN_PERIODS / lo_hz / LONGEST_SHARE
        raise InputError(f"the record ({duration_s:.3g} s) is too short for {lo_hz:.3g} Hz: "
                         f"its longest window ({LONGEST_SHARE:g} of the record) must hold "
                         f"{MIN_PERIODS:g} periods, so the record at least {need:.3g} s")
    shortest = min(longest, max(SHORTEST_PERIODS / hi_hz, longest / 16.0))
    return np.geomspace(longest, shortest, count) if count > 1 else np.array([longest])


def _hann(n: int) -> np.ndarray:
    return 0.5 - 0.5 * np.cos(2.0 * np.pi * (np.arange(n) + 0.5) / n)


def independent_averages(n: int, hop: int, count: int, taper=None) -> float:
    """The number of independent averages ``count`` windows of ``n`` samples, ``hop`` apart,
    are worth (Welch 1967): ``count / (1 + 2 sum_j (1 - j/count) rho(j hop))``, ``rho`` the
    squared correlation of the taper with itself shifted."""
    w = _hann(n) if taper is None else taper
    power = float(np.sum(w ** 2)) ** 2
    total = 1.0
    for j in range(1, count):
        shift = j * hop
        if shift >= n:
            break
        rho = float(np.sum(w[:n - shift] * w[shift:])) ** 2 / power
        total += 2.0 * (1.0 - j / count) * rho
    return count / total


def _spectra(signals, fs_hz, freqs_hz, n, hop):
    """Each signal's tapered windows transformed at ``freqs_hz``: ``(X, count)``, ``X`` a
    list of (windows x frequencies) arrays; each window's mean removed."""
    length = signals[0].size
    count = 1 + (length - n) // hop
    starts = hop * np.arange(count)
    taper = _hann(n)
    kernel = np.exp(-2j * np.pi * np.outer(np.arange(n), freqs_hz) / fs_hz)    # n x f
    index = starts[:, None] + np.arange(n)[None, :]
    out = []
    for x in signals:
        seg = x[index]
        seg = (seg - seg.mean(axis=1, keepdims=True)) * taper
        out.append(seg @ kernel)
    return out, count


def _random_error(coherence, n_d):
    """Bendat and Piersol's normalised random error of a frequency response."""
    with np.errstate(divide="ignore", invalid="ignore"):
        c = np.clip(coherence, 0.0, 1.0)
        return np.sqrt(1.0 - c) / (np.sqrt(c) * math.sqrt(2.0 * n_d))


def window_estimates(y, u, fs_hz, freqs_hz, window_s, r=None, overlap: float = OVERLAP):
    """One window length's estimate at the frequencies it resolves: a dict of arrays
    (``freq_hz``, ``gain``, ``coherence``, ``coherence_ry``, ``coherence_ru``, ``eps``,
    ``input_gain``) and ``n_d``, or None when it resolves none of them or the record holds
    fewer than two windows of it."""
    n = int(round(window_s * fs_hz))
    hop = max(1, int(round(n * (1.0 - overlap))))
    if n < 8 or y.size < n + hop:
        return None
    f = np.asarray(freqs_hz, dtype=float)
    f = f[(f * n / fs_hz >= MIN_PERIODS) & (f < fs_hz / 2)]
    if not f.size:
        return None
    signals = [y, u] + ([r] if r is not None else [])
    X, count = _spectra(signals, fs_hz, f, n, hop)
    n_d = independent_averages(n, hop, count)
    Y, U = X[0], X[1]
    gyy, guu = np.mean(np.abs(Y) ** 2, axis=0), np.mean(np.abs(U) ** 2, axis=0)
    guy = np.mean(np.conj(U) * Y, axis=0)
    nan = np.full(f.size, np.nan)
    with np.errstate(divide="ignore", invalid="ignore"):
        if r is None:
            gain = guy / guu
            coherence = np.abs(guy) ** 2 / (guu * gyy)
            eps = _random_error(coherence, n_d)
            c_ry, c_ru, input_gain = nan, nan, nan * (1 + 1j)
        else:
            R = X[2]
            grr = np.mean(np.abs(R) ** 2, axis=0)
            gry, gru = np.mean(np.conj(R) * Y, axis=0), np.mean(np.conj(R) * U, axis=0)
            gain = gry / gru
            c_ry = np.abs(gry) ** 2 / (grr * gyy)
            c_ru = np.abs(gru) ** 2 / (grr * guu)
            coherence = np.minimum(c_ry, c_ru)
            eps = np.hypot(_random_error(c_ry, n_d), _random_error(c_ru, n_d))
            input_gain = gru / grr
    return {"freq_hz": f, "gain": gain, "coherence": coherence, "coherence_ry": c_ry,
            "coherence_ru": c_ru, "eps": eps, "input_gain": input_gain, "n_d": n_d,
            "window_s": n / fs_hz}


def composite_response(y, u, fs_hz: float, freqs_hz, r=None, windows_s=None,
                       overlap: float = OVERLAP) -> list:
    """The composite frequency response of ``y`` over ``u`` (conditioned on ``r`` when
    given) at ``freqs_hz``, one :class:`~heliquad.host.records.points.FrequencyPoint` per
    frequency some window resolves with a finite random error (``method`` "composite").

    ``y``, ``u`` (and ``r``): equally long records sampled at ``fs_hz``, every sample
    present (fill holes before). ``windows_s``: the window lengths (default
    :func:`default_windows_s` over the frequencies asked for)."""
    y, u = (np.asarray(x, dtype=float) for x in (y, u))
    r = None if r is None else np.asarray(r, dtype=float)
    freqs = np.sort(np.asarray(freqs_hz, dtype=float))
    if y.shape != u.shape or (r is not None and r.shape != y.shape) or y.ndim != 1:
        raise InputError("the record's input, output and excitation must be equally long")
    if not freqs.size or not np.all(np.isfinite(freqs)) or freqs[0] <= 0:
        raise InputError("the frequencies must be positive")
    if not all(np.all(np.isfinite(x)) for x in (y, u) + ((r,) if r is not None else ())):
        raise InputError("the record has samples that are not numbers")
    if freqs[-1] >= fs_hz / 2:
        raise InputError(f"{freqs[-1]:.4g} Hz is not below the record's Nyquist frequency "
                         f"({fs_hz / 2:.4g} Hz)")
    duration = y.size / fs_hz
    if windows_s is None:
        windows_s = default_windows_s(duration, freqs[0], freqs[-1])
    found = [w for w in (window_estimates(y, u, fs_hz, freqs, T, r, overlap)
                         for T in windows_s) if w is not None]
    points = []
    for f in freqs:
        parts = []
        for w in found:
            i = np.flatnonzero(w["freq_hz"] == f)
            if i.size and np.isfinite(w["eps"][i[0]]) and np.isfinite(w["gain"][i[0]]):
                parts.append((w, i[0]))
        if not parts:
            continue
        eps = np.array([w["eps"][i] for w, i in parts])
        weight = 1.0 / np.maximum(eps, 1e-12) ** 2
        weight /= weight.sum()
        pick = lambda key: complex(sum(k * w[key][i] for k, (w, i) in zip(weight, parts)))  # noqa: E731
        gain = pick("gain")
        best = float(eps.min())
        points.append(FrequencyPoint(
            omega_rad_s=2 * math.pi * float(f), gain=gain,
            sigma=math.sqrt(2.0) * best * abs(gain), coherence=pick("coherence").real,
            method="composite", estimate="input" if r is None else "excitation",
            coherence_ry=pick("coherence_ry").real, coherence_ru=pick("coherence_ru").real,
            input_gain=pick("input_gain") if r is not None else complex("nan+nanj")))
    return points
