"""Each rotor's control effectiveness from per-rotor injections on the one-axis rigs.

docs/effectiveness.md derives the method. On the rig about axis ``k`` the cascade flies and
rotor ``i``'s injection ``u_i`` is added to its thrust command after the allocation. Two
responses are measured against ``u_i`` on each of its lines: the rate, ``T_p = p / u_i``,
and the axis's torque command, ``T_c = c_k / u_i`` (:func:`rig_points`). With every
rotor's path to the rate

    P_j(s) = (E_kj + s M_kj) exp(-s tau_j) / (T_j s + 1) R_k(s),

(``E`` the effectiveness, rad/s^2 per unit of thrust command; ``M`` the rotor's spin-up
reaction; ``R_k`` the rig's rate per angular acceleration) and the torque command's path
``P_c = sum_j a_kj P_j`` (``a_kj``: rotor ``j``'s command per unit of the axis's torque
command, the allocation's column), on rotor ``i``'s lines

    T_p = P_c T_c + P_i,

whatever the controller is (its answer to the injection is measured in ``T_c``).
:func:`estimate_effectiveness` fits ``E``, ``M``, ``T`` and ``tau`` (``T`` and ``tau``
shared by the rigs) to every rotor's points at once by weighted least squares, each line's
residual ``T_p - P_c T_c - P_i`` weighted by its sigma (the two points' errors are
correlated: the command answers the rate's noise), and gives the parameters' standard
deviations from the fit's covariance; asked (``fit_hinges``), it fits each rig's hinge
damping too. :func:`rotor_paths` gives the fitted paths, and the axis's ``P_c`` to compare
with the axis sweep's model.

No I/O: a command feeds it from run folders (each rotor's excitation, the rate and the
torque command logged per sample, the multisine's period and lines from the manifest, the
allocation from the flown parameters).
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import scipy.optimize

from ...sim.base.dialect import AXES
from ...sim.base.errors import InputError
from .fsf import (complete_excitation, estimate_multisine_against_excitation, fill_lost,
                  period_dfts, period_segments)
from .held_paths import held_paths

__all__ = ["RotorPoints", "Rig", "EffectivenessEstimate", "rig_points",
           "estimate_effectiveness", "rig_from_poles", "rotor_paths", "held_paths"]

#: A rotor's time constant and delay are reported only when one of its rows' effectiveness
#: is this many sigmas from zero (else no rig moved it enough to see its lag).
IDENTIFIED_SIGMAS = 3.0
#: The fit's starting point: a small rotor's time constant and the sample-and-hold's
#: delay, s (the fit moves them; they only need to be of the right order).
START_TIME_CONSTANT_S = 0.05
START_DELAY_S = 0.005
#: The lags' fit runs from this many of the common starting lags (a grid of time constants
#: and delays about the above), the best by their linear fit first; the best end is kept (a
#: delay far from its start can end in a local minimum).
FIT_STARTS = 3
#: Bounds of the fit: time constant (s) and delay (s), beyond any rotor and loop.
TIME_CONSTANT_BOUNDS_S = (1e-3, 5.0)
DELAY_BOUNDS_S = (-0.05, 0.2)
#: With ``fit_hinges``: a hinge's damping over its inertia is fitted from 0 to this (1/s,
#: far above any rig's: the simulated rigs' are 0.09 to 0.17) on this scale.
HINGE_BOUND_RAD_S, HINGE_SCALE_RAD_S = 10.0, 0.1
#: A line's residual variance is floored at this fraction of its rate point's own (a
#: correlation of the two points' errors near 1 can make the difference vanish by round-off).
VARIANCE_FLOOR = 1e-6
#: The lags' central-difference step for the covariance, relative (log T) and in s (tau):
#: a millionth, far above round-off and far below the sigmas.
JACOBIAN_STEP = 1e-6
#: The lags' fit stops when a step or the cost changes by less than this, relative: well below
#: any sigma, so exact points give exact rotors.
LAG_TOLERANCE = 1e-12


@dataclasses.dataclass(frozen=True)
class RotorPoints:
    """What one rig measured of one rotor: on each line of the rotor's excitation, the rate
    (``rate``) and the axis's torque command (``command``) against the injection, as
    :class:`~heliquad.host.records.points.FrequencyPoint` lists of the same lines, and the
    correlation of their errors ``E[dT_p conj(dT_c)] / (sigma_p sigma_c)``."""

    axis: str
    rotor: int                # 0-based, the firmware's motor order
    rate: tuple
    command: tuple
    correlation: tuple        # per line, of the two points' errors (complex, |.| <= 1)


@dataclasses.dataclass(frozen=True)
class Rig:
    """One rig: its axis, the allocation's column for that axis (each rotor's thrust command
    per unit of the axis's torque command, at the trim flown) and the rig's rate per angular
    acceleration ``R(s) = s / (s^2 + damping s + stiffness)`` (rad/s, rad/s^2: its hinge's
    damping and stiffness over its inertia)."""

    axis: str
    allocation: tuple
    damping_rad_s: float = 0.0
    stiffness_rad2_s2: float = 0.0

    def response(self, omega_rad_s) -> np.ndarray:
        """``R(j omega)``, rad/s per rad/s^2."""
        s = 1j * np.asarray(omega_rad_s, dtype=float)
        return s / (s * s + self.damping_rad_s * s + self.stiffness_rad2_s2)


@dataclasses.dataclass(frozen=True)
class EffectivenessEstimate:
    """The fit. Rows roll, pitch, yaw (NaN for an axis no rig measured), columns the rotors.

    ``effectiveness_rad_s2``: angular acceleration per unit of thrust command at steady state;
    ``spin_up_rad_s``: the spin-up reaction's part, rad/s per unit of command (the
    acceleration's term in ``s``); ``time_constant_s`` and ``delay_s`` per rotor (NaN when no
    rig moved the rotor's row, ``IDENTIFIED_SIGMAS``); each with its sigma.
    ``effectiveness_covariance``: the entries' covariance, ``3 rotors`` square in the order of
    ``effectiveness_rad_s2.ravel()`` (NaN for rows not measured): the entries share ``P_c``
    and the lags, so their errors are correlated. ``chi2_dof``: the weighted residuals' sum of
    squares over the degrees of freedom (about 1 when the model and the points' sigmas
    hold). ``hinge_damping_rad_s``: with ``fit_hinges``, each rig's hinge damping as fitted
    (None: the rigs' as given)."""

    effectiveness_rad_s2: np.ndarray
    effectiveness_sigma_rad_s2: np.ndarray
    spin_up_rad_s: np.ndarray
    time_constant_s: np.ndarray
    time_constant_sigma_s: np.ndarray
    delay_s: np.ndarray
    delay_sigma_s: np.ndarray
    effectiveness_covariance: np.ndarray
    chi2_dof: float
    hinge_damping_rad_s: dict | None = None    # axis -> the damping fitted (fit_hinges)


def rig_points(excitation, rate, command, fs_hz: float, period: int, orders, axis: str,
               present=None) -> list:
    """One rig's record as :class:`RotorPoints`, one per rotor excited: the rate and the
    torque command each against the injections, on every rotor's lines (``orders[i]``:
    rotor ``i``'s harmonics of the multisine's base period of ``period`` samples, none for a
    rotor not excited; ``excitation``: the injections' sum per sample, or samples x rotors,
    each rotor's own).

    Every line of every rotor is fitted at once against the sum of the injections (on a
    rotor's line the others' are zero), so the other rotors' responses are modelled, not
    left in the residual: that matters when samples were lost (``present``, as for
    :func:`~heliquad.host.estimate.fsf.estimate_multisine_against_excitation`), where the
    periods are no longer orthogonal. A point is ``Y / R`` with the sigma of its per-period
    scatter; the correlation of the two points' errors per line comes with them (the command
    answers the rate's noise)."""
    x = np.asarray(excitation, dtype=float)
    owner = {int(l): i for i, lines in enumerate(orders) for l in lines}
    if (x.ndim == 2 and x.shape[1] != len(orders)) or x.ndim not in (1, 2) or \
            len(owner) != sum(map(len, orders)):
        raise InputError("the injections (their sum, or one column per rotor) and one set of "
                         "lines per rotor, no line shared by two rotors")
    r = x.sum(axis=1) if x.ndim == 2 else x
    args = (fs_hz, period, sorted(owner))
    to_rate = estimate_multisine_against_excitation(r, r, rate, *args, present=present)
    to_command = estimate_multisine_against_excitation(r, r, command, *args, present=present)
    if [p.order for p in to_rate] != [p.order for p in to_command]:
        raise InputError("the rate and the torque command follow the excitation on different "
                         "lines")
    rate, command = (np.asarray(v, dtype=float) for v in (rate, command))
    if present is not None and not np.all(present):     # the holes filled by the fits
        present = np.asarray(present, dtype=bool)
        r = complete_excitation(r, present, period)
        rate, command = (fill_lost(np.where(present, v, 0.0), present, r, period,
                                   {p.order: p.gain for p in pts}, pts[0].offset if pts else 0.0)
                         for v, pts in ((rate, to_rate), (command, to_command)))
    correlation = _correlations(r, rate, command, period, [p.order for p in to_rate])
    return [RotorPoints(axis, i, *(tuple(p for p in pts if owner[p.order] == i)
                                   for pts in (to_rate, to_command)),
                        tuple(c for p, c in zip(to_rate, correlation) if owner[p.order] == i))
            for i in sorted(set(owner.values()))]


def _correlations(r, rate, command, period: int, orders) -> list:
    """Per line ``orders``, the correlation of the per-period estimates of the rate and of
    the command against ``r`` (whole periods after the first)."""
    starts, length = period_segments(r.size, period, 1)
    out = []
    for order in orders:
        w = 2 * np.pi * order / period
        ref = period_dfts(r, w, starts, length)
        a, b = (period_dfts(v, w, starts, length) / ref for v in (rate, command))
        a, b = a - a.mean(), b - b.mean()
        norm = math.sqrt(float(np.sum(np.abs(a) ** 2) * np.sum(np.abs(b) ** 2)))
        out.append(complex(np.sum(a * np.conj(b)) / norm) if norm > 0 else 0j)
    return out


def rig_from_poles(axis: str, allocation, poles) -> Rig:
    """The :class:`Rig` whose rate per angular acceleration has these poles: the axis
    model's slowest one (damping only) or two (damping and stiffness), which are the hinge's
    (docs/effectiveness.md)."""
    poles = np.atleast_1d(np.asarray(poles, dtype=complex))
    if poles.size not in (1, 2) or np.any(poles.real > 0):
        raise InputError("a rig has one or two stable poles: its hinge's damping and stiffness")
    den = np.real(np.poly(poles)) if poles.size == 2 else np.array([1.0, -poles[0].real, 0.0])
    return Rig(axis, tuple(allocation), float(den[1]), float(den[2]))


class _Problem:
    """Every record's lines stacked, and the model of what they measured: per line, the
    residual ``T_p - P_c T_c - P_i`` is linear in ``E`` and ``M`` once the lags are held."""

    def __init__(self, records, rigs: dict, rotors: int, hold_s: float | None):
        self.rotors, self.axes = rotors, sorted({r.axis for r in records}, key=AXES.get)
        self.hold_s = hold_s
        lines = []
        for rec in records:
            if rec.axis not in rigs:
                raise InputError(f"no rig given for the {rec.axis} records")
            if not 0 <= rec.rotor < rotors:
                raise InputError(f"rotor {rec.rotor + 1} is not one of the {rotors}")
            if not len(rec.rate) == len(rec.command) == len(rec.correlation):
                raise InputError(f"rotor {rec.rotor + 1} on {rec.axis}: its rate and command "
                                 f"points and their correlations are not of the same lines")
            for p, c, rho in zip(rec.rate, rec.command, rec.correlation):
                if not (p.sigma > 0 and c.sigma >= 0):
                    raise InputError(f"rotor {rec.rotor + 1} on {rec.axis}: a point without "
                                     f"a positive sigma at {p.omega_rad_s:.4g} rad/s")
                rig = rigs[rec.axis]
                lines.append((self.axes.index(rec.axis), rec.rotor, p.omega_rad_s, p.gain,
                              c.gain, p.sigma, c.sigma, rho * p.sigma * c.sigma,
                              rig.response(p.omega_rad_s), rig.damping_rad_s,
                              rig.stiffness_rad2_s2))
        cols = list(zip(*lines))
        self.row, self.rotor = (np.array(c, dtype=int) for c in cols[:2])
        (self.omega, self.t_p, self.t_c, self.sigma_p, self.sigma_c, self.cov_pc,
         self.rig_response, self.damping, self.stiffness) = (np.array(c) for c in cols[2:])
        self.alloc = np.array([rigs[a].allocation for a in self.axes], dtype=float)
        if self.alloc.shape[1] != rotors:
            raise InputError(f"an allocation column needs one entry per rotor ({rotors})")
        self.weight = 1.0 / self.sigma_p
        self.fit_hinges = False

    def hinges(self) -> np.ndarray:
        """Each rig's hinge damping (in ``axes`` order), rad/s."""
        return np.array([self.damping[self.row == r][0] for r in range(len(self.axes))])

    def set_hinges(self, damping) -> None:
        """Fly every line's rig with these hinge dampings (in ``axes`` order), rad/s."""
        self.damping = np.asarray(damping, dtype=float)[self.row]
        s = 1j * self.omega
        self.rig_response = s / (s * s + self.damping * s + self.stiffness)

    @property
    def linear(self) -> int:
        """How many of the parameters are linear: ``E`` and ``M`` of every row and rotor."""
        return 2 * len(self.axes) * self.rotors

    def lags(self, x) -> tuple:
        """``(T, tau)`` of the full parameter vector ``x`` (``E``, ``M``, log ``T``, ``tau``)."""
        n, k = self.rotors, self.linear
        return np.exp(x[k:k + n]), x[k + n:]

    def paths(self, t, tau) -> tuple:
        """Per line and rotor, its path per unit of its ``E`` and per unit of its ``M``:
        ``exp(-s tau) / (T s + 1) R(s)`` and ``s`` times it, or their hold's equivalents
        (:func:`held_paths`) when the points were sampled with a hold."""
        if self.hold_s is not None:
            return held_paths(self.omega[:, None], self.hold_s, t, tau,
                              self.damping[:, None], self.stiffness[:, None])
        s = 1j * self.omega[:, None]
        per_e = np.exp(-s * tau) / (t * s + 1) * self.rig_response[:, None]
        return per_e, s * per_e

    def design(self, t, tau) -> np.ndarray:
        """Per line, the complex coefficient of each ``E`` (then each ``M``) in
        ``P_i + P_c T_c``, the lags held at ``t`` and ``tau``."""
        m, n = len(self.axes), self.rotors
        own = np.zeros((self.omega.size, n))
        own[np.arange(self.omega.size), self.rotor] = 1.0
        gain = own + self.t_c[:, None] * self.alloc[self.row]
        per_e, per_m = self.paths(t, tau)
        design = np.zeros((self.omega.size, 2 * m * n), dtype=complex)
        for r in range(m):
            on = self.row == r
            design[on, r * n:(r + 1) * n] = (gain * per_e)[on]
            design[on, (m + r) * n:(m + r + 1) * n] = (gain * per_m)[on]
        return design

    def reweigh(self, x) -> None:
        """Each line's weight, ``1 / sigma`` of ``T_p - P_c T_c`` at the parameters ``x``."""
        n, half = self.rotors, self.linear // 2
        e, spin = x[:half].reshape(-1, n), x[half:self.linear].reshape(-1, n)
        per_e, per_m = self.paths(*self.lags(x))
        p_c = np.sum(self.alloc[self.row] * (e[self.row] * per_e + spin[self.row] * per_m),
                     axis=1)
        var = (self.sigma_p ** 2 + np.abs(p_c) ** 2 * self.sigma_c ** 2
               - 2 * np.real(np.conj(p_c) * self.cov_pc))
        self.weight = 1.0 / np.sqrt(np.maximum(var, VARIANCE_FLOOR * self.sigma_p ** 2))

    def stacked(self, z) -> np.ndarray:
        """Complex per-line values (or rows of them) weighted, as real then imaginary parts:
        the weighted residuals' space."""
        z = z * (math.sqrt(2.0) * self.weight.reshape((-1,) + (1,) * (z.ndim - 1)))
        return np.concatenate([z.real, z.imag])

    def solve_linear(self, t, tau):
        """The best ``E`` and ``M`` for these lags and the weighted residuals."""
        a, b = self.stacked(self.design(t, tau)), self.stacked(self.t_p)
        coef, *_ = np.linalg.lstsq(a, b, rcond=None)
        return coef, b - a @ coef

    def residuals(self, x) -> np.ndarray:
        """The weighted residuals at the full parameter vector ``x`` (``E``, ``M``, log ``T``,
        ``tau``)."""
        return self.stacked(self.t_p) - self.stacked(self.design(*self.lags(x))) @ x[:self.linear]


def _fit_lags(problem: _Problem, t0, tau0, free) -> np.ndarray:
    """The full parameter vector that fits best with the lags of the rotors ``free`` (a
    mask) free and the others held at ``t0``, ``tau0``: the lags (and with ``fit_hinges``
    the rigs' hinge dampings, from the problem's, left in it as fitted) by nonlinear least
    squares, ``E`` and ``M`` solved for at each step (variable projection)."""
    count = int(np.count_nonzero(free))
    hinges = len(problem.axes) if problem.fit_hinges else 0
    start = problem.hinges()

    def lags(phi):
        t, tau = t0.copy(), tau0.copy()
        t[free], tau[free] = np.exp(phi[:count]), phi[count:2 * count]
        if hinges:
            problem.set_hinges(phi[2 * count:])
        return t, tau

    if count or hinges:
        phi0 = np.concatenate([np.log(t0[free]), tau0[free], start[:hinges]])
        lower = np.concatenate([np.full(count, math.log(TIME_CONSTANT_BOUNDS_S[0])),
                                np.full(count, DELAY_BOUNDS_S[0]), np.zeros(hinges)])
        upper = np.concatenate([np.full(count, math.log(TIME_CONSTANT_BOUNDS_S[1])),
                                np.full(count, DELAY_BOUNDS_S[1]),
                                np.full(hinges, HINGE_BOUND_RAD_S)])
        sol = scipy.optimize.least_squares(
            lambda phi: problem.solve_linear(*lags(phi))[1], np.clip(phi0, lower, upper),
            bounds=(lower, upper), x_scale=np.concatenate([np.ones(count), np.full(count, 0.01),
                                                           np.full(hinges, HINGE_SCALE_RAD_S)]),
            xtol=LAG_TOLERANCE, ftol=LAG_TOLERANCE, gtol=LAG_TOLERANCE)
        t, tau = lags(sol.x)
    else:
        t, tau = t0, tau0
    return np.concatenate([problem.solve_linear(t, tau)[0], np.log(t), tau])


def _jacobian(problem: _Problem, x) -> np.ndarray:
    """d(weighted residuals)/dx: the linear parameters' columns exactly, the lags' by
    central differences."""
    k = problem.linear
    jac = np.zeros((2 * problem.omega.size, x.size))
    jac[:, :k] = -problem.stacked(problem.design(*problem.lags(x)))
    for j in range(k, x.size):
        step = JACOBIAN_STEP * max(1.0, abs(x[j]))
        hi, lo = x.copy(), x.copy()
        hi[j] += step
        lo[j] -= step
        jac[:, j] = (problem.residuals(hi) - problem.residuals(lo)) / (2 * step)
    return jac


def _covariance(jac, keep) -> np.ndarray:
    """The parameters' covariance from the weighted residuals' Jacobian, over the columns
    ``keep`` (the others: NaN)."""
    cov = np.full((jac.shape[1],) * 2, np.nan)
    sub = jac[:, keep]
    cov[np.ix_(keep, keep)] = np.linalg.pinv(sub.T @ sub)
    return cov


def _sigmas(cov) -> np.ndarray:
    """Standard deviations from a covariance's diagonal (a variance that round-off took
    below zero, for a parameter fitted exactly, as 0; NaN kept)."""
    return np.sqrt(np.clip(np.diag(cov), 0.0, None))


def _seen(problem: _Problem, t, tau) -> np.ndarray:
    """Which rotors moved some rig enough to show their lag (``IDENTIFIED_SIGMAS``), judged
    with every lag held at ``t``, ``tau`` (a free lag would fit the noise of a rotor that
    moves nothing)."""
    n, half = problem.rotors, problem.linear // 2
    x = np.concatenate([problem.solve_linear(t, tau)[0], np.log(t), tau])
    problem.reweigh(x)
    x[:problem.linear] = problem.solve_linear(t, tau)[0]
    design = problem.stacked(problem.design(t, tau))
    sd = _sigmas(_covariance(design, np.ones(problem.linear, dtype=bool)))
    e = np.abs(x[:half].reshape(-1, n)) / sd[:half].reshape(-1, n)
    return np.any(e > IDENTIFIED_SIGMAS, axis=0)


def estimate_effectiveness(records, rigs: dict, rotors: int, hold_s: float | None = None,
                           fit_hinges: bool = False) -> EffectivenessEstimate:
    """Fit every rotor's effectiveness, spin-up reaction, time constant and delay to the
    records (:class:`RotorPoints`) of the rigs (``axis -> Rig``), ``rotors`` rotors in all
    (module docstring, docs/effectiveness.md). ``hold_s``: the loop period, when the logged
    commands were held for it (the firmware's): the paths are then the hold's exact
    equivalents and ``tau`` leaves the hold out; None: continuous paths, ``tau`` with the
    hold's half period in it. ``fit_hinges``: fit each rig's hinge damping too, from the
    rig's as given (its stiffness held); the sigmas are then those with the hinges held at
    the fitted ones."""
    records = [r for r in records if r.rate]
    if not records:
        raise InputError("no rotor's points to fit")
    problem = _Problem(records, rigs, rotors, hold_s)
    n, k = rotors, problem.linear
    if 2 * problem.omega.size <= k + 2 * n:
        raise InputError(f"{problem.omega.size} lines cannot fit the {k + 2 * n} parameters "
                         f"of {len(problem.axes)} rigs and {n} rotors")
    starts = sorted(((np.full(n, f * START_TIME_CONSTANT_S), np.full(n, g * START_DELAY_S))
                     for f in (0.5, 1.0, 4.0) for g in (1.0, 2.0, 4.0)),
                    key=lambda lags: float(np.sum(problem.solve_linear(*lags)[1] ** 2)))
    seen = _seen(problem, *starts[0])
    given, fits = problem.hinges(), []
    problem.fit_hinges = fit_hinges
    for t0, tau0 in starts[:FIT_STARTS]:
        if fit_hinges:                   # each start from the rigs' hinges as given
            problem.set_hinges(given)
        x = _fit_lags(problem, t0, tau0, seen)
        fits.append((float(np.sum(problem.residuals(x) ** 2)), len(fits), x, problem.hinges()))
    _, _, x, hinges = min(fits)
    if fit_hinges:
        problem.set_hinges(hinges)
    problem.reweigh(x)
    x = _fit_lags(problem, np.exp(x[k:k + n]), x[k + n:], seen)
    keep = np.concatenate([np.ones(k, dtype=bool), seen, seen])
    jac = _jacobian(problem, x)
    est = _estimate(problem, x, _covariance(jac, keep), seen,
                    float(np.sum(problem.residuals(x) ** 2))
                    / max(jac.shape[0] - int(np.count_nonzero(keep)), 1))
    return dataclasses.replace(est, hinge_damping_rad_s=dict(zip(
        problem.axes, problem.hinges().tolist()))) if fit_hinges else est


def _estimate(problem: _Problem, x, cov, seen, chi2_dof: float) -> EffectivenessEstimate:
    """The fitted vector ``x`` and its covariance ``cov`` as the estimate, rows in roll,
    pitch, yaw order (NaN for a rig not flown)."""
    n, k, half = problem.rotors, problem.linear, problem.linear // 2
    rows = [AXES[a] for a in problem.axes]
    sd = _sigmas(cov)
    entries = (np.array(rows)[:, None] * n + np.arange(n)).ravel()
    e_cov = np.full((len(AXES) * n,) * 2, np.nan)
    e_cov[np.ix_(entries, entries)] = cov[:half, :half]

    def full(values):
        out = np.full((len(AXES), n), np.nan)
        out[rows] = np.reshape(values, (-1, n))
        return out

    t = np.exp(x[k:k + n])
    return EffectivenessEstimate(
        effectiveness_rad_s2=full(x[:half]), effectiveness_sigma_rad_s2=full(sd[:half]),
        spin_up_rad_s=full(x[half:k]),
        time_constant_s=np.where(seen, t, np.nan),
        time_constant_sigma_s=np.where(seen, t * sd[k:k + n], np.nan),
        delay_s=np.where(seen, x[k + n:], np.nan),
        delay_sigma_s=np.where(seen, sd[k + n:], np.nan), effectiveness_covariance=e_cov,
        chi2_dof=chi2_dof)


def rotor_paths(est: EffectivenessEstimate, rig: Rig, omega_rad_s,
                hold_s: float | None = None) -> tuple:
    """The fitted paths on ``rig``'s axis at ``omega_rad_s``: ``(P_j per rotor (rotors x
    frequencies), P_c = sum_j a_kj P_j)``, the second to compare with the axis sweep's model
    of the same rig; ``hold_s`` as the estimate was fitted. A rotor with no reported lag (it
    moved no rig) enters with its entry alone, which is zero within its sigma."""
    row = AXES[rig.axis]
    omega = np.atleast_1d(np.asarray(omega_rad_s, dtype=float))[None, :]
    t, tau = (np.nan_to_num(v)[:, None] for v in (est.time_constant_s, est.delay_s))
    t = np.where(t > 0, t, TIME_CONSTANT_BOUNDS_S[0])
    e, spin = (v[row][:, None] for v in (est.effectiveness_rad_s2, est.spin_up_rad_s))
    if hold_s is not None:
        per_e, per_m = held_paths(omega, hold_s, t, tau, rig.damping_rad_s,
                                  rig.stiffness_rad2_s2)
    else:
        per_e = np.exp(-1j * omega * tau) / (t * 1j * omega + 1) * rig.response(omega)
        per_m = 1j * omega * per_e
    paths = e * per_e + spin * per_m
    return paths, np.asarray(rig.allocation, dtype=float) @ paths
