"""From points to a set of fitted, evaluated models and a recommendation.

The one place that turns frequency points (:class:`~heliquad.host.records.points.FrequencyPoint`,
as the estimator returns them or points.csv gives them back) into models, shared by ``heliquad
fit`` and ``identify``, so both weight, fit and judge the same way.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from ...sim.base.errors import InputError
from ..records import paper
from ..records.points import known_column
from .fit import TfModel, fit_tf, n_parameters, order_name
from .metrics import cifer_weight, evaluate_model, quality, recommend

__all__ = ["WEIGHT_MODES", "FitResult", "point_weights", "fit_orders", "default_orders",
           "INTEGRATOR_ORDERS", "WIDE_BAND_ORDERS"]

#: Integrator structures tried beside the paper's orders: K / (s (s + a)), the rate of a
#: free rig driven through one lag, and with one more pole and a zero for the rotors and the
#: sampling.
INTEGRATOR_ORDERS = ((0, 2, 1), (1, 3, 1))


#: Orders added on a wide band (:data:`WIDE_BAND_FACTOR` above the paper's top for the axis,
#: as the tuning band is): there the rotors' lag, the sensor's filter and the loop's hold
#: add a pole, and the rotors' reaction torque a zero, that the paper's bands do not see.
#: Without them the fits that hold the shape drive a spare pole to the allowed range's edge
#: (degenerate), and the model left over misses the margins by several dB.
WIDE_BAND_ORDERS = ((1, 2), (1, 3), (2, 3), (1, 4))
WIDE_BAND_FACTOR = 3.0


def default_orders(axis: str, top_hz: float | None = None) -> tuple:
    """The orders identify fits unless told: the paper's for the axis and the integrator
    structures, and on a band whose top ``top_hz`` is a wide band's the
    :data:`WIDE_BAND_ORDERS` not among them."""
    orders = tuple(paper.DEFAULT_ORDERS[axis]) + INTEGRATOR_ORDERS
    if top_hz is not None and top_hz > WIDE_BAND_FACTOR * paper.BANDS_HZ[axis][1]:
        orders += tuple(o for o in WIDE_BAND_ORDERS if o not in orders)
    return orders

WEIGHT_MODES = ("auto", "sigma", "coherence", "none")
#: Sigmas below this fraction of |F| are raised to it (noise-free simulations give sigma ~ 0,
#: which would otherwise give one point all the weight).
SIGMA_FLOOR = 1e-6


@dataclasses.dataclass
class FitResult:
    """Models fitted to one points table and the recommendation among them."""

    models: list
    recommended: int | None
    reason: str
    weights: str
    band_rad_s: tuple = ()
    cost: str = "j"
    quality: tuple = ()


def point_weights(points, mode: str = "auto"):
    """Per-point weights on the complex error, and the mode actually used, for ``points``
    (:class:`~heliquad.host.records.points.FrequencyPoint`, in the order given).

    ``sigma``: ``1 / sigma``. ``coherence``: ``sqrt(W_gamma) / |F|``, the CIFER coherence
    weight on the relative error. ``none``: ``1 / |F|``, equal weight on every point's
    relative error. ``auto`` picks sigma, else coherence, else none, by what the points know.
    """
    if mode not in WEIGHT_MODES:
        raise InputError(f"unknown weights {mode!r}; use one of {', '.join(WEIGHT_MODES)}")
    known = {name: known_column(points, name) for name in ("sigma", "coherence")}
    if mode == "auto":
        mode = ("sigma" if known["sigma"] is not None
                else "coherence" if known["coherence"] is not None else "none")
    mag = np.abs(known_column(points, "gain"))
    if mode in ("sigma", "coherence") and known[mode] is None:
        raise InputError(f"--weights {mode}: the points file has no {mode} column")
    if mode == "sigma":
        return 1.0 / np.maximum(known["sigma"], SIGMA_FLOOR * mag), mode
    if mode == "coherence":
        w = np.sqrt(cifer_weight(known["coherence"])) / mag
        if not np.any(w > 0):
            raise InputError("coherence weights: every point has coherence 0, so none would "
                             "count; use --weights none (or sigma)")
        return w, mode
    return 1.0 / mag, mode


#: A zero this many times below the band's bottom is one the points cannot place.
ZERO_BELOW = 10.0
#: A zero whose factor ``1 - s/z``, or with a pole ``(s - z) / (s - p)``, stays within this
#: of 1 at every point (0.04 dB, 0.3 deg) changes nothing the points can show: the order is
#: one the data do not need, and the zero is the fit's way of spending a spare parameter.
CANCEL = 5e-3


def _unsupported_zero(model: TfModel, omega):
    """Why a zero of ``model`` is one the points at ``omega`` do not support, or None:

    - one so far above the band that ``1 - s/z`` stays within CANCEL of 1 (the yaw demo's
      2/3 put one at 2.4e7 rad/s, a numerator coefficient of 1e-5: a 1/3 in disguise);
    - one that all but cancels a pole across the band (on noise-free points a 2/4 fitted to
      a 0/2 with delay placed a pair of each at 1322 rad/s, 1e-5 apart, and won on AICc by
      rounding);
    - one far below the band (a DC behaviour no point constrains: a fitted 2/4 put one at
      0.12 rad/s under a 3.1 rad/s band, flipping the sign of its DC gain and making the
      integral loop unstable there).
    """
    zeros = model.zeros
    far = [z for z in zeros if np.max(omega) < CANCEL * abs(z)]
    if far:
        return (f"a zero at {abs(far[0]):.3g} rad/s, so far above the band that it changes "
                "nothing there")
    poles, s = list(model.poles), 1j * omega
    for z in zeros:
        if not poles:
            break
        nearest = min(range(len(poles)), key=lambda i: abs(poles[i] - z))
        if np.max(np.abs((s - z) / (s - poles[nearest]) - 1.0)) < CANCEL:
            return f"a zero cancels a pole at {abs(z):.4g} rad/s"
        poles.pop(nearest)
    below = [z for z in zeros if abs(z) < np.min(omega) / ZERO_BELOW]
    if below:
        return (f"a zero at {abs(below[0]):.3g} rad/s, more than {ZERO_BELOW:g} times below "
                "the band")
    return None


def _flag_unsupported_zeros(model: TfModel, omega) -> None:
    """A zero the points do not support (:func:`_unsupported_zero`) marks the model
    degenerate, like a pole at the allowed range's edge, and says why."""
    why = _unsupported_zero(model, np.asarray(omega, dtype=float))
    if why:
        model.degenerate, model.degenerate_why = True, why


