"""Transfer-function fitting to frequency-response points (the missing ``invfreqs``).

Given points ``F_k = F(j omega_k)`` and an order ``m/n`` this module fits

    G(s) = (a_m s^m + ... + a_0) / (s^n + b_{n-1} s^{n-1} + ... + b_0) * exp(-s tau)

in three stages (docs/method.md has the derivations):

1. **Levy** (docs/paper.md step 3, MATLAB invfreqs' default): minimise the weighted equation error
   ``sum w_k^2 |D(j w_k) F_k - N(j w_k)|^2``, linear in the coefficients.
2. **Sanathanan-Koerner**: repeat Levy with weights ``w_k / |D_prev(j w_k)|`` so the equation
   error approaches the output error; this removes Levy's over-weighting of high frequencies.
3. **Output-error refinement**: minimise ``sum w_k^2 |F_k - G(j w_k)|^2`` by Levenberg-Marquardt
   (:func:`_least_squares`, with Coleman and Li's scaling at the bounds) over the poles and
   the delay only: for
   fixed poles and delay the numerator is linear and is solved exactly (variable projection),
   and the Jacobian of the projected residual is analytic (every parameter scales the basis
   ``s^i / D(s) e^{-s tau}`` point by point). The denominator is parametrised as a product of
   ``s^2 + e^p s + e^q`` factors (and one ``s + e^r`` for odd ``n``), which is stable for
   every parameter value, so the result is stable by construction.

   Starts, of four kinds: Levy, SK with the given weights, SK with unit weights, and for
   ``n >= 2`` the next-lower order's SK poles with one fast pole; with a delay each kind is
   built at every delay of a grid over ``[0, pi / omega_max]`` (the data with that delay
   removed), and the cost of every start as it stands (one evaluation, no refinement) picks
   the five lowest of each kind. The starts are refined briefly, the two best of them on until
   they converge, and the best of all is kept. Tests hold this to the best of refining every
   start fully, with a delay and without.

4. **CIFER's J** (``cost="j"``, the default; :mod:`heliquad.host.estimate.cifer`): from the
   J_STARTS output-error results of lowest cost, Levenberg-Marquardt on J itself, the
   magnitude error in dB and the phase error in degrees (weighted 0.01745) at each point,
   each point weighted by its coherence (CIFER's ``W_gamma``), over the pole parameters (the
   same stable parametrisation), the numerator's coefficients and the delay. The residuals
   are ``sqrt(20 W_gamma / n)`` times the real and imaginary parts of ``log(G / F)`` in
   those units, whose derivatives are analytic (``d log G = dN / N - dD / D - s dtau``).
   The model of lowest J is kept; J is never above the output-error fit's own. The
   weights ``w_k`` of stages 1-3 shape its starts only. ``cost="relative"`` stops after
   stage 3.

With ``stable=False`` the refinement works on the free denominator coefficients instead, and
the model's ``stable`` flag reports what came out.

Frequencies are scaled by ``omega_0`` (the geometric mean of the band) during the fit so the
Vandermonde-like matrices stay well conditioned; coefficients are returned unscaled, in
descending powers of ``s``, with a monic denominator (python-control and MATLAB order).
"""

from __future__ import annotations

import dataclasses
import re

import numpy as np

from ...sim.base.errors import InputError
from ..records.choices import COSTS
from .cifer import J_PHASE_WEIGHT, J_SCALE, cifer_weight

__all__ = ["TfModel", "fit_tf", "fit_levy", "parse_order", "model_response", "format_tf",
           "order_name", "COSTS"]

#: Sanathanan-Koerner iterations at most, and the relative change that stops them early.
SK_MAX_ITER = 30
SK_TOL = 1e-12
#: Delays tried as starts, as a fraction of the largest delay (pi / omega_max).
DELAY_GRID = np.linspace(0.0, 1.0, 13)
#: Of each kind of start (Levy, SK, unit-weight SK, next-lower order with a fast pole) this
#: many are refined: those of lowest cost before refinement across DELAY_GRID (without a
#: delay there is one of each kind).
#: None refines every start fully (the exhaustive search, kept to test the choice against).
STARTS_PER_KIND = 5
#: A refinement stops after this many residual evaluations per parameter (plus one).
REFINE_EVALUATIONS = 400
#: The J stage's refinements stop after this many (J is flat along a valley where an order
#: has a parameter to spare: past this, a fifth of a per cent of a J that is a thousandth
#: of the acceptable one).
J_EVALUATIONS = 100
#: The J stage starts from this many of the output-error refinement's results, those of
#: lowest output error (distinct minima can swap places under J's other weighting).
J_STARTS = 3
#: The chosen starts are first refined for this many evaluations per parameter
#: (plus one); the CONTINUED lowest-cost of them then go on to REFINE_EVALUATIONS.
SCREEN_EVALUATIONS = 10
CONTINUED = 2
#: The refinement's tolerance (relative: the cost's decrease, the step, the gradient) and
#: its first damping (relative to the scaled J^T J, whose diagonal is 1 at the start; a
#: parameter near a bound it is moving towards is damped more, :func:`_damped_step`).
LSQ_TOL = 1e-15
LSQ_DAMPING = 1e-3
#: Roots on the imaginary axis (after reflection) are moved left by this fraction of
#: omega_0 so that the log parametrisation exists.
AXIS_MARGIN = 1e-6
#: The extra pole of a start built from the next-lower order sits this far above the band.
FAST_POLE = 10.0
#: Poles are kept within this factor of the band's centre frequency (above and below): the
#: log-parameters of a factor ``s + e^r`` are bounded by ``ln(POLE_RANGE)`` and those of
#: ``s^2 + e^p s + e^q`` by ``ln(2 POLE_RANGE)`` and ``2 ln(POLE_RANGE)``. A pole that runs
#: to the bound means the data do not support the order; the model is flagged degenerate.
POLE_RANGE = 1e4
LOG_LIMIT = 2.0 * np.log(2.0 * POLE_RANGE)


