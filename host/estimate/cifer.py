"""CIFER's cost J, the one number rotorcraft identification compares models by.

(Tischler and Remple, *Aircraft and Rotorcraft System Identification*, 2nd ed., 2012,
ch. 11.) For a model's response ``G_k`` against points ``F_k`` (n of them):

    J = 20/n sum_k W_gamma,k [ (20 log10 |G_k / F_k|)^2 + 0.01745 (angle(G_k / F_k) in deg)^2 ]

with the coherence weight ``W_gamma = [1.58 (1 - exp(-gamma^2))]^2``. The phase error is the
principal angle of ``G/F`` (within +/-180 deg). Here once, for the metric
(:func:`heliquad.host.estimate.metrics.evaluate_model`) and for the fit's stage that
minimises it (:mod:`heliquad.host.estimate.fit`), so both are the same J.
"""

from __future__ import annotations

import numpy as np

__all__ = ["J_PHASE_WEIGHT", "J_SCALE", "cifer_weight", "j_errors"]

#: Phase weight in J: 0.01745 dB^2 per deg^2 (1 dB of magnitude ~ 7.57 deg of phase).
J_PHASE_WEIGHT = 0.01745
#: J's factor over the mean: 20 / n times the weighted sum.
J_SCALE = 20.0


def cifer_weight(coherence) -> np.ndarray:
    """CIFER coherence weight ``[1.58 (1 - exp(-gamma^2))]^2``; NaN coherence counts as 1."""
    gamma2 = np.nan_to_num(np.asarray(coherence, dtype=float), nan=1.0)
    return (1.58 * (1.0 - np.exp(-gamma2))) ** 2


def j_errors(G, F) -> tuple:
    """``(dB error, deg error)`` of the model's response ``G`` at the points ``F``: the
    magnitude and principal phase of ``G / F``."""
    ratio = np.asarray(G, dtype=complex) / np.asarray(F, dtype=complex)
    with np.errstate(divide="ignore"):          # G = 0 at a point: an infinite error in dB
        mag_err_db = 20.0 * np.log10(np.abs(ratio))
    return mag_err_db, np.degrees(np.angle(ratio))
