"""The cascade's gains designed from identified models (``heliquad tune``; docs/tuning.md).

The design is for the loops as the firmware flies them (:mod:`.loops`: its discrete PID at
its loop rate, derivative on the measurement filtered with its fixed N, around each model's
own response with its delay exact), to a :class:`Spec`: every gain crossover of every loop
with its phase margin, and every phase crossover with its gain margin, at least the spec's
once the model's uncertainty there is taken off (:class:`Uncertainty`), on the recommended
model and on the second-best one; the rate loop's gain crossovers inside the identified
band; the gains inside the firmware's parameter ranges; the predicted step's peak axis
command within the spec's limit.

Method: a PID is a shape scaled to a crossover. For a target rate crossover ``wc``, each
shape ``(tau_I wc, tau_D wc)`` of a small fixed set gives the gains, Kc being the one that puts
``|L_r(wc)| = 1`` on the recommended model (the loop is linear in Kc); the best shape at
``wc`` is the one with the largest worst slack over all constraints. ``wc`` runs down a
log-spaced grid from the Nyquist frequency and the first that holds is refined by bisection
against the grid point above it: the highest rate crossover that keeps the spec. The
angle loop (roll, pitch) is then designed the same way below it, a PD shape
``tau_D wa`` scaled to its crossover ``wa``. Grids and shapes are fixed, so the design is
deterministic; the margins of the result are those of :func:`.loops.margins`.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from ..records.gains import AXIS_COMMAND_MAX, Gains, gains_params, param_range
from . import loops as L
from .closed_loop import STEP_ANGLE_RAD, STEP_RATE_RAD_S
from .tune_step import SEARCH_STEP_S, step_command_peak

__all__ = ["Spec", "Uncertainty", "Plant", "Design", "design_axis", "loop_slack",
           "RATE_SHAPES", "ANGLE_SHAPES"]

#: Rate PID shapes: (tau_I wc, tau_D wc). tau_I wc = 3..30 costs the integral 19..2 deg of
#: phase at the crossover; tau_D wc up to 0.6 adds the derivative's lead, and from 1 to 3
#: the derivative carries the crossover (the paper's own rate loops are such, tau_D wc near
#: 3): less proportional gain for the same crossover, so a smaller kick on a step.
RATE_SHAPES = tuple((ti, td) for ti in (3.0, 5.0, 10.0, 30.0)
                    for td in (0.0, 0.1, 0.2, 0.35, 0.6, 1.0, 2.0, 3.0))
#: Angle PD shapes: tau_D wa.
ANGLE_SHAPES = (0.0, 0.1, 0.25, 0.5)
#: Candidate crossovers per decade, and the search's lowest crossover below the band.
GRID_PER_DECADE = 24
GRID_BELOW_BAND = 30.0
#: Bisection steps refining the highest crossover between two grid points (0.05 %).
REFINE_STEPS = 8
#: The angle loop's crossover is at most this fraction of the rate loop's (a cascade's
#: inner loop several times faster than its outer one). Below it, the angle loop is as fast
#: as the spec and the step's command allow, down to the identified band's bottom: the rate
#: loop is not slowed to make room for a faster angle loop (its crossover is what rejects
#: disturbances; on the step, the command's peak is mostly the product of the two gains).
ANGLE_SEPARATION = 1 / 2.5
#: Points on which a candidate's loops are searched for crossovers (then interpolated).
SEARCH_POINTS = 3000


@dataclasses.dataclass(frozen=True)
class Spec:
    """What the design must keep: margins (deg, dB) at every crossover after the
    uncertainty, the coverage factor ``k`` on the points' sigma, the step (deg for roll and
    pitch, deg/s for yaw) whose peak axis command must stay within ``command_max``, and the
    lowest rate crossover asked for (rad/s). The step's sizes default to validate's, the
    command's limit to the firmware's clamp."""

    phase_margin_deg: float = 45.0
    gain_margin_db: float = 6.0
    coverage_k: float = 2.0
    step_angle_deg: float = round(math.degrees(STEP_ANGLE_RAD), 9)
    step_rate_deg_s: float = round(math.degrees(STEP_RATE_RAD_S), 9)
    command_max: float = AXIS_COMMAND_MAX
    min_crossover_rad_s: float = 0.0


@dataclasses.dataclass(frozen=True)
class Uncertainty:
    """The points' relative sigma (``sigma / |G|``) against frequency, and the coverage
    factor: at ``omega`` the model's response may be off by ``k r`` of itself, which moves a
    margin by :meth:`half_widths`. No points: no uncertainty (``omega`` empty)."""

    omega_rad_s: tuple = ()
    relative_sigma: tuple = ()
    k: float = 2.0

    def relative(self, omega) -> np.ndarray:
        """``k r`` at ``omega`` (rad/s), log-frequency interpolation, ends held."""
        omega = np.atleast_1d(np.asarray(omega, dtype=float))
        if not self.omega_rad_s:
            return np.zeros(omega.shape)
        return self.k * np.interp(np.log(omega), np.log(self.omega_rad_s), self.relative_sigma)

    def half_widths(self, omega, sensitivity=1.0):
        """``(phase deg, gain dB)`` a margin read at ``omega`` can move by: the loop off by
        ``e = k r |sensitivity|`` of itself turns its phase by up to ``asin(e)`` and its gain
        by up to ``-20 log10(1 - e)`` (infinite from e = 1: nothing is known there)."""
        e = self.relative(omega) * np.abs(sensitivity)
        with np.errstate(divide="ignore", invalid="ignore"):
            phase = np.where(e < 1, np.degrees(np.arcsin(np.minimum(e, 1))), 90.0)
            gain = np.where(e < 1, -20 * np.log10(np.maximum(1 - e, 1e-300)), np.inf)
        return phase, gain


@dataclasses.dataclass(frozen=True)
class Plant:
    """A model the design must hold on: its name (as said), its coefficients and delay, and
    the IMU path its sweep flew (how the logged angle follows the rate:
    :func:`heliquad.host.validate.loops.angle_over_rate`)."""

    name: str
    num: tuple
    den: tuple
    delay_s: float
    imu_path: str | None = None

    def responses(self):
        return L.model_responses(self.num, self.den, self.delay_s, self.imu_path)


@dataclasses.dataclass
class Design:
    """A design's outcome: ``gains`` (None when none holds), the rate crossover designed
    for, ``limit`` (what stopped a faster one), ``free_crossover_rad_s`` and ``free_gains``
    (the highest rate crossover the spec allows with the band ignored, and its rate gains;
    None when none)."""

    gains: Gains | None
    crossover_rad_s: float | None
    limit: str = ""
    free_crossover_rad_s: float | None = None
    free_gains: Gains | None = None


def _crossings(values):
    """Indices ``i`` where ``values`` changes sign between ``i`` and ``i + 1``, and the
    fraction of the way to ``i + 1`` where it is zero (linear)."""
    with np.errstate(invalid="ignore"):
        i = np.nonzero(np.sign(values[:-1]) * np.sign(values[1:]) < 0)[0]
    return i, values[i] / (values[i] - values[i + 1])


def loop_slack(values, grid, spec: Spec, unc: Uncertainty, sensitivity=None):
    """The worst slack of one loop's gain ``values`` on ``grid`` (rad/s): per gain crossover
    its phase margin less its uncertainty less the spec's (deg), per phase crossover its
    gain margin likewise (dB, scaled by 45/6 to weigh like degrees; where ``|L| > 1`` there,
    the margin is how far the gain may fall, ``20 log10 |L|``); ``(slack, what, gain
    crossovers)``. ``sensitivity``: the factor the model's relative error takes into this
    loop on ``grid`` (None: 1)."""
    logw = np.log(grid)
    worst, what = math.inf, ""
    i, f = _crossings(np.log(np.abs(values)))
    wcs = np.exp(logw[i] + f * (logw[i + 1] - logw[i]))
    s = 1.0 if sensitivity is None else np.abs(sensitivity[i])
    lc = values[i] + f * (values[i + 1] - values[i])
    pm = np.degrees(np.angle(-lc)) - unc.half_widths(wcs, s)[0] - spec.phase_margin_deg
    if pm.size and pm.min() < worst:
        worst, what = float(pm.min()), "phase margin"
    j, g = _crossings(values.imag)
    lp = values[j] + g * (values[j + 1] - values[j])
    neg = lp.real < 0
    if np.any(neg):
        wps = np.exp(logw[j] + g * (logw[j + 1] - logw[j]))[neg]
        sj = 1.0 if sensitivity is None else np.abs(sensitivity[j][neg])
        gm = np.abs(20 * np.log10(np.abs(lp[neg]))) - unc.half_widths(wps, sj)[1] \
            - spec.gain_margin_db
        scaled = gm * (45.0 / 6.0)
        if scaled.min() < worst:
            worst, what = float(scaled.min()), "gain margin"
    return worst, what, wcs


def _in_ranges(gains: Gains, axis: str) -> bool:
    """The gains are inside the firmware's parameter ranges (docs/parameters.md)."""
    for name, value in gains_params(axis, gains).items():
        lo, hi, floor = param_range(name)
        if not lo <= value <= hi or (0 < value < floor):
            return False
    return True


