"""Experiment design for a sweep under disturbance: how hard to excite each frequency, and
for how long.

On a rig the loop is closed and the air is not still. A fixed small amplitude leaves the
response buried (at the mixer, 0.05 swings the roll rig by +/-0.4 deg: the loop cancels most
of the excitation) and a fixed dwell spends as long on a clean frequency as on a noisy one.

* **Amplitude** (mixer injection): each frequency's amplitude aims at a swing of the rig of
  ``swing_deg`` (default 10 deg; the rigs allow +/-80 deg, the firmware's abort limit, and
  the published experiments swung +/-5 to 80 deg). The response per unit of excitation is
  what the previous frequency measured (rate over excitation, at its fundamental), so no
  model is assumed; the first frequency starts at a quarter of the firmware's bound, each
  step changes the amplitude by at most 4x, and no amplitude passes the firmware's bound.
  Near the loop's crossover the loop amplifies the excitation at the plant input (the
  input per unit of excitation, ``|U/R| = 1 / |1 + L|``, reaches 2 on the roll rig at 10 Hz):
  the amplitude is also held so that the input, as the previous frequency measured it,
  swings at most half the bound (at a full-bound input the rotors' thrust is far from
  linear; measured, the loop broken at the plant input then reads a gain margin of 5.2 dB
  where the truth is 1.6 dB, and 1.8 dB at a fifth of the bound).
  Angle and rate injection keep their fixed amplitudes, which are already responses (a
  5 deg angle or 10 deg/s rate setpoint).
* **Dwell** (sequential): the excitation is started for the most cycles the frequency may
  have (``max_cycles``, and at most ``max_dwell_s`` of full amplitude, never fewer than
  ``min_cycles``); from ``min_cycles`` on, after every whole period the host estimates the
  point against the excitation and, once its relative standard deviation is at most
  ``target_sigma``, asks the firmware to finish (HQ_EXCITATION_FINISH: the cycle under way
  completes, then the planned fade-out). A clean frequency costs ``min_cycles``; a noisy one
  runs until it is known or the cap.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from ...sim.base.errors import InputError
from .redesign import combined_sigmas

__all__ = ["Dwell", "AmplitudeDesign", "SequentialMultisine", "response_per_unit",
           "line_sdr", "SEQUENTIAL_RIG_TIME_S",
           "TARGET_SWING_DEG", "TARGET_SIGMA", "MIN_CYCLES", "MAX_CYCLES", "MAX_DWELL_S"]

#: The rig's swing each designed amplitude aims at, deg.
TARGET_SWING_DEG = 10.0
#: A dwell ends when its point's standard deviation is this fraction of its magnitude or less
#: (2 %: 0.17 dB and 1.15 deg, so the worst of 15 points, near 2.5 sigma, stays within about
#: 0.5 dB and 3 deg).
TARGET_SIGMA = 0.02
#: The published dwell's measured cycles: the least any frequency gets.
MIN_CYCLES = 8
#: The most measured cycles a frequency gets, and the most time at full amplitude.
MAX_CYCLES = 48
MAX_DWELL_S = 60.0
#: A sequential multisine's rig time at most, fades included, s (the cap its periods fill).
SEQUENTIAL_RIG_TIME_S = 180.0
#: The first designed amplitude, as a fraction of the firmware's bound; the largest change
#: from one frequency to the next.
START_FRACTION = 0.25
MAX_STEP = 4.0
#: The most the axis's command (excitation and the loop's answer) may swing, as a fraction
#: of the firmware's bound.
INPUT_FRACTION = 0.5


@dataclasses.dataclass
class Dwell:
    """The sequential dwell's rule (module docstring)."""
    min_cycles: int = MIN_CYCLES
    max_cycles: int = MAX_CYCLES
    target_sigma: float = TARGET_SIGMA
    max_dwell_s: float = MAX_DWELL_S

    def cycles(self, freq_hz: float) -> int:
        """The cycles to start a frequency's excitation with: its cap."""
        return max(self.min_cycles, min(self.max_cycles, int(self.max_dwell_s * freq_hz)))

    def relative_sigma(self, r, u, y, fs_hz: float, freq_hz: float, present=None) -> float:
        """The point's sigma over its magnitude, from the record so far (inf when it cannot
        be estimated yet); ``present``: which samples arrived (None: all)."""
        # the estimator (estimate.fsf, 17 ms) when a dwell is judged: sil and --help need not wait
        from ..estimate.fsf import estimate_against_excitation
        try:
            p = estimate_against_excitation(np.asarray(r), np.asarray(u), np.asarray(y), fs_hz,
                                            freq_hz, discard_periods=1, present=present)
        except InputError:
            return math.inf
        return p.sigma / abs(p.gain) if abs(p.gain) > 0 else math.inf