@dataclasses.dataclass
class TfModel:
    """A fitted transfer function and what is known about it.

    Attributes
    ----------
    order : tuple of int
        ``(m, n)``: numerator and denominator degrees.
    num, den : ndarray
        Coefficients in descending powers of ``s``; ``den[0] == 1``.
    delay_s : float
        Pure time delay ``tau`` in seconds (0 when not fitted).
    stable : bool
        Every pole has a negative real part.
    delay_fitted : bool
        The delay was a free parameter of the fit (it may have come out as 0).
    degenerate : bool
        The points do not support this order: a pole ran to the edge of the allowed range
        (``POLE_RANGE`` times the band's centre frequency, or as far below), or (flagged by
        :func:`heliquad.host.estimate.models.fit_orders`) a zero lies far below or far above the band
        or all but cancels a pole.
    degenerate_why : str
        Which of these, in words ("" when not degenerate).
    integrator : bool
        One of the ``n`` poles is fixed at the origin (order ``M/Ni``): a rate that
        integrates the command, as a free rig's does; ``stable`` then speaks of the others.
    cost : str
        What the fit minimised: ``"j"`` (CIFER's J) or ``"relative"`` (the weighted
        output error), :data:`COSTS`.
    metrics : dict
        Filled by :func:`heliquad.host.estimate.metrics.evaluate_model`.
    """

    order: tuple
    num: np.ndarray
    den: np.ndarray
    delay_s: float = 0.0
    stable: bool = True
    delay_fitted: bool = False
    degenerate: bool = False
    integrator: bool = False
    degenerate_why: str = ""
    cost: str = "relative"
    metrics: dict = dataclasses.field(default_factory=dict)

    @property
    def structure(self) -> tuple:
        """The order as :func:`parse_order` gives it: ``(m, n)``, or ``(m, n, 1)`` with an
        integrator."""
        return (*self.order, 1) if self.integrator else tuple(self.order)

    @property
    def poles(self) -> np.ndarray:
        return np.roots(self.den)

    @property
    def zeros(self) -> np.ndarray:
        return np.roots(self.num) if len(self.num) > 1 else np.array([])

    @property
    def dc_gain(self) -> float:
        """``G(0)``; infinite for a pole at the origin."""
        if self.den[-1] == 0:
            return float("inf")
        return float(self.num[-1] / self.den[-1])

    def response(self, omega_rad_s) -> np.ndarray:
        """Complex frequency response at ``omega_rad_s``."""
        return model_response(self.num, self.den, self.delay_s, omega_rad_s)


def model_response(num, den, delay_s, omega_rad_s) -> np.ndarray:
    """``N(j w) / D(j w) * exp(-j w tau)``."""
    s = 1j * np.asarray(omega_rad_s, dtype=float)
    return np.polyval(num, s) / np.polyval(den, s) * np.exp(-s * delay_s)


_ORDER_RE = re.compile(r"^\s*(\d+)\s*/\s*(\d+)\s*(i?)\s*$")


def parse_order(text: str) -> tuple:
    """Parse ``"M/N"`` (numerator/denominator degree) into ``(M, N)``, and ``"M/Ni"`` (one of
    the N poles at the origin: an integrator) into ``(M, N, 1)``."""
    match = _ORDER_RE.match(str(text))
    if not match:
        raise InputError(f"order {text!r} is not of the form M/N (numerator/denominator "
                         "degree, e.g. 0/2; 0/2i puts one of the poles at the origin)")
    m, n = int(match.group(1)), int(match.group(2))
    if match.group(3):
        if n < 2 or m > n - 1:
            raise InputError(f"order {text}: an integrator order needs N >= 2 and M <= N - 1 "
                             "(e.g. 0/2i: K / (s (s + a)))")
        return m, n, 1
    if n < 1:
        raise InputError(f"order {text}: the denominator degree must be at least 1")
    if m > n:
        raise InputError(f"order {text}: improper (numerator degree above denominator's); "
                         "a physical rate response is proper")
    if n > 12:
        raise InputError(f"order {text}: denominator degree above 12 is not supported")
    return m, n


def n_parameters(order, delay: bool) -> int:
    """Real parameters of a model: ``m + 1`` numerator, ``n`` denominator (``n - 1`` with an
    integrator: its pole is fixed), optional delay."""
    m, n = order[:2]
    return m + 1 + n - int(len(order) > 2 and bool(order[2])) + int(delay)


def order_name(order, delay: bool = False) -> str:
    """``"0/2"``, ``"0/2i"`` with an integrator, ``+d`` with a fitted delay."""
    integrator = "i" if len(order) > 2 and order[2] else ""
    return f"{order[0]}/{order[1]}{integrator}" + ("+d" if delay else "")