class _Problem:
    """One axis's design problem: its plants, band, spec, uncertainty and search grid."""

    def __init__(self, plants, band, spec, unc, axis):
        self.plants, self.band, self.spec, self.unc, self.axis = plants, band, spec, unc, axis
        self.grid = np.geomspace(band[0] / GRID_BELOW_BAND, math.pi / L.LOOP_DT_S * 0.999,
                                 SEARCH_POINTS)
        self.h = [p.responses() for p in plants]
        self.hg = [(h(self.grid), ha(self.grid)) for h, ha in self.h]

    def rate_gains(self, wc, shape):
        ti, td = shape
        unit = Gains((1.0, ti / wc, td / wc), None)
        h, _ = self.h[0]
        kc = 1.0 / abs(complex(L.loop_functions(h, None, unit)["rate"](np.array([wc]))[0]))
        return Gains((kc, ti / wc, td / wc), None)

    def rate_slack(self, gains, in_band: bool):
        """The rate loop's worst slack over the plants, what it is, and whether its gain
        crossovers (on the recommended model) lie inside the band."""
        worst, what, inside = math.inf, "", True
        for n, ((h, _), (hg, _)) in enumerate(zip(self.h, self.hg)):
            # the model's response precomputed on the grid, where alone the loop is evaluated
            values = L.loop_functions(lambda w, hg=hg: hg, None, gains)["rate"](self.grid)
            s, w, wcs = loop_slack(values, self.grid, self.spec, self.unc)
            if s < worst:
                worst, what = s, w
            if n == 0:
                inside = bool(wcs.size) and bool(np.all((wcs >= self.band[0] * (1 - L.BAND_SLACK))
                                                        & (wcs <= self.band[1] * (1 + L.BAND_SLACK))))
        if in_band and not inside:
            return -math.inf, "the identified band", inside
        return worst, what, inside

    def best_rate(self, wc, in_band: bool):
        """The best rate shape at ``wc``: ``(slack, what, gains)``."""
        best = (-math.inf, "the parameters' ranges", None)
        for shape in RATE_SHAPES:
            gains = self.rate_gains(wc, shape)
            if not _in_ranges(gains, self.axis):
                continue
            s, what, _ = self.rate_slack(gains, in_band)
            if best[2] is None or s > best[0]:
                best = (s, what, gains)
        return best

    def angle_slack(self, gains):
        worst, what = math.inf, ""
        for hg, ha in self.hg:              # as rate_slack: the responses on the grid
            loops = L.loop_functions(lambda w, hg=hg: hg, lambda w, ha=ha: ha, gains)
            rate = loops["rate"](self.grid)
            sens = 1.0 / (1.0 + rate)
            for name, sensitivity in (("angle", sens), ("input", None)):
                s, w, _ = loop_slack(loops[name](self.grid), self.grid, self.spec, self.unc,
                                     sensitivity)
                if s < worst:
                    worst, what = s, f"{w} of the {name} loop"
        return worst, what

    def command_ok(self, gains) -> bool:
        p = self.plants[0]
        return step_command_peak(p.num, p.den, p.delay_s, gains, self.axis, self._step_size(),
                                 SEARCH_STEP_S, p.imu_path) <= self.spec.command_max

    def _step_size(self):
        return math.radians(self.spec.step_rate_deg_s if self.axis == "yaw"
                            else self.spec.step_angle_deg)


