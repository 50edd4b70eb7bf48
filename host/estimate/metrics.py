"""How well a fitted model matches its points, and which model to recommend.

Every metric compares the model's response ``G_k`` with the points ``F_k``:

* ``rms``: relative complex RMS error, ``sqrt(mean |F_k - G_k|^2 / |F_k|^2)`` (unitless).
* ``J``: CIFER's cost (:mod:`heliquad.host.estimate.cifer`): ``J = 20/n sum W_gamma
  [(dB error)^2 + 0.01745 (deg error)^2]`` with ``W_gamma = [1.58 (1 - exp(-gamma^2))]^2``
  from each point's coherence ``gamma^2`` (1 where unknown). ``J <= 100`` is acceptable; ``J <= 50`` is a match
  that can hardly be told from the data (CIFER's guideline).
* ``aicc``: corrected Akaike information criterion of the weighted residuals, with ``2n`` real
  observations and ``m + 1 + n (+1)`` parameters.
* ``max_mag_err_db``, ``max_phase_err_deg``: worst point.
"""

from __future__ import annotations

import math

import numpy as np

from .cifer import J_PHASE_WEIGHT, J_SCALE, cifer_weight, j_errors
from .fit import TfModel, n_parameters, order_name

__all__ = ["evaluate_model", "recommend", "quality", "cifer_weight", "J_ACCEPTABLE", "J_EXCELLENT",
           "J_PHASE_WEIGHT"]

#: CIFER guideline: J at or below this is an acceptable model.
J_ACCEPTABLE = 100.0
#: CIFER guideline: J at or below this can hardly be told from the data.
J_EXCELLENT = 50.0
#: A model is visibly worse than another when its J is above twice the other's and higher by
#: more than this (J = 5 is about 0.5 dB of RMS magnitude error: a gap a Bode plot shows).
J_VISIBLE = 5.0


def evaluate_model(model: TfModel, omega_rad_s, F, weights, coherence=None) -> dict:
    """Fill and return ``model.metrics`` for the points it was fitted to.

    ``weights`` are the per-point weights the fit used (for AICc).
    """
    omega = np.asarray(omega_rad_s, dtype=float)
    F = np.asarray(F, dtype=complex)
    G = model.response(omega)
    mag_err_db, phase_err_deg = j_errors(G, F)
    w_gamma = cifer_weight(np.ones(omega.size) if coherence is None else coherence)
    counted = w_gamma > 0                       # a point of weight 0 adds nothing, even inf
    J = J_SCALE / omega.size * float(np.sum(w_gamma[counted] * (
        mag_err_db[counted] ** 2 + J_PHASE_WEIGHT * phase_err_deg[counted] ** 2)))
    resid = np.asarray(weights, dtype=float) * (F - G)
    rss = max(float(np.sum(np.abs(resid) ** 2)), np.finfo(float).tiny)
    n_obs = 2 * omega.size
    k = n_parameters(model.structure, model.delay_fitted)
    aicc = n_obs * math.log(rss / n_obs) + 2 * k
    aicc = aicc + 2 * k * (k + 1) / (n_obs - k - 1) if n_obs - k - 1 > 0 else float("inf")
    model.metrics.update({
        "rms": float(np.sqrt(np.mean(np.abs(F - G) ** 2 / np.abs(F) ** 2))),
        "J": J,
        "aicc": float(aicc),
        "max_mag_err_db": float(np.max(np.abs(mag_err_db))),
        "max_phase_err_deg": float(np.max(np.abs(phase_err_deg))),
        "n_parameters": k,
    })
    return model.metrics


def _visibly_better(models, i, j) -> bool:
    """Model ``j``'s fit is visibly better than model ``i``'s (:data:`J_VISIBLE`)."""
    Ji, Jj = models[i].metrics["J"], models[j].metrics["J"]
    return Ji > 2 * Jj and Ji - Jj > J_VISIBLE


def recommend(models) -> tuple:
    """Pick a model by a stated rule: among the stable, non-degenerate models with acceptable
    fit (J <= 100), the lowest AICc (the information criterion weighs fit against
    parameters); then, if another acceptable model fits visibly better (J less than half
    and lower by more than 5), the lowest AICc among those instead, so the pick is never
    visibly worse than another candidate. Degenerate models (a pole at the edge of the
    allowed range: the order is more than the points support) are never picked. Without an
    acceptable stable model, the stable one with the lowest J is chosen, and the reason
    says so (:func:`quality` then says poor).

    Returns
    -------
    (index, reason) : tuple of int and str
    """
    stable = [i for i, m in enumerate(models) if m.stable and not m.degenerate]
    if not stable:
        return None, "no stable, non-degenerate model; none is recommended"
    acceptable = [i for i in stable if models[i].metrics["J"] <= J_ACCEPTABLE]
    if not acceptable:
        best = min(stable, key=lambda i: models[i].metrics["J"])
        return best, (f"no stable model reaches J <= {J_ACCEPTABLE:g}; "
                      f"{_name(models[best])} has the lowest J ({models[best].metrics['J']:.1f})")
    aicc = lambda i: models[i].metrics["aicc"]                  # noqa: E731
    pick = min(acceptable, key=aicc)
    reason = (f"{_name(models[pick])} has the lowest AICc ({aicc(pick):.1f}) of the stable "
              f"models with acceptable fit (J = {models[pick].metrics['J']:.2f} <= "
              f"{J_ACCEPTABLE:g})")
    better = [j for j in acceptable if _visibly_better(models, pick, j)]
    while better:
        alt = min(better, key=aicc)
        reason = (f"{_name(models[alt])} fits visibly better than {_name(models[pick])}, which "
                  f"has the lowest AICc: J {models[alt].metrics['J']:.2f} against "
                  f"{models[pick].metrics['J']:.2f}")
        pick = alt
        better = [j for j in acceptable if _visibly_better(models, pick, j)]
    return pick, reason


def quality(model) -> tuple:
    """``(level, why)`` of a recommended model: ``good`` (J <= 50, hard to tell from the
    data), ``acceptable`` (J <= 100), ``poor`` (more: the best the orders tried could do is
    still far from the points; try other orders or look at the points)."""
    J = model.metrics["J"]
    worst = (f"worst point {model.metrics['max_mag_err_db']:.2f} dB, "
             f"{model.metrics['max_phase_err_deg']:.1f} deg")
    if J <= J_EXCELLENT:
        return "good", f"J = {J:.2f} <= {J_EXCELLENT:g}; {worst}"
    if J <= J_ACCEPTABLE:
        return "acceptable", f"J = {J:.1f} <= {J_ACCEPTABLE:g}; {worst}"
    return "poor", (f"J = {J:.0f} > {J_ACCEPTABLE:g}: no order tried fits the points well; "
                    f"{worst}")


def _name(model) -> str:
    return order_name(model.structure) + (" with delay" if model.delay_fitted else "")