# --- Levy and Sanathanan-Koerner (linear, in scaled frequency) -----------------------------

def _levy_solve(x, F, m, n, w):
    """Weighted Levy step in scaled frequency ``x``: returns (num, den) descending, den monic."""
    s = 1j * x
    # Unknowns: a_0..a_m, b_0..b_{n-1};  sum b_i F s^i - sum a_i s^i = -F s^n.
    cols = [-(s ** i) for i in range(m + 1)] + [F * s ** i for i in range(n)]
    A = np.column_stack(cols) * w[:, None]
    rhs = -F * s ** n * w
    A_real = np.vstack([A.real, A.imag])
    rhs_real = np.concatenate([rhs.real, rhs.imag])
    scale = np.linalg.norm(A_real, axis=0)
    scale[scale == 0] = 1.0
    sol, *_ = np.linalg.lstsq(A_real / scale, rhs_real, rcond=None)
    sol /= scale
    num = sol[:m + 1][::-1]
    den = np.concatenate([[1.0], sol[m + 1:][::-1]])
    return num, den


def fit_levy(omega_rad_s, F, order, weights=None):
    """Plain Levy fit (one linear solve), as MATLAB invfreqs does without 'iter'.

    Returns ``(num, den)`` in descending powers of ``s``, den monic.
    """
    x, w0 = _scaled(omega_rad_s)
    w = np.ones_like(x) if weights is None else np.asarray(weights, float)
    num, den = _levy_solve(x, np.asarray(F, complex), order[0], order[1], w)
    return _unscale(num, den, w0)


def _sk_solve(x, F, m, n, w, start=None):
    num, den = start if start is not None else _levy_solve(x, F, m, n, w)
    for _ in range(SK_MAX_ITER):
        d = np.abs(np.polyval(den, 1j * x))
        if not np.all(np.isfinite(d)) or np.any(d == 0):
            break
        new_num, new_den = _levy_solve(x, F, m, n, w / d)
        change = np.linalg.norm(new_den - den) / np.linalg.norm(new_den)
        num, den = new_num, new_den
        if change < SK_TOL:
            break
    return num, den


def _scaled(omega_rad_s):
    """Frequencies over their band's centre ``w0`` (the geometric mean of the lowest and the
    highest, taken in logs so that neither overflows nor underflows)."""
    omega = np.asarray(omega_rad_s, dtype=float)
    w0 = float(np.exp(0.5 * (np.log(omega.min()) + np.log(omega.max()))))
    return omega / w0, w0


def _normalised(omega_rad_s, F, weights):
    """The points as the fit works on them: ``(x, w0, F / g0, g0, w)``, frequencies over
    ``w0`` (:func:`_scaled`), the response over its typical magnitude ``g0`` (the geometric
    mean of ``|F|``) and weights of typical size 1 (their scale does not move the fit). An
    InputError for points no fit can use."""
    omega = np.asarray(omega_rad_s, dtype=float)
    F = np.asarray(F, dtype=complex)
    w = 1.0 / np.abs(F) if weights is None else np.asarray(weights, dtype=float)
    if not (omega.ndim == 1 and omega.size == F.size == w.size and omega.size >= 1):
        raise InputError("frequencies, responses and weights must be lists of one length")
    if not (np.all(np.isfinite(omega)) and np.all(omega > 0) and np.all(np.diff(omega) > 0)):
        raise InputError("frequencies must be finite, positive and strictly increasing")
    if not (np.all(np.isfinite(F)) and np.all(F != 0)):
        raise InputError("responses must be finite and not zero")
    if not (np.all(np.isfinite(w)) and np.all(w > 0)):
        raise InputError("weights must be finite and positive")
    with np.errstate(all="ignore"):
        g0 = float(np.exp(np.mean(np.log(np.abs(F)))))
        w = w * g0
        w = w / np.exp(np.mean(np.log(w)))
    x, w0 = _scaled(omega)
    if not (np.all(np.isfinite(w)) and np.all(w > 0) and np.all(np.isfinite(x)) and g0 > 0):
        raise InputError("the points' frequencies, magnitudes or weights span more than double "
                         "precision holds")
    return x, w0, F / g0, g0, w


def _check_unscaled(order, num, den, response, omega) -> None:
    """The model in rad/s must still be the one fitted in scaled frequency: coefficients of
    ``w0`` to the n-th power over- or underflow when the band is far from 1 rad/s."""
    with np.errstate(all="ignore"):
        ok = np.all(np.isfinite(num)) and np.all(np.isfinite(den)) and np.any(num != 0)
        if ok:
            got = model_response(num, den, 0.0, omega)
            ok = bool(np.all(np.abs(got - response) <= 1e-6 * np.abs(response) + 1e-300))
    if not ok:
        raise InputError(f"order {order[0]}/{order[1]}: in rad/s the model's coefficients "
                         "leave double precision (the band or the magnitudes are too far from "
                         "1); give the points in other units")


def _unscale(num, den, w0):
    """From ``s' = s / w0`` back to ``s``; the monic denominator stays monic."""
    n = len(den) - 1
    with np.errstate(over="ignore", under="ignore"):      # checked by _check_unscaled
        den_s = np.asarray(den) * w0 ** (np.arange(n + 1))        # d'_i w0^(n-i), descending
        num_s = np.asarray(num) * w0 ** (n - np.arange(len(num) - 1, -1, -1))
    return num_s, den_s


