"""A model's replay of a sweep's records: the measured input pushed through the model, set
against the measured output.

A sweep measures each frequency over whole periods of the excitation (``period_samples``,
the period the FSF analyses). After the periods identification discards (the transient
after the fade-in), the input's mean period (its synchronous average over the whole periods
left: the part of the input that repeats with the excitation, its fundamental and
harmonics) is taken through the model in the frequency domain: its DFT, each harmonic ``l``
multiplied by ``G(j l omega)`` (the delay included), transformed back and repeated over the
periods. That is the model's periodic steady state for that input, exact when the record is
periodic. What the input holds that does not repeat with the excitation (in a closed loop,
the controller's answer to a gust or to sensor noise) is not replayed: its effect on the
output is mixed with the disturbance it answers, which the model does not know. The DC term
is left out too: a constant in the input (trim) or the output (a gyro's bias) lies outside
the band the model was fitted to, so the replay carries the measured output's mean.

The replay error of a frequency is ``rms(y - replay) / rms(y - mean(y))`` over the replayed
samples: 0 when the model explains the output; what it does not explain is the model's own
error, the part of the output that does not repeat (noise, turbulence, a transient that has
not died out) and a nonlinearity.

Nothing here is used to estimate points or to choose a model: it is a check of the
recommended one, drawn in responses.png and listed by ``heliquad report``.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from ...sim.base.errors import InputError
from ..estimate.fsf import DEFAULT_DISCARD_PERIODS

__all__ = ["Replay", "replay_record", "replay_points"]


@dataclasses.dataclass(frozen=True)
class Replay:
    """One frequency's replay.

    Attributes
    ----------
    freq_hz : float
        The excitation frequency.
    start : int
        Index, into the record, of the first replayed sample (after the discarded periods).
    y : numpy.ndarray
        The model's periodic steady-state output for the input's mean period, over the whole
        periods from ``start`` on, plus the measured output's mean over them.
    periods : int
        Whole periods replayed.
    nrmse : float
        ``rms(y_measured - y) / rms(y_measured - mean)`` over the same samples (NaN for an
        output that does not vary).
    """

    freq_hz: float
    start: int
    y: np.ndarray
    periods: int
    nrmse: float


def replay_record(response, u, y, fs_hz: float, period_samples,
                  discard_periods: int = DEFAULT_DISCARD_PERIODS) -> Replay:
    """The replay of one record (input ``u``, output ``y``, sampled at ``fs_hz``, excited with
    a period of ``period_samples``, a whole number): ``response(omega_rad_s)``, the model's
    complex frequency response (for instance ``TfModel.response``), applied to the input's
    mean period over the whole periods after ``discard_periods``."""
    u, y = np.asarray(u, float), np.asarray(y, float)
    if u.shape != y.shape or u.ndim != 1:
        raise InputError("input and output must be one-dimensional and of equal length")
    period = int(round(period_samples))
    if period < 2 or abs(period - period_samples) > 1e-9 * period:
        raise InputError(f"a replay needs a whole period of at least 2 samples, got "
                         f"{period_samples:g}")
    start = int(discard_periods) * period
    periods = (u.size - start) // period
    if periods < 1:
        raise InputError(f"a record of {u.size} samples has no whole period of {period} after "
                         f"the {discard_periods} discarded")
    n = periods * period
    y_rec = y[start:start + n]
    mean_period = u[start:start + n].reshape(periods, period).mean(axis=0)
    spectrum = np.fft.rfft(mean_period)
    gain = np.zeros(spectrum.size, complex)
    gain[1:] = response(2 * np.pi * fs_hz * np.arange(1, spectrum.size) / period)
    replay = np.tile(np.fft.irfft(gain * spectrum, period), periods)
    varying = y_rec - y_rec.mean()
    spread = math.sqrt(float(np.mean(varying ** 2)))
    misfit = math.sqrt(float(np.mean((varying - replay) ** 2)))
    return Replay(freq_hz=fs_hz / period, start=start, y=replay + y_rec.mean(), periods=periods,
                  nrmse=misfit / spread if spread > 0 else math.nan)


def replay_points(model, points, records, discard_periods: int = DEFAULT_DISCARD_PERIODS):
    """The replay through ``model`` (a :class:`~heliquad.host.estimate.fit.TfModel`) of each record
    ``(freq_hz, t_s, u, y)`` that the point beside it (a
    :class:`~heliquad.host.records.points.FrequencyPoint`; a multisine's record: any of its lines) was
    estimated from, at that point's (base) period: every line of the record is replayed."""
    out = []
    for p, (_, _, u, y) in zip(points, records):
        fs_hz = p.omega_rad_s * p.period_samples / (2 * np.pi * p.order)
        out.append(replay_record(model.response, u, y, fs_hz, p.period_samples, discard_periods))
    return out