def _candidates(problem, lo):
    """The rate crossovers tried, highest first, down to ``lo``."""
    hi = problem.grid[-1] / 2
    n = max(2, int(math.ceil(math.log10(hi / lo) * GRID_PER_DECADE)) + 1)
    return np.geomspace(hi, lo, n)


def _highest_rate(problem, in_band):
    """The highest rate crossover that holds: ``(wc, gains, what limited it)`` or
    ``(None, None, what failed)``; bisected between the first grid crossover that holds
    and the one above it."""
    lo = max(problem.band[0] / GRID_BELOW_BAND, problem.spec.min_crossover_rad_s or 0.0)
    above, what_above = None, "the Nyquist frequency"
    if lo >= problem.grid[-1] / 2:
        return None, None, f"no crossover from {lo:.3g} rad/s is below half the Nyquist frequency"
    for wc in _candidates(problem, lo):
        s, what, gains = problem.best_rate(wc, in_band)
        if s >= 0:
            break
        above, what_above = wc, what
    else:
        return None, None, what_above
    if above is not None:
        low, high = wc, above
        for _ in range(REFINE_STEPS):
            mid = math.sqrt(low * high)
            s, what, g = problem.best_rate(mid, in_band)
            if s >= 0:
                low, gains = mid, g
            else:
                high, what_above = mid, what
        wc = low
    return wc, gains, what_above