# --- stable denominator parametrisation -----------------------------------------------------

def _reflect(den):
    """Roots of ``den`` moved into the open left half plane (real parts negated)."""
    roots = np.roots(den)
    return -np.abs(roots.real) - AXIS_MARGIN + 1j * roots.imag


def _roots_to_params(roots):
    """Stable roots -> ``[p, q]`` per quadratic factor and ``[r]`` for a leftover real root."""
    roots = np.asarray(roots)
    cplx = roots[roots.imag > 1e-12 * np.maximum(1.0, np.abs(roots))]
    real = np.sort(roots[np.abs(roots.imag) <= 1e-12 * np.maximum(1.0, np.abs(roots))].real)
    params = []
    for r in cplx:                            # upper half-plane member of each pair
        params += [np.log(-2 * r.real), np.log(abs(r) ** 2)]
    for i in range(0, len(real) - 1, 2):
        a, b = -real[i], -real[i + 1]
        params += [np.log(a + b), np.log(a * b)]
    if len(real) % 2:
        params.append(np.log(-real[-1]))
    return np.array(params, dtype=float)


def _params_to_den(params, n):
    params = np.clip(params, -LOG_LIMIT, LOG_LIMIT)
    den = np.array([1.0])
    for i in range(n // 2):
        den = np.polymul(den, [1.0, np.exp(params[2 * i]), np.exp(params[2 * i + 1])])
    if n % 2:
        den = np.polymul(den, [1.0, np.exp(params[n - 1])])
    return den


# --- output-error refinement (variable projection) -----------------------------------------

class _OutputError:
    """Residuals ``w (F - N/D e^{-j x tau'})`` with ``N`` solved linearly for given poles, and
    their Jacobian.

    For parameters ``theta`` (pole parameters, then the delay) the residual is the variable
    projection ``r = b - A A^+ b``: ``A`` stacks the real and imaginary parts of the complex
    basis ``A_c = vander * w e^{-s tau} / D(s)`` and ``b`` those of ``w F``. Each parameter
    scales the basis row by row, ``dA_c/dtheta_k = g_k * A_c`` with ``g_k = -dD/dtheta_k / D``
    for a pole parameter and ``g = -s`` for the delay, so the Jacobian (Golub and Pereyra's
    full form) is ``-(P_perp dA_k a + (A^+)^T dA_k^T r)``, ``a = A^+ b``. One singular value
    decomposition per parameter vector serves both (cached on the vector).
    """

    def __init__(self, x, F, m, n, w, stable, delay):
        self.x, self.F, self.m, self.n, self.w = x, F, m, n, w
        self.stable, self.delay = stable, delay
        self.s = 1j * x
        self.vander = np.column_stack([self.s ** i for i in range(m, -1, -1)])
        # free coefficients: D = s^n + sum_k c_k s^(n-k), dD/dc_k = s^(n-k)
        self.powers = np.column_stack([self.s ** i for i in range(n - 1, -1, -1)])
        self.rhs = w * F
        self.b = np.concatenate([self.rhs.real, self.rhs.imag])
        self.rcond = np.finfo(float).eps * max(2 * x.size, m + 1)    # numpy lstsq's cut
        self._key, self._state = None, None

    def den(self, params):
        if self.stable:
            return _params_to_den(params[:self.n], self.n)
        return np.concatenate([[1.0], params[:self.n]])

    def _den_terms(self, params):
        """``D(s)`` at the points and ``dD/dtheta_k / D`` (a column per pole parameter)."""
        n, s = self.n, self.s
        if not self.stable:
            D = s ** n + self.powers @ params[:n]
            return D, self.powers / D[:, None]
        e = np.exp(np.clip(params[:n], -LOG_LIMIT, LOG_LIMIT))
        k = 2 * (n // 2)
        sc = s[:, None]
        inv = 1.0 / (sc * (sc + e[0:k:2]) + e[1:k:2])         # 1 / (s^2 + e^p s + e^q)
        dlog = np.empty((s.size, n), dtype=complex)
        dlog[:, 0:k:2] = sc * e[0:k:2] * inv
        dlog[:, 1:k:2] = e[1:k:2] * inv
        D = 1.0 / np.prod(inv, axis=1)
        if n % 2:                                                # and s + e^r
            D *= s + e[-1]
            dlog[:, -1] = e[-1] / (s + e[-1])
        clipped = np.abs(params[:n]) >= LOG_LIMIT                # such a parameter moves nothing
        if clipped.any():
            dlog[:, clipped] = 0.0
        return D, dlog

    def _solve(self, params):
        """The projection at ``params`` (cached): None where the basis is not finite, else
        ``(r, rc, U, sv, Vt, A_c, model, dlogD)``: ``r`` the residuals, ``rc`` the same as
        complex numbers, ``A = U diag(sv) Vt`` truncated as numpy's lstsq truncates, and
        ``model = A_c a``."""
        key = params.tobytes()
        if key == self._key:
            return self._state
        tau = params[self.n] if self.delay else 0.0
        # A trial step may put a pole on a point's frequency: the basis is then not finite,
        # which residuals() answers with a large cost; numpy need not warn about it.
        with np.errstate(all="ignore"):
            D, dlog = self._den_terms(params)
            A_c = self.vander * (self.w * np.exp(-self.s * tau) / D)[:, None]
            finite = np.isfinite(A_c.sum() + dlog.sum())
        state = None
        if finite:
            U, sv, Vt = np.linalg.svd(np.vstack([A_c.real, A_c.imag]), full_matrices=False)
            keep = sv > self.rcond * sv[0]
            U, sv, Vt = U[:, keep], sv[keep], Vt[keep]
            model = A_c @ (Vt.T @ ((U.T @ self.b) / sv))
            rc = self.rhs - model
            state = (np.concatenate([rc.real, rc.imag]), rc, U, sv, Vt, A_c, model, dlog)
        self._key, self._state = key, state
        return state

    def num(self, params):
        """The numerator's coefficients (scaled frequency, descending) for ``params``; not
        finite where the basis is not."""
        state = self._solve(params)
        if state is None:
            return np.full(self.m + 1, np.nan)
        U, sv, Vt = state[2:5]
        return Vt.T @ ((U.T @ self.b) / sv)

    def residuals(self, params):
        state = self._solve(params)
        if state is None:
            return self.b * 1e6                # a trial step off the map: a large, finite cost
        return state[0]

    def jacobian(self, params):
        """``dr/dtheta``, one column per parameter."""
        state = self._solve(params)
        if state is None:
            return np.zeros((self.b.size, params.size))
        _, rc, U, sv, Vt, A_c, model, dlog = state
        g = np.empty((self.s.size, params.size), dtype=complex)   # dA_k = g_k * A_c, row-wise
        g[:, :self.n] = -dlog
        if self.delay:
            g[:, self.n] = -self.s
        moved = g * model[:, None]                                # dA_k a
        moved = np.vstack([moved.real, moved.imag])
        pulled = (A_c.conj().T @ (g.conj() * rc[:, None])).real   # dA_k^T r
        term1 = moved - U @ (U.T @ moved)                        # P_perp dA_k a
        term2 = U @ ((Vt @ pulled) / sv[:, None])                # (A^+)^T dA_k^T r
        return -(term1 + term2)

    def bounds(self):
        """Lower and upper bounds of the pole parameters (none for free coefficients)."""
        if not self.stable:
            return np.full(self.n, -np.inf), np.full(self.n, np.inf)
        b = np.empty(self.n)
        b[0:2 * (self.n // 2):2] = np.log(2.0 * POLE_RANGE)      # p: sum of decay rates
        b[1:2 * (self.n // 2):2] = 2.0 * np.log(POLE_RANGE)      # q: product of magnitudes
        if self.n % 2:
            b[-1] = np.log(POLE_RANGE)                           # r: a real pole
        return -b, b

    def initial(self, den, tau):
        if self.stable:
            lo, hi = self.bounds()
            p = np.clip(_roots_to_params(_reflect(den)), lo + 1e-9, hi - 1e-9)
        else:
            p = np.asarray(den[1:], dtype=float)
        return np.concatenate([p, [tau]]) if self.delay else p


def _refine(problem, x0, tau_max, evaluations):
    """Output-error refinement from ``x0``: ``(params, cost, done)``, ``done`` when it stopped
    by its tolerances rather than after ``evaluations`` per parameter (plus one)."""
    lower, upper = (np.append(b, 0.0) for b in problem.bounds())
    lower, upper = lower[:x0.size], upper[:x0.size]
    if problem.delay:
        lower[-1], upper[-1] = 0.0, tau_max
    x, r, done = _least_squares(problem.residuals, problem.jacobian, x0, lower, upper,
                                evaluations * (x0.size + 1))
    return x, float(r @ r), done


def _least_squares(fun, jac, x0, lower, upper, max_nfev):
    """Minimise ``|fun(x)|^2`` for ``lower <= x <= upper`` from ``x0`` (clipped into the box),
    ``jac`` its Jacobian: ``(x, fun(x), done)``, ``done`` when it stopped by its tolerances
    (or where the residuals or the Jacobian are not finite) rather than after ``max_nfev``
    evaluations of ``fun``.

    Levenberg-Marquardt with Nielsen's update of the damping, in parameters scaled by the
    largest norm each Jacobian column has had (Moré's scaling), over the box by projection: a
    parameter on a bound that the gradient pushes outward is held for the step, and the step
    is clipped into the box. It stops when the cost's decrease, the step or the free
    gradient falls to LSQ_TOL relative (the round-off of the cost), or the cost to zero. Here
    rather than scipy.optimize's trust-region solver: the problems are a few parameters by a
    few dozen residuals, and importing scipy.optimize cost a fifth of a second of every
    identify."""
    x = np.clip(np.asarray(x0, dtype=float), lower, upper)
    r, J = fun(x), jac(x)
    nfev, damping, grow = 1, LSQ_DAMPING, 2.0
    if not (np.all(np.isfinite(r)) and np.all(np.isfinite(J))):
        return x, r, True
    cost = float(r @ r)
    scale = np.maximum(np.linalg.norm(J, axis=0), np.finfo(float).tiny)
    while nfev < max_nfev:
        g = J.T @ r
        free = ~(((x <= lower) & (g > 0)) | ((x >= upper) & (g < 0)))
        if cost == 0.0 or not free.any() or \
                np.max(np.abs(g[free]) / scale[free]) <= LSQ_TOL * max(cost, 1e-300) ** 0.5:
            return x, r, True
        step = _damped_step(J, r, g, x, lower, upper, scale, free, damping)
        if step is None:
            return x, r, True
        trial = np.clip(x + step, lower, upper)
        step = trial - x
        if np.linalg.norm(step) <= LSQ_TOL * (LSQ_TOL + np.linalg.norm(x)):
            return x, r, True
        r_trial = fun(trial)
        nfev += 1
        cost_trial = float(r_trial @ r_trial)
        Js = J @ step
        predicted = -(2.0 * (g @ step) + Js @ Js)         # the linear model's decrease
        ratio = (cost - cost_trial) / predicted if predicted > 0 else -1.0
        if ratio > 0 and np.isfinite(cost_trial):
            converged = cost - cost_trial <= LSQ_TOL * cost
            x, r, cost, J = trial, r_trial, cost_trial, jac(trial)
            if not np.all(np.isfinite(J)):
                return x, r, True
            scale = np.maximum(scale, np.linalg.norm(J, axis=0))
            damping *= max(1.0 / 3.0, 1.0 - (2.0 * ratio - 1.0) ** 3)
            grow = 2.0
            if converged:
                return x, r, True
        else:
            damping *= grow
            grow *= 2.0
    return x, r, False


def _damped_step(J, r, g, x, lower, upper, scale, free, damping):
    """The damped Gauss-Newton step of the free parameters, or None where it cannot be
    found. It is solved as a least-squares problem of its own in the scaled parameters
    ``z = scale * step``: ``[J / scale; sqrt(damping / room)] z = [-r; 0]`` (no J^T J, no
    scale squared, so nothing overflows; a Jacobian without full rank, as where a zero
    cancels a pole, gives the shortest step). ``room`` is Coleman and Li's: a parameter that
    the gradient moves towards a bound is damped by its distance to that bound (1 where
    there is none), so that steps do not zigzag against it."""
    room = np.where(g > 0, x - lower, np.where(g < 0, upper - x, np.inf))
    room = np.where(np.isfinite(room), np.maximum(room, 1e-300), 1.0)[free]
    stacked = np.vstack([J[:, free] / scale[free], np.diag(np.sqrt(damping / room))])
    if not np.all(np.isfinite(stacked)):
        return None
    try:
        z = np.linalg.lstsq(stacked, np.concatenate([-r, np.zeros(room.size)]), rcond=None)[0]
    except np.linalg.LinAlgError:
        return None
    step = np.zeros_like(x)
    step[free] = z / scale[free]
    return step


def _starts(x, F, m, n, w, delay, tau_max):
    """Initial ``(den, tau, kind)`` in scaled frequency: at each trial delay (0 alone without
    a delay) the Levy, SK and unit-weight SK denominators and, for ``n >= 2``, the next-lower
    order's SK poles with a fast pole; ``kind`` names which of these a start is."""
    taus = DELAY_GRID * tau_max if delay else [0.0]
    starts = []
    for tau in taus:
        Fd = F * np.exp(1j * x * tau)             # the data with the trial delay removed
        levy = _levy_solve(x, Fd, m, n, w)
        starts.append((levy[1], tau, "levy"))
        starts.append((_sk_solve(x, Fd, m, n, w, levy)[1], tau, "sk"))
        starts.append((_sk_solve(x, Fd, m, n, np.ones_like(w))[1], tau, "sk-unit"))
        if n >= 2:
            # The next-lower order's poles and one fast pole above the band: the start that
            # reaches "this order is one more than the data need" without a local minimum.
            lower = _sk_solve(x, Fd, min(m, n - 1), n - 1, w)[1]
            starts.append((np.polymul(lower, [1.0, FAST_POLE * x.max()]), tau, "lower+fast"))
    return starts


def _chosen(problem, starts):
    """The parameter vectors worth refining, from the ``(den, tau, kind)`` starts: of each
    kind the STARTS_PER_KIND whose cost as they stand (one residual evaluation each, no
    refinement) is lowest (across the delay grid with a delay; without one there is a start
    of each kind, so every start); every start when STARTS_PER_KIND is None.
    """
    usable = [(problem.initial(den, tau), kind) for den, tau, kind in starts
              if np.all(np.isfinite(den))]
    if STARTS_PER_KIND is None:
        return [params for params, _ in usable]
    cost = [float(np.sum(problem.residuals(params) ** 2)) for params, _ in usable]
    chosen = []
    for kind in dict.fromkeys(kind for _, kind in usable):
        of_kind = [i for i, (_, k) in enumerate(usable) if k == kind]
        chosen += sorted(of_kind, key=cost.__getitem__)[:STARTS_PER_KIND]
    return [usable[i][0] for i in sorted(chosen)]


def _refined(problem, starts, tau_max):
    """``(params, cost)`` of the refined starts (see :func:`_chosen`): each chosen start is
    refined for SCREEN_EVALUATIONS, which tells the minima apart, and the CONTINUED lowest
    that have not converged go on from there to REFINE_EVALUATIONS. Every start is refined
    fully when STARTS_PER_KIND is None (the exhaustive search the tests hold this to)."""
    chosen = _chosen(problem, starts)
    if STARTS_PER_KIND is None:
        return [_refine(problem, params, tau_max, REFINE_EVALUATIONS)[:2] for params in chosen]
    screened = sorted((_refine(problem, params, tau_max, SCREEN_EVALUATIONS)
                       for params in chosen), key=lambda result: result[1])
    continued = [_refine(problem, params, tau_max, REFINE_EVALUATIONS)[:2]
                 for params, _, done in screened[:CONTINUED] if not done]
    return [result[:2] for result in screened] + continued


# --- CIFER's J (stage 4) --------------------------------------------------------------------

#: dB per neper and degrees per radian: ``log(G / F)``'s real and imaginary parts in J's units.
_DB_PER_NEPER = 20.0 / np.log(10.0)
_DEG_PER_RAD = 180.0 / np.pi


class _JCost:
    """Residuals of CIFER's J for ``theta = (pole parameters, numerator, delay)``, J their
    sum of squares, and their Jacobian. The denominator's terms are the output-error
    problem's (:class:`_OutputError`), so the poles mean the same in both stages."""

    def __init__(self, problem: _OutputError, w_gamma):
        self.p = problem
        self.n, self.m, self.delay = problem.n, problem.m, problem.delay
        k = np.sqrt(J_SCALE * np.asarray(w_gamma, dtype=float) / problem.x.size)
        self.k_mag = k * _DB_PER_NEPER
        self.k_phase = k * _DEG_PER_RAD * np.sqrt(J_PHASE_WEIGHT)
        self.size = problem.n + problem.m + 1 + int(problem.delay)

    def theta(self, params):
        """The J stage's parameters from the output-error stage's: its numerator solved."""
        num = self.p.num(params)
        tau = params[self.n:self.n + 1] if self.delay else np.empty(0)
        return np.concatenate([params[:self.n], num, tau])

    def params(self, theta):
        """The output-error stage's parameters (poles, delay) within ``theta``."""
        tau = theta[-1:] if self.delay else np.empty(0)
        return np.concatenate([theta[:self.n], tau])

    def num(self, theta):
        return theta[self.n:self.n + self.m + 1]

    def _terms(self, theta):
        """``log(G / F)`` at the points, and ``dD/dtheta / D`` and ``N``; None where the
        model is not finite or is 0 at a point."""
        p, tau = self.p, (theta[-1] if self.delay else 0.0)
        with np.errstate(all="ignore"):
            D, dlog = p._den_terms(theta[:self.n])
            N = p.vander @ self.num(theta)
            log_ratio = np.log(N / (D * p.F)) - p.s * tau
            if not (np.all(np.isfinite(log_ratio)) and np.all(np.isfinite(dlog))):
                return None
        # the principal phase, as the metric reads it
        log_ratio = log_ratio.real + 1j * np.angle(np.exp(1j * log_ratio.imag))
        return log_ratio, dlog, N

    def residuals(self, theta):
        terms = self._terms(theta)
        if terms is None:                       # a trial step off the map: a large cost
            return np.full(2 * self.p.x.size, 1e6)
        e = terms[0]
        return np.concatenate([self.k_mag * e.real, self.k_phase * e.imag])

    def jacobian(self, theta):
        terms = self._terms(theta)
        if terms is None:
            return np.zeros((2 * self.p.x.size, self.size))
        _, dlog, N = terms
        d = np.empty((self.p.x.size, self.size), dtype=complex)   # d log G / d theta
        d[:, :self.n] = -dlog
        d[:, self.n:self.n + self.m + 1] = self.p.vander / N[:, None]
        if self.delay:
            d[:, -1] = -self.p.s
        return np.vstack([self.k_mag[:, None] * d.real, self.k_phase[:, None] * d.imag])

    def bounds(self, tau_max):
        lo, hi = self.p.bounds()
        free = np.full(self.m + 1, np.inf)
        lower, upper = np.concatenate([lo, -free]), np.concatenate([hi, free])
        if self.delay:
            lower, upper = np.append(lower, 0.0), np.append(upper, tau_max)
        return lower, upper


def _j_stage(problem, refined, w_gamma, tau_max):
    """Stage 4 from the J_STARTS lowest-cost ``(params, cost)`` of stage 3: ``theta`` of the
    lowest J reached (a start's own when no refinement lowers it; None when no start is
    finite), and the :class:`_JCost` that reads it."""
    cost = _JCost(problem, w_gamma)
    lower, upper = cost.bounds(tau_max)
    best_theta, best_j = None, np.inf
    for params, _ in sorted(refined, key=lambda result: result[1])[:J_STARTS]:
        start = cost.theta(params)
        if not np.all(np.isfinite(start)):
            continue
        r0 = cost.residuals(start)
        theta, r, _ = _least_squares(cost.residuals, cost.jacobian, start, lower, upper,
                                     J_EVALUATIONS * (start.size + 1))
        for candidate, res in ((start, r0), (theta, r)):
            j = float(res @ res)
            if np.isfinite(j) and j < best_j:
                best_theta, best_j = candidate, j
    return best_theta, cost


def _minimised(problem, starts, tau_max, w_gamma):
    """The fit's stages 3 and 4: ``(params, num)`` (scaled frequency) of the output-error
    refinement's best result, or, with J's weights ``w_gamma`` (None: stage 3 alone), of
    J's stage started from its best results."""
    # Weights that span hundreds of decades (sigma from 1e-8 to 1e238 is a valid file) make
    # infinite costs, which lose to every finite one, and numpy need not warn about them.
    with np.errstate(over="ignore", invalid="ignore"):
        refined = _refined(problem, starts, tau_max)
        finite = [(params, error) for params, error in refined if error < np.inf]
        if not finite:
            raise InputError(f"order {problem.m}/{problem.n}: no fit could be started "
                             "(degenerate points)")
        best = min(finite, key=lambda result: result[1])[0]
        if w_gamma is not None:
            theta, j_cost = _j_stage(problem, finite, w_gamma, tau_max)
            if theta is not None:
                return j_cost.params(theta), j_cost.num(theta)
    return best, problem.num(best)


def fit_tf(omega_rad_s, F, order, weights=None, delay: bool = False,
           stable: bool = True, cost: str = "j", coherence=None) -> TfModel:
    """Fit a transfer function of the given order to frequency-response points.

    Parameters
    ----------
    omega_rad_s : array_like
        Strictly increasing frequencies, rad/s.
    F : array_like of complex
        Measured response at those frequencies.
    order : tuple of int
        ``(m, n)`` numerator and denominator degree, ``m <= n``.
    weights : array_like, optional
        Per-point weight ``w_k`` on the complex error (``1/sigma_k``, say). Default
        ``1/|F_k|``: each point counts by its relative error, as on a Bode plot.
    delay : bool
        Fit a pure time delay ``exp(-s tau)`` with the model, ``0 <= tau <= pi/omega_max``.
    stable : bool
        Constrain the poles to the left half plane (default).
    cost : str
        ``"j"`` (default): end with the stage that minimises CIFER's J; ``"relative"``:
        the output-error fit alone, weighted by ``weights`` (see the module's stages).
    coherence : array_like, optional
        Each point's coherence ``gamma^2``, J's weight (CIFER's ``W_gamma``); unknown (NaN
        or not given) counts as 1.

    Returns
    -------
    TfModel
        Without metrics; see :func:`heliquad.host.estimate.metrics.evaluate_model`.
    """
    if cost not in COSTS:
        raise InputError(f"unknown cost {cost!r}; use one of {', '.join(COSTS)}")
    if len(order) > 2 and order[2]:
        return _fit_integrator(omega_rad_s, F, order, weights, delay, stable, cost, coherence)
    m, n = order
    x, w0, F, g0, w = _normalised(omega_rad_s, F, weights)
    w_gamma = cifer_weight(np.full(x.size, np.nan) if coherence is None else coherence)
    if w_gamma.shape != x.shape:
        raise InputError("coherences must be a list as long as the points")
    tau_max = np.pi / x.max()                   # scaled: 180 degrees at the top frequency
    problem = _OutputError(x, F, m, n, w, stable, delay)
    with np.errstate(over="ignore", invalid="ignore"):      # as in _minimised
        starts = _starts(x, F, m, n, w, delay, tau_max)
    best_params, num = _minimised(problem, starts, tau_max, w_gamma if cost == "j" else None)
    den = problem.den(best_params)
    tau = best_params[n] / w0 if delay else 0.0
    num_s, den_s = _unscale(num * g0, den, w0)
    _check_unscaled(order, num_s, den_s, g0 * model_response(num, den, 0.0, x), x * w0)
    poles = np.roots(den_s)
    model = TfModel(order=(m, n), num=num_s, den=den_s, delay_s=float(tau),
                    stable=bool(np.all(poles.real < 0)), delay_fitted=bool(delay), cost=cost)
    if stable:
        lo, hi = problem.bounds()
        at_bound = np.isclose(best_params[:n], lo, atol=1e-3) | np.isclose(best_params[:n], hi, atol=1e-3)
        if np.any(at_bound):
            model.degenerate, model.degenerate_why = True, "a pole reached the edge of the allowed range"
    return model


def _fit_integrator(omega_rad_s, F, order, weights, delay, stable, cost,
                    coherence) -> TfModel:
    """``M/Ni``: ``G = N / (s D)``. Since ``|F - N/(s D)| = |s F - N/D| / w``, this is the
    ``M/(N-1)`` fit of ``s F`` with each weight over its frequency, the same problem; and
    ``G / F = (N/D) / (s F)``, so J is the same too."""
    omega = np.asarray(omega_rad_s, dtype=float)
    F = np.asarray(F, dtype=complex)
    w = (1.0 / np.abs(F)) if weights is None else np.asarray(weights, dtype=float)
    if not (omega.shape == F.shape == w.shape and np.all(omega > 0)):
        raise InputError("frequencies, responses and weights must be lists of one length, "
                         "the frequencies positive")
    m, n = order[:2]
    inner = fit_tf(omega, F * 1j * omega, (m, n - 1), weights=w / omega, delay=delay,
                   stable=stable, cost=cost, coherence=coherence)
    return TfModel(order=(m, n), num=inner.num, den=np.polymul(inner.den, [1.0, 0.0]),
                   delay_s=inner.delay_s, stable=inner.stable, delay_fitted=inner.delay_fitted,
                   degenerate=inner.degenerate, degenerate_why=inner.degenerate_why,
                   integrator=True, cost=inner.cost)


def format_tf(model) -> str:
    """``(num) / (den)`` in descending powers of s, with the delay if any."""
    def poly(c):
        n = len(c) - 1
        terms = [f"{v:.5g}" + (f" s^{n - i}" if n - i > 1 else " s" if n - i == 1 else "")
                 for i, v in enumerate(c)]
        return " + ".join(terms).replace("+ -", "- ")
    text = f"({poly(model.num)}) / ({poly(model.den)})"
    if model.delay_fitted:
        text += f" * exp(-{model.delay_s * 1e3:.3g} ms s)"
    return text