def fit_orders(points, orders, weights: str = "auto", delay: bool = False,
               stable: bool = True, cost: str = "j") -> FitResult:
    """Fit every order to ``points`` (:class:`~heliquad.host.records.points.FrequencyPoint`,
    taken in increasing frequency), evaluate each model and recommend one. ``cost``: what
    the fits minimise (:data:`~heliquad.host.estimate.fit.COSTS`; J by default, with the
    points' coherence as its weight, the ``weights`` shaping its starts)."""
    points = sorted(points, key=lambda p: p.omega_rad_s)
    n_points = len(points)
    for order in orders:
        k = n_parameters(order, delay)
        if 2 * n_points < k + 1:
            raise InputError(f"order {order_name(order)}{' with delay' if delay else ''} has "
                             f"{k} unknowns; it needs at least {(k + 2) // 2} points, "
                             f"the file has {n_points}")
    w, mode = point_weights(points, weights)
    omega, F = known_column(points, "omega_rad_s"), known_column(points, "gain")
    coherence = known_column(points, "coherence")
    models = []
    for order in orders:
        model: TfModel = fit_tf(omega, F, order, weights=w, delay=delay, stable=stable,
                                cost=cost, coherence=coherence)
        evaluate_model(model, omega, F, w, coherence)
        _flag_unsupported_zeros(model, omega)
        models.append(model)
    index, reason = recommend(models)
    return FitResult(models=models, recommended=index, reason=reason, weights=mode, cost=cost,
                     band_rad_s=(float(np.min(omega)), float(np.max(omega))),
                     quality=() if index is None else quality(models[index]))