@dataclasses.dataclass
class SequentialMultisine:
    """The sequential multisine's rule: whole base periods, from ``min_periods`` on, until
    every line's sigma over its magnitude is ``target_sigma`` or less (the dwell's target,
    for each line at once), or the periods its rig time holds have run. ``prior``: per line,
    the sigma over magnitude of an earlier pass on the same lines (:mod:`.redesign`), which
    each line's estimate is judged combined with."""
    target_sigma: float = TARGET_SIGMA
    min_periods: int = 3
    prior: tuple | None = None

    def met(self, sigmas, used: int) -> bool:
        """Whether every line is known well enough: ``sigmas`` this pass's over ``used``
        whole periods, with the period under way added (the dwell's rule, ``sqrt(used /
        (used + 1))``), combined with :attr:`prior`, ``(sigmas, used periods, amplitudes
        then, amplitudes now)``, as identify combines the passes
        (:func:`.redesign.combined_sigmas`)."""
        if used < 1:
            return False
        now = np.asarray(sigmas, dtype=float) * math.sqrt(used / (used + 1))
        if not np.all(np.isfinite(now)):                 # this pass must know every line
            return False
        if self.prior is not None:
            before, periods, then, amps = self.prior
            s = np.column_stack([[np.nan if v is None else v for v in before], now])
            now = combined_sigmas(s, np.column_stack([then, amps]), [periods, used + 1])
        return float(np.max(now)) <= self.target_sigma

    def relative_sigmas(self, r, u, y, fs_hz: float, period: int, orders,
                        present=None) -> np.ndarray:
        """Each line's sigma over its magnitude from the record so far (inf for a line not
        estimated yet), in the order of ``orders``."""
        # the estimator (estimate.fsf) when a multisine is judged: sil and --help need not wait
        from ..estimate.fsf import estimate_multisine_against_excitation
        try:
            found = {p.order: p for p in estimate_multisine_against_excitation(
                np.asarray(r), np.asarray(u), np.asarray(y), fs_hz, period, orders,
                discard_periods=1, present=present)}
        except InputError:
            return np.full(len(orders), math.inf)
        return np.array([found[h].sigma / abs(found[h].gain)
                         if h in found and abs(found[h].gain) > 0 else math.inf
                         for h in orders])


def line_sdr(y, period: int, orders, present=None) -> list:
    """Each line's signal-to-disturbance ratio in the output ``y``: over the whole periods
    after the first (none with a lost sample), the magnitude of the line's mean over them
    against the RMS of its scatter about that mean; None where fewer than two periods or no
    scatter."""
    y = np.asarray(y, dtype=float)
    n = y.size // period
    periods = y[:n * period].reshape(n, period)[1:]
    if present is not None:
        keep = np.asarray(present[:n * period], dtype=bool).reshape(n, period)[1:].all(axis=1)
        periods = periods[keep]
    if periods.shape[0] < 2:
        return [None] * len(orders)
    lines = np.fft.rfft(periods, axis=1)[:, list(orders)]
    mean = lines.mean(axis=0)
    scatter = np.sqrt(np.mean(np.abs(lines - mean) ** 2, axis=0))
    return [float(abs(m) / s) if s > 0 else None for m, s in zip(mean, scatter)]


def response_per_unit(r, y, fs_hz: float, freq_hz: float, present=None) -> float:
    """``|Y/R|`` at the fundamental: the output (rate) per unit of excitation; NaN when the
    record does not give it. ``present``: which samples arrived (None: all)."""
    # the estimator (estimate.fsf, 17 ms) when a dwell is judged: sil and --help need not wait
    from ..estimate.fsf import complete_excitation, estimate_fsf
    try:
        if present is not None:
            r = complete_excitation(r, present, round(fs_hz / freq_hz))
            y = np.where(present, y, 0.0)
        return abs(estimate_fsf(np.asarray(r), np.asarray(y), fs_hz, freq_hz,
                                discard_periods=1, present=present).gain)
    except InputError:
        return math.nan


@dataclasses.dataclass
class AmplitudeDesign:
    """Amplitudes aimed at a swing of ``swing_deg`` (module docstring), mixer injection."""
    bound: float
    swing_deg: float = TARGET_SWING_DEG

    def first(self) -> float:
        return START_FRACTION * self.bound

    def next(self, freq_hz: float, last_amplitude: float, rate_per_unit: float,
             input_per_unit: float = math.nan) -> float:
        """The amplitude for ``freq_hz`` after a frequency excited with ``last_amplitude``
        answered ``rate_per_unit`` (rad/s of rate per unit of excitation) and
        ``input_per_unit`` (the axis's command per unit of excitation; NaN if unknown)."""
        lo, hi = last_amplitude / MAX_STEP, min(self.bound, last_amplitude * MAX_STEP)
        if input_per_unit > 0 and math.isfinite(input_per_unit):
            hi = min(hi, INPUT_FRACTION * self.bound / input_per_unit)
            lo = min(lo, hi)
        if not (rate_per_unit > 0 and math.isfinite(rate_per_unit)):
            return min(max(last_amplitude, lo), hi)
        # A swing of A rad at w rad/s is a rate of A w.
        want = math.radians(self.swing_deg) * 2 * math.pi * freq_hz / rate_per_unit
        return min(max(want, lo), hi)
