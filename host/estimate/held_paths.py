"""The zero-order hold's exact equivalents of a rotor's path on a rig
(docs/effectiveness.md, "The hold"): the firmware holds each command for a loop period and
the rate is sampled, so the points the rigs give are those of the hold's equivalent of
``exp(-s tau) / (T s + 1) R(s)``, not of the path itself. Used by the effectiveness fit
(:mod:`.effectiveness`).
"""

from __future__ import annotations

import numpy as np

__all__ = ["held_paths", "REPEATED_POLE_SPLIT"]

#: A critically damped hinge's double pole is split by this much (1/s, relative to its
#: damping) so that the hold's partial fractions stay distinct: far below any line.
REPEATED_POLE_SPLIT = 1e-7


def held_paths(omega_rad_s, hold_s: float, t, tau, damping, stiffness) -> tuple:
    """``(A, B)``: the zero-order hold's exact equivalents, sampled every ``hold_s`` at
    ``omega_rad_s``, of a rotor's path per unit of ``E``, ``exp(-s tau) / (T s + 1) R(s)``
    with ``R(s) = s / (s^2 + damping s + stiffness)``, and per unit of ``M`` (``s`` times
    it). Arguments broadcast together.

    The hold's equivalent of ``H`` is ``(1 - 1/z) Z{y(k h)}``, ``y`` the delayed step
    response of ``H``. ``H / s = N(s) / (T (s - q1) (s - q2) (s - q3))`` (``N`` = 1 or ``s``;
    ``q1``, ``q2`` the hinge's poles, ``q3 = -1/T``) in partial fractions, each term
    ``c e^{p t}`` sampled in closed form with the delay split into whole samples and a
    fraction; a rig with neither damping nor stiffness has a double pole at the origin, whose
    ``c t`` term is sampled the same way."""
    z = np.exp(1j * np.asarray(omega_rad_s, dtype=float) * hold_s)
    t, tau = np.asarray(t, dtype=float), np.asarray(tau, dtype=float)
    damping, stiffness = np.asarray(damping, dtype=float), np.asarray(stiffness, dtype=float)
    whole = np.floor(tau / hold_s)
    frac = tau - whole * hold_s
    double = (damping == 0) & (stiffness == 0)
    root = np.sqrt(damping ** 2 - 4 * stiffness + 0j)
    root = np.where(root == 0, REPEATED_POLE_SPLIT * np.maximum(damping, 1.0), root)
    q1, q2, q3 = (-damping + root) / 2, np.where(double, -1.0, (-damping - root) / 2), -1.0 / t
    q1 = np.where(double, 1.0, q1)
    back = 1 / z

    def sampled(p, c):                       # sum_{j >= 1} c e^{p (j h - frac)} z^-j
        step = np.exp(p * hold_s) * back
        return c * np.exp(-p * frac) * step / (1 - step)

    out = []
    for num in (np.ones_like, lambda s: s):
        distinct = sum(sampled(p, num(p) / (t * (p - a) * (p - b)))
                       for p, a, b in ((q1, q2, q3), (q2, q1, q3), (q3, q1, q2)))
        c3 = num(q3) / (t * q3 ** 2)
        c2 = num(np.zeros_like(q3)) / (-t * q3)
        ramp = c2 * (hold_s * back / (1 - back) ** 2 - frac * back / (1 - back))
        at_origin = ramp + sampled(np.zeros_like(q3), -c3) + sampled(q3, c3)
        out.append(z ** -whole * (1 - back) * np.where(double, at_origin, distinct))
    return tuple(out)
