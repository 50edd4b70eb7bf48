"""Baseline estimators of one frequency-response point, for comparison with the FSF.

* :func:`estimate_dft`: the single-bin DFT ratio ``Y(omega) / U(omega)`` over the whole
  periods after settling: what a careful user computes by hand.
* :func:`estimate_h1`: Welch's H1 estimator ``S_uy / S_uu`` (scipy.signal.csd) with its
  magnitude-squared coherence, read at the excitation frequency; segments hold an integer
  number of periods so the frequency falls on a bin.
"""

from __future__ import annotations

import math

import numpy as np
import scipy.signal

from ...sim.base.errors import InputError
from ..records.points import FrequencyPoint
from .fsf import _check_signals

__all__ = ["estimate_dft", "estimate_h1"]

#: Welch averages aimed for when choosing the segment length (Hann window, 50 % overlap).
H1_TARGET_SEGMENTS = 8


def _period(fs_hz, freq_hz):
    period = fs_hz / freq_hz
    whole = round(period)
    if abs(period - whole) > 1e-9 * period:
        raise InputError(f"baselines need an integer period; {period:.6g} samples is not")
    return whole


def estimate_dft(u, y, fs_hz, freq_hz, discard_periods=1) -> FrequencyPoint:
    """Single-bin DFT ratio over the whole periods after ``discard_periods``."""
    u, y = _check_signals(u, y)
    period = _period(fs_hz, freq_hz)
    start = discard_periods * period
    n_periods = (u.size - start) // period
    if n_periods < 1:
        raise InputError("record too short for the DFT baseline")
    k = np.arange(start, start + n_periods * period)
    z = np.exp(-2j * np.pi * (k % period) / period)
    gain = complex(np.dot(y[k], z) / np.dot(u[k], z))
    return FrequencyPoint(omega_rad_s=2 * math.pi * fs_hz / period, gain=gain,
                          sigma=float("nan"), coherence=float("nan"),
                          period_samples=float(period), n_periods=int(n_periods),
                          method="dft", harmonics={1: gain})


def estimate_h1(u, y, fs_hz, freq_hz, discard_periods=1, nperseg=None) -> FrequencyPoint:
    """Welch H1 estimate ``S_uy / S_uu`` and coherence at ``freq_hz``."""
    u, y = _check_signals(u, y)
    period = _period(fs_hz, freq_hz)
    start = discard_periods * period
    u, y = u[start:], y[start:]
    if nperseg is None:
        # K half-overlapping segments of length L span L (K + 1) / 2 samples.
        periods_per_seg = max(1, (2 * u.size // (H1_TARGET_SEGMENTS + 1)) // period)
        nperseg = period * periods_per_seg
    if nperseg > u.size:
        raise InputError("record too short for the H1 baseline")
    f, s_uy = scipy.signal.csd(u, y, fs=fs_hz, nperseg=nperseg)
    _, s_uu = scipy.signal.csd(u, u, fs=fs_hz, nperseg=nperseg)
    _, s_yy = scipy.signal.csd(y, y, fs=fs_hz, nperseg=nperseg)
    i = int(round(freq_hz * nperseg / fs_hz))
    gain = complex(s_uy[i] / s_uu[i])
    coh = float(np.abs(s_uy[i]) ** 2 / (s_uu[i].real * s_yy[i].real))
    return FrequencyPoint(omega_rad_s=2 * math.pi * f[i], gain=gain, sigma=float("nan"),
                          coherence=coh, period_samples=float(period),
                          n_periods=int(u.size // period), method="h1", harmonics={1: gain})
