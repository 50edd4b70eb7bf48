"""The report's checks of the points and the recommended model, a line each: how the points
were estimated, the model's replay of the measured records and, for a simulated sweep, how
far both are from the simulator's truth, with the points' error/sigma statistic and what it
means."""

from __future__ import annotations

import html

import numpy as np

from ..estimate.thresholds import ACCURACY_DB, ACCURACY_DEG, ROUND_OFF_SIGMA, honest_sigma_bound
from ..records.points import known_column
from .report_html import number_text
from .report_models import order_text
from .report_points import beyond_accuracy

#: models.json's ``estimate``, in words.
ESTIMATES = {"excitation": "Points estimated against the logged excitation r: G = (Y/R) / (U/R), "
                           "unbiased with the loop closed.",
             "input": "Points estimated against the measured input u (the direct estimate, "
                      "right for open-loop data; biased when the loop is closed and the air moves)."}


def checks_html(models, points=None):
    """How the points were estimated (``points``: points.csv's, or None), the recommended model's replay and, for a simulated
    sweep, how far the points and the model are from the simulator's truth, with the
    points' error/sigma statistic (:func:`_sigma_text`)."""
    said = []
    if models.estimate:
        said.append(ESTIMATES[models.estimate])
    replay = models.replay
    if models.recommended is None:
        said.append("No model is recommended, so none is replayed.")
    elif replay:
        errors = [100 * p["nrmse"] for p in replay["points"] if p.get("nrmse") is not None]
        said.append(f"Replay: each frequency's measured input (its mean period after "
                    f"{replay.get('discard_periods', 1)} discarded) through the recommended model "
                    f"({order_text(models.models[models.recommended])}), its periodic steady "
                    f"state against the measured output (dashed in the responses): error "
                    + (f"{min(errors):.2g} to {max(errors):.2g} % of the output's RMS "
                       "(per frequency in the table above)." if errors else "not known."))
    truth = models.sil_truth
    if truth:
        text = (f"Against the simulator's truth: the points within {truth['points_worst_db']:.2f} dB "
                f"and {truth['points_worst_deg']:.1f} deg")
        if truth.get("model_worst_db") is not None and models.recommended is not None:
            text += (f"; the recommended model within {truth['model_worst_db']:.2f} dB and "
                     f"{number_text(truth.get('model_worst_deg'), '.1f')} deg across the band")
        said.append(text + f" (the report's accuracy: {ACCURACY_DB:g} dB and {ACCURACY_DEG:g} "
                    "deg, an error that would change a controller designed on the model).")
        said.append(_sigma_text(truth, points))
    return "".join(f"<p>{html.escape(t)}</p>" for t in said if t)


def _sigma_text(truth, points) -> str:
    """The points' RMS error/sigma against the truth, as a statistic with what it says: how
    many of their own standard errors the points lie from the truth (about 1 when each
    point's sigma accounts for its whole error). Not read at all when the sigmas are
    round-off (:data:`ROUND_OFF_SIGMA`)."""
    z = truth.get("points_rms_error_over_sigma")
    if z is None:
        return ""
    text = (f"RMS error/sigma of the points: {z:.2f}, how many of their own standard errors "
            "(sigma, from the scatter between periods) the points lie from the truth: ")
    relative = None
    sigma = known_column(points, "sigma") if points else None
    if sigma is not None:
        with np.errstate(all="ignore"):
            ratio = sigma / np.abs(known_column(points, "gain"))
        relative = float(np.median(ratio[np.isfinite(ratio)])) if np.any(np.isfinite(ratio)) \
            else None
    if relative is not None and relative < ROUND_OFF_SIGMA:
        return text + (f"not meaningful here, as the sigmas are round-off ({relative:.1g} of the "
                       "magnitude: a noise-free simulation has no scatter to measure).")
    n = len(sigma) if sigma is not None else 1
    if z <= honest_sigma_bound(n):
        return text + "about 1, as it should be: sigma accounts for each point's error."
    return text + (f"above 1, so the points carry a bias their scatter does not show (at most "
                   f"{truth['points_worst_db']:.2f} dB and {truth['points_worst_deg']:.1f} deg"
                   + (", within the accuracy" if not beyond_accuracy(
                       truth["points_worst_db"], truth["points_worst_deg"]) else "")
                   + "): weights and confidence bounds built on sigma are that much too "
                   "confident; the model is judged against the accuracy, not against sigma.")
