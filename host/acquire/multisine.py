"""Multisine excitation: the whole band in one periodic record (``heliquad sweep --signal
multisine``).

A multisine is a sum of sines at chosen harmonics ``h`` of one base period of ``N`` loop
samples, ``r(k) = sum_h a_h sin(2 pi h k / N + phi_h)``. Every excited harmonic is a
frequency-response point of the same record (the FSF estimates them all at once,
:func:`heliquad.host.estimate.fsf.estimate_multisine`), where the paper's dwell needs one record,
with its own fades and settling, per frequency.

Design (:func:`design`):

* **Lines.** ``lines`` log-spaced frequencies over the band, each moved to the nearest
  harmonic of the base frequency (duplicates dropped): as in the dwell, the points are
  evenly spread on the Bode plot's axis. The base frequency is the band's lowest edge over
  ``h_min``: of the grids whose ``min_periods`` whole periods and fades fit ``rig_time_s``,
  the one with the most distinct lines, and of those the most whole periods.
* **Phases** for a low crest factor (peak over RMS): Schroeder's phases, generalised to
  harmonics that are not consecutive (each line's phase advances by the power of the lines
  below it times its distance from the previous one, as a chirp would visit them), then
  improved by iterative clipping (clip the period's peaks, keep the clipped signal's
  phases at the excited lines, repeat; the best is kept). On the paper's bands this gives a
  crest factor near 1.9 for equal amplitudes, where zero phases give 3.6 and Schroeder's
  alone 2.9: at the same peak, each line gets about twice the power of a naive design.
* **Peak.** The firmware bounds the peak like a sine's amplitude and checks every sample
  against the peak the request declares; the design scales the lines so that the period's
  peak, computed here in double precision, is ``peak``.
* **Fades** of ``fade_cycles`` cycles of the lowest line (the firmware's rule), so the
  vehicle is not kicked and the measured periods start settled.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from ...sim.base import firmware_facts
from ...sim.base.errors import InputError

__all__ = ["Multisine", "design", "synthesise", "schroeder_phases", "low_crest_phases", "crest_factor",
           "LINES", "MAX_LINES", "RIG_TIME_S", "MIN_PERIODS", "FADE_CYCLES"]

#: Lines of a multisine: the dwell's 15 frequencies; the most HQ_EXCITATION carries.
LINES = 15
MAX_LINES = firmware_facts.MAX_HARMONICS
#: The rig time a multisine aims at, fades included, s.
RIG_TIME_S = 60.0
#: Whole base periods at full amplitude: the FSF's first fills its filter (the settling
#: after the fade-in), the rest are regression rows and give each line's coherence.
MIN_PERIODS = 3
#: Fade in (and out) over this many cycles of the lowest line.
FADE_CYCLES = 1
#: The finest grid tried: the lowest line is at most this harmonic of the base period.
MAX_LOWEST_ORDER = 8
#: Iterations of the clipping that lowers the crest factor.
CLIP_ITERATIONS = 200


@dataclasses.dataclass(frozen=True)
class Multisine:
    """One multisine: base period, lines, amplitudes, phases, declared peak and length."""

    fs_hz: float
    period_samples: int
    orders: tuple
    amplitudes: tuple
    phases: tuple
    peak: float
    periods: int
    fade_cycles: int = FADE_CYCLES

    @property
    def base_hz(self) -> float:
        return self.fs_hz / self.period_samples

    @property
    def freqs_hz(self) -> np.ndarray:
        return np.asarray(self.orders, dtype=float) * self.base_hz

    @property
    def fade_samples(self) -> int:
        """The firmware's fade: whole cycles of the lowest line, rounded up."""
        return self.fade_cycles * -(-self.period_samples // self.orders[0])

    @property
    def duration_s(self) -> float:
        """The excitation's length, fades included (the rig time it costs)."""
        return (self.period_samples * self.periods + 2 * self.fade_samples) / self.fs_hz

    @property
    def crest_factor(self) -> float:
        """The period's peak over its RMS."""
        return crest_factor(self.period())

    def harmonics(self) -> list:
        """``[(order, amplitude, phase_rad), ...]`` as HQ_EXCITATION carries them."""
        return list(zip(self.orders, self.amplitudes, self.phases))

    def period(self) -> np.ndarray:
        """One period of the signal, in double precision."""
        return synthesise(self.orders, self.amplitudes, self.phases, self.period_samples)

    def record(self) -> dict:
        """The design, for the manifest."""
        return {"signal": "multisine", "base_hz": self.base_hz,
                "period_samples": self.period_samples, "orders": list(self.orders),
                "freqs_hz": [float(f) for f in self.freqs_hz],
                "amplitudes": list(self.amplitudes), "phases_rad": list(self.phases),
                "peak": self.peak, "crest_factor": self.crest_factor,
                "periods": self.periods, "fade_cycles": self.fade_cycles,
                "duration_s": self.duration_s}


def synthesise(orders, amplitudes, phases, n) -> np.ndarray:
    """One period of ``n`` samples of the lines ``orders`` (their amplitudes and phases), in
    double precision."""
    spectrum = np.zeros(n // 2 + 1, dtype=complex)
    # a sin(w k + phi) = Re(a e^{j(w k + phi - pi/2)}); irfft of X/2 per line, scaled by n.
    spectrum[list(orders)] = np.asarray(amplitudes) * np.exp(1j * (np.asarray(phases) - np.pi / 2)) * n / 2
    return np.fft.irfft(spectrum, n)


def crest_factor(x) -> float:
    """Peak over RMS (a sine's is sqrt 2)."""
    x = np.asarray(x, dtype=float)
    return float(np.max(np.abs(x)) / math.sqrt(np.mean(x ** 2)))


def schroeder_phases(orders, amplitudes) -> np.ndarray:
    """Schroeder's low-crest-factor phases, for lines that need not be consecutive
    harmonics: ``phi_k = phi_{k-1} - 2 pi (h_k - h_{k-1}) sum_{i<k} p_i`` with the power
    fractions ``p_i``; for consecutive harmonics this is Schroeder's own formula."""
    p = np.asarray(amplitudes, dtype=float) ** 2
    p = p / p.sum()
    steps = np.diff(np.asarray(orders, dtype=float)) * np.cumsum(p)[:-1]
    return np.mod(np.concatenate([[0.0], -2 * np.pi * np.cumsum(steps)]), 2 * np.pi)


def low_crest_phases(orders, amplitudes, n: int, iterations: int = CLIP_ITERATIONS) -> np.ndarray:
    """Phases for a low crest factor: Schroeder's, improved by iterative clipping (clip the
    period at a level below its peak, take the clipped signal's phases at the lines, keep
    the best); deterministic."""
    orders = list(orders)
    phases = schroeder_phases(orders, amplitudes)
    best, best_crest = phases, crest_factor(synthesise(orders, amplitudes, phases, n))
    for _ in range(iterations):
        x = synthesise(orders, amplitudes, phases, n)
        crest = crest_factor(x)
        if crest < best_crest:
            best, best_crest = phases, crest
        level = max(0.9 * crest, math.sqrt(2)) * math.sqrt(np.mean(x ** 2))
        clipped = np.fft.rfft(np.clip(x, -level, level))[orders]
        phases = np.mod(np.angle(clipped) + np.pi / 2, 2 * np.pi)
    return best


def _grid(band_hz, fs_hz, lines, rig_time_s, min_periods, fade_cycles, base_period_s=None):
    """(period N, orders, whole periods) of the grid that fits the rig time with the most
    distinct lines, and of those the most periods (the coarsest grid that keeps them); with
    ``base_period_s``, the grid of that base period."""
    lo, hi = band_hz
    if base_period_s is not None and base_period_s * lo < 1.0 - 1e-9:
        raise InputError(f"a base period of {base_period_s:g} s puts the first harmonic above "
                         f"the band's lowest frequency, {lo:g} Hz: at least {1 / lo:.6g} s")
    sizes = ([int(round(fs_hz * base_period_s))] if base_period_s is not None else
             [int(round(fs_hz * lowest / lo)) for lowest in range(1, MAX_LOWEST_ORDER + 1)])
    best = None
    for n in sizes:
        base = fs_hz / n
        orders = sorted({max(1, int(round(f / base))) for f in
                         np.logspace(math.log10(lo), math.log10(hi), lines)})
        fade = fade_cycles * -(-n // orders[0])
        periods = int((rig_time_s * fs_hz - 2 * fade) // n)
        if periods >= min_periods and 4 * orders[-1] <= n and (
                best is None or (len(orders), periods) > (len(best[1]), best[2])):
            best = (n, orders, periods)
    if best is None:
        grid = ("a base frequency below its lowest line" if base_period_s is None else
                f"its base period of {base_period_s:g} s")
        raise InputError(f"a multisine over {lo:g}-{hi:g} Hz needs more than {rig_time_s:g} s: "
                         f"{min_periods} whole periods of {grid}, and the fades, do not fit "
                         "(a longer rig time, or a higher lowest frequency)")
    return best


def design(band_hz, peak: float, lines: int = LINES, rig_time_s: float = RIG_TIME_S,
           min_periods: int = MIN_PERIODS, fade_cycles: int = FADE_CYCLES,
           fs_hz: float | None = None, weights=None, like: Multisine | None = None,
           base_period_s: float | None = None) -> Multisine:
    """A multisine over ``band_hz`` (lo, hi) with declared peak ``peak`` (injection units)
    that fits ``rig_time_s``; ``weights`` (one per line after rounding, default equal) are
    the lines' relative amplitudes. ``like``: keep that multisine's period and lines, and
    fill ``rig_time_s`` with as many whole periods as fit (a longer or shorter record of the
    same points). ``base_period_s``: the base period (rounded to whole loop samples) instead
    of the one chosen for the rig time: the lines of a design made for another length."""
    fs_hz = float(fs_hz or firmware_facts.LOOP_RATE_HZ)
    if not 0 < band_hz[0] < band_hz[1] <= fs_hz / 4:
        raise InputError(f"band {band_hz[0]:g}-{band_hz[1]:g} Hz: the lowest must be above 0 "
                         f"and below the highest, at most {fs_hz / 4:g} Hz")
    if not 2 <= lines <= MAX_LINES:
        raise InputError(f"lines must be from 2 to {MAX_LINES}, got {lines}")
    if like is None:
        n, orders, periods = _grid(band_hz, fs_hz, lines, rig_time_s, min_periods, fade_cycles,
                                   base_period_s)
    else:
        n, orders = like.period_samples, list(like.orders)
        periods = int((rig_time_s * fs_hz - 2 * like.fade_samples) // n)
        if periods < min_periods:
            raise InputError(f"{rig_time_s:g} s holds fewer than {min_periods} periods of "
                             f"{n / fs_hz:g} s and the fades")
    w = np.ones(len(orders)) if weights is None else np.asarray(weights, dtype=float)
    if w.shape != (len(orders),) or not np.all(np.isfinite(w) & (w > 0)):
        raise InputError(f"weights: {len(orders)} positive numbers wanted")
    phases = low_crest_phases(orders, w, n)
    scale = peak / float(np.max(np.abs(synthesise(orders, w, phases, n))))
    return Multisine(fs_hz, n, tuple(orders), tuple(float(a) for a in w * scale),
                     tuple(float(p) for p in phases), float(peak), periods, fade_cycles)