def _best_angle(problem, rate: Gains, wa):
    """The best angle PD shape at the angle crossover ``wa`` around the rate loop ``rate``:
    ``(slack, what, gains)``."""
    h, h_a = problem.h[0]
    best = (-math.inf, "the parameters' ranges", None)
    for shape in ANGLE_SHAPES:
        unit = Gains(rate.rate, (1.0, shape / wa))
        la = abs(complex(L.loop_functions(h, h_a, unit)["angle"](np.array([wa]))[0]))
        gains = Gains(rate.rate, (1.0 / la, shape / wa))
        if not _in_ranges(gains, problem.axis):
            continue
        s, what = problem.angle_slack(gains)
        if best[2] is None or s > best[0]:
            best = (s, what, gains)
    return best


def _angle_loop(problem, rate: Gains, wc):
    """The highest angle crossover below ``wc`` that keeps the spec on the angle and input
    loops and the step's command within its limit: ``(gains, what limited it)``, gains None
    when none does."""
    # its phase margin read where the model was measured: the crossover inside the band
    hi, lo = wc * ANGLE_SEPARATION, problem.band[0]
    limit = f"the separation from the rate loop (at most {ANGLE_SEPARATION:.2g} of its crossover)"
    if hi < lo:
        return None, "its crossover held inside the identified band"
    n = int(math.ceil(math.log10(hi / lo) * GRID_PER_DECADE)) + 1
    for wa in np.geomspace(hi, lo, n):
        s, what, gains = _best_angle(problem, rate, wa)
        if s < 0:
            limit = what
            continue
        if problem.command_ok(gains):
            return gains, limit
        limit = "the step's peak command"
    return None, limit


def _rate_command(problem, wc, gains, limit):
    """Yaw's step is a rate step: the rate crossover walks down the grid from ``wc`` until
    its peak command is within the limit; ``(wc, gains, limit)``, gains None when none is."""
    if problem.command_ok(gains):
        return wc, gains, limit
    for w in _candidates(problem, max(problem.band[0], problem.spec.min_crossover_rad_s)):
        if w >= wc:
            continue
        s, _, g = problem.best_rate(w, True)
        if s >= 0 and problem.command_ok(g):
            return w, g, "the step's peak command"
    return None, None, "the step's peak command"


def design_axis(axis, plants, band, spec: Spec, unc: Uncertainty) -> Design:
    """The highest-bandwidth gains for ``axis`` that keep ``spec`` on every plant of
    ``plants`` (the recommended model first): the rate PID, then for roll and pitch the
    angle PD below it (module docstring). The :class:`Design` says what limited it; its
    gains are None when the band forbids every design the spec allows (``free_*`` then
    holds the fastest the spec allows with the band ignored) or the spec allows none."""
    problem = _Problem(plants, band, spec, unc, axis)
    free_wc, free_gains, why = _highest_rate(problem, in_band=False)
    if free_wc is None:
        return Design(None, None, limit=why)
    wc, gains, limit = _highest_rate(problem, in_band=True)
    if wc is None:
        return Design(None, None, limit="the identified band", free_crossover_rad_s=free_wc,
                      free_gains=free_gains)
    design = Design(None, wc, limit, free_wc, free_gains)
    if axis == "yaw":
        design.crossover_rad_s, design.gains, design.limit = _rate_command(problem, wc, gains,
                                                                           limit)
        return design
    for w in [wc] + [w for w in _candidates(problem, band[0]) if w < wc]:
        if w != wc:
            s, _, gains = problem.best_rate(w, True)
            if s < 0:
                continue
        angle, why = _angle_loop(problem, gains, w)
        if angle is not None:
            design.gains, design.crossover_rad_s = angle, w
            if w != wc:
                design.limit = f"the angle loop ({why})"
            return design
    design.limit = f"the angle loop ({why})"
    return design
