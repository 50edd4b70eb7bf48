"""The best linear approximation (BLA) from random-phase multisine realisations, with the
noise and the nonlinear distortion told apart per line (Pintelon and Schoukens, *System
Identification: A Frequency Domain Approach*, 2nd ed., 2012, sec. 3.5 and 4.3: the robust
method).

Each realisation ``m`` of ``M`` gives, per line, ``G_m`` with its noise variance
``sigma_m^2`` (from the scatter of its periods: the points' ``sigma``, with ``n_m`` periods).
Then, per line:

* the BLA, ``G = mean_m G_m``;
* its total variance ``var_total = sum_m |G_m - G|^2 / (M (M - 1))``: the noise and the
  stochastic nonlinear distortion together (the realisations differ by both);
* its noise variance ``var_noise = mean_m sigma_m^2 / M`` (the periods of one realisation
  differ by the noise only);
* the distortion's variance ``var_distortion = M max(var_total - var_noise, 0)``, as it
  affects one realisation.

For a linear system the ratio ``var_total / var_noise`` is F-distributed with ``2 (M - 1)``
and ``2 sum_m (n_m - 1)`` degrees of freedom (complex values: two real ones each). A line is
above the noise when its ratio passes the F quantile of :data:`LINE_ALPHA`; the level as a
whole when so many lines are that the binomial chance of it, were the system linear, is
below :data:`LEVEL_ALPHA` (about 1 false flag in 100 linear campaigns).
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np
from scipy import stats

from ...sim.base.errors import InputError

__all__ = ["LineBLA", "best_linear_approximation", "level_verdict", "LINE_ALPHA",
           "LEVEL_ALPHA"]

#: A line's false-alarm probability, were the system linear.
LINE_ALPHA = 0.05
#: A level's false-alarm probability (the binomial tail of its lines' flags).
LEVEL_ALPHA = 0.01


@dataclasses.dataclass(frozen=True)
class LineBLA:
    """One line's BLA and what scatters it."""
    order: int
    omega_rad_s: float
    gain: complex
    var_total: float            # the BLA's variance: noise and distortion
    var_noise: float            # the BLA's noise variance
    realisations: int
    noise_dof: int              # the noise variance's degrees of freedom (real)

    @property
    def dof(self) -> tuple:
        """The F test's degrees of freedom: the total's and the noise's."""
        return 2 * (self.realisations - 1), self.noise_dof

    @property
    def var_distortion(self) -> float:
        """The distortion's variance in one realisation (0 when below the noise's)."""
        return self.realisations * max(self.var_total - self.var_noise, 0.0)

    @property
    def var_noise_one(self) -> float:
        """The noise's variance in one realisation."""
        return self.realisations * self.var_noise

    @property
    def ratio(self) -> float:
        """Total over noise variance: about 1 for a linear system."""
        return self.var_total / self.var_noise if self.var_noise > 0 else math.inf

    @property
    def above_noise(self) -> bool:
        """The ratio passes the F quantile of :data:`LINE_ALPHA`."""
        return self.ratio > stats.f.ppf(1 - LINE_ALPHA, *self.dof)


def best_linear_approximation(realisations) -> list:
    """Per line (:class:`LineBLA`), from ``realisations``: a list (one per realisation) of
    that realisation's points (FrequencyPoint, ``order`` the line's harmonic, ``sigma`` its
    noise, ``n_periods`` the periods behind it). Lines missing from a realisation are left
    out; InputError with fewer than two realisations."""
    if len(realisations) < 2:
        raise InputError(f"{len(realisations)} realisation(s): the distortion needs two or more")
    by_line = {}
    for points in realisations:
        for p in points:
            by_line.setdefault(p.order, []).append(p)
    out = []
    for order, pts in sorted(by_line.items()):
        if len(pts) < len(realisations):
            continue
        m = len(pts)
        g = np.array([p.gain for p in pts])
        noise = np.array([p.sigma for p in pts], dtype=float) ** 2
        periods = np.array([max(int(p.n_periods), 2) for p in pts])
        bla = complex(np.mean(g))
        out.append(LineBLA(int(order), float(np.mean([p.omega_rad_s for p in pts])), bla,
                           float(np.sum(np.abs(g - bla) ** 2) / (m * (m - 1))),
                           float(np.mean(noise) / m), m, 2 * int(np.sum(periods - 1))))
    return out


def level_verdict(lines) -> dict:
    """One amplitude's verdict: its lines above the noise, how many would be by chance, and
    whether that many is improbable for a linear system (``flagged``); the distortion and
    the noise relative to the BLA's magnitude, RMS over the lines (dB)."""
    n = len(lines)
    above = sum(1 for line in lines if line.above_noise)
    chance = float(stats.binom.sf(above - 1, n, LINE_ALPHA)) if above else 1.0
    mag2 = np.array([abs(line.gain) ** 2 for line in lines])
    rel = lambda v: 10 * math.log10(max(float(np.mean(np.array(v) / mag2)), 1e-30))  # noqa: E731
    return {"count": n, "above_noise": above, "chance": chance,
            "flagged": chance < LEVEL_ALPHA,
            "distortion_db": rel([line.var_distortion for line in lines]),
            "noise_db": rel([line.var_noise_one for line in lines])}
