"""The linearity campaign (``heliquad sweep --signal multisine --linearity``): odd
multisines with random phases, several realisations at two amplitudes, from which identify
separates, per line, the noise from the nonlinear distortion (Pintelon and Schoukens,
*System Identification: A Frequency Domain Approach*, 2nd ed., 2012, ch. 3-4: the "robust"
method of the best linear approximation).

Design (:func:`linearity_plan`):

* **Lines.** Odd harmonics of one base period only (a symmetric nonlinearity, as a hinge's
  friction or a saturation, puts its distortion on odd lines: an odd design sees it on the
  excited lines, and the even harmonics stay free of it), log-spaced over the band: the
  base is the band's bottom over the largest odd order (1, 3 or 5) whose period is at most
  :data:`MAX_PERIOD_S`, each log-spaced frequency moved to the nearest odd harmonic. Equal
  amplitudes.
* **Realisations.** :data:`REALISATIONS` multisines of those lines, each with phases drawn
  uniformly at random (a generator seeded by the sweep's seed and the realisation's
  number: the same campaign again is the same signal). For a linear system every
  realisation measures the same response up to the noise; a nonlinear one answers each
  realisation differently (the "stochastic nonlinear distortion"), so the scatter across
  realisations beyond what the scatter across periods explains is the distortion.
* **Periods.** :data:`PERIODS` whole base periods at full amplitude each: the first
  settles (the FSF's filter fill), the others give each line's noise from their scatter.
* **Two amplitudes.** Each realisation is flown at the peak asked for and again at
  :data:`SMALL_SHARE` of it, interleaved (realisation 1 large, 1 small, 2 large, ...), so
  slow drifts do not pass for an amplitude dependence.
"""

from __future__ import annotations

import math

import numpy as np

from ...sim.base import firmware_facts
from ...sim.base.errors import InputError
from .multisine import MAX_LINES, Multisine, synthesise

__all__ = ["odd_lines", "realisation", "linearity_design", "REALISATIONS", "PERIODS",
           "SMALL_SHARE", "LINES"]

#: Random-phase realisations per amplitude.
REALISATIONS = 6
#: Whole base periods per realisation at full amplitude: one settles, the rest measure.
PERIODS = 3
#: The second amplitude, as a share of the first.
SMALL_SHARE = 0.25
#: Log-spaced lines asked for (fewer after rounding to distinct odd harmonics).
LINES = 10
#: The longest base period, s (the lowest line's order is chosen for it).
MAX_PERIOD_S = 10.0
#: Fade in and out over this many cycles of the lowest line.
FADE_CYCLES = 1


def odd_lines(band_hz, fs_hz: float, lines: int = LINES) -> tuple:
    """``(period N, orders)``: odd harmonics of a base period, log-spaced over ``band_hz``
    (module docstring)."""
    lo, hi = band_hz
    lowest = max(k for k in (1, 3, 5) if k == 1 or k / lo <= MAX_PERIOD_S)
    n = int(round(fs_hz * lowest / lo))
    base = fs_hz / n
    top = hi / base
    wanted = np.geomspace(lowest, max(top, lowest), lines)
    orders = sorted({int(2 * round((h - 1) / 2) + 1) for h in wanted})
    orders = [h for h in orders if lowest <= h and 4 * h <= n]
    if len(orders) < 3:
        raise InputError(f"an odd multisine over {lo:g}-{hi:g} Hz has {len(orders)} odd "
                         "lines: the band is too narrow (at least 3 are needed)")
    return n, orders[:MAX_LINES]


def realisation(n: int, orders, peak: float, fs_hz: float, seed: int, index: int,
                periods: int = PERIODS) -> Multisine:
    """Realisation ``index`` of the odd multisine on ``orders`` of period ``n``: equal
    amplitudes, phases uniform on [0, 2 pi) from the generator seeded by (``seed``,
    ``index``), scaled so that its period's peak is ``peak``."""
    rng = np.random.default_rng([int(seed), int(index)])
    phases = rng.uniform(0.0, 2 * math.pi, len(orders))
    unit = np.ones(len(orders))
    scale = peak / float(np.max(np.abs(synthesise(orders, unit, phases, n))))
    return Multisine(fs_hz, n, tuple(orders), tuple(float(a) for a in unit * scale),
                     tuple(float(p) for p in phases), float(peak), periods, FADE_CYCLES)


def linearity_design(band_hz, peak: float, seed: int, realisations: int = REALISATIONS,
                     lines: int = LINES, fs_hz: float | None = None) -> list:
    """The campaign's excitations in the order flown: ``(multisine, level, index)``, level 0
    the peak asked for and 1 its :data:`SMALL_SHARE`, interleaved by realisation."""
    if realisations < 2:
        raise InputError(f"--realisations {realisations}: at least 2 (the distortion is their "
                         "scatter)")
    fs_hz = float(fs_hz or firmware_facts.LOOP_RATE_HZ)
    n, orders = odd_lines(band_hz, fs_hz, lines)
    return [(realisation(n, orders, p, fs_hz, seed, i), level, i)
            for i in range(realisations) for level, p in enumerate((peak, SMALL_SHARE * peak))]
