"""The rotor geometry that best explains a measured control effectiveness.

Each rotor's moment per unit of thrust command at steady state is
``B_i = T_max,i (r_i x d_i - kappa_i spin_i d_i)`` (docs/vehicle-model.md: the thrust's arm and
the drag torque), and the rigs measure ``E = B / I`` row by row
(host/estimate/effectiveness.py). Three numbers per rotor cannot give its place (3), axis (2),
largest thrust and torque ratio, so :func:`fit_rotor_geometry` fits the parameterisation
docs/effectiveness.md justifies: the places, spins and inertia as built (a ruler and the
vehicle file know them), the arm rotors canted by one angle about their arms (the firmware's
layout: ``d_i = -cos(delta) z - spin_0 sin(delta) t_i``, ``t_i`` the tangent at the arm's
azimuth), one torque ratio for the arm rotors and one for the central rotor, whose largest
thrust the moments cannot show (it sits on the axis; no rig measures the vertical force) and
is taken as given; and each arm rotor's largest thrust. Weighted by the effectiveness's
covariance (its entries' errors are correlated), with the parameters' sigmas from the fit's
covariance.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import scipy.optimize

from ...sim.base.errors import InputError

__all__ = ["RotorGeometryFit", "fit_rotor_geometry", "canted_axes"]

#: The covariance's eigenvalues are floored at this fraction of the largest before it is
#: inverted (entries fitted to round-off, such as a rotor's zero on a rig, make it singular).
EIGENVALUE_FLOOR = 1e-12


@dataclasses.dataclass(frozen=True)
class RotorGeometryFit:
    """The fitted geometry: the cant (deg), the torque ratios (m) of the arm rotors and of the
    central one, each rotor's largest thrust (N; the central one as given, its sigma NaN),
    each with its sigma; the thrust axes (rotors x 3, body FRD); the effectiveness the
    geometry predicts (3 x rotors, rad/s^2); and the weighted residuals' chi-square per
    degree of freedom."""

    cant_deg: float
    cant_sigma_deg: float
    arm_torque_ratio_m: float
    arm_torque_ratio_sigma_m: float
    central_torque_ratio_m: float
    central_torque_ratio_sigma_m: float
    max_thrust_n: np.ndarray
    max_thrust_sigma_n: np.ndarray
    thrust_axes: np.ndarray
    predicted_rad_s2: np.ndarray
    chi2_dof: float


def canted_axes(positions_m, cant_rad: float, central_spin: int) -> np.ndarray:
    """Thrust axes of a central rotor (the first, along -z) and arm rotors canted by
    ``cant_rad`` about their arms against the central rotor's reaction torque."""
    pos = np.asarray(positions_m, dtype=float)
    psi = np.arctan2(pos[:, 1], pos[:, 0])
    tangent = np.column_stack([-np.sin(psi), np.cos(psi), np.zeros(psi.size)])
    axes = (-math.cos(cant_rad) * np.array([0.0, 0.0, 1.0])
            - central_spin * math.sin(cant_rad) * tangent)
    axes[0] = (0.0, 0.0, -1.0)
    return axes


def _effectiveness(x, pos, spins, inertia, central_max_thrust_n):
    """``E`` (3 x rotors) of the parameters ``x``: cant, arm and central torque ratios, arm
    rotors' largest thrusts."""
    axes = canted_axes(pos, x[0], int(spins[0]))
    thrust = np.concatenate([[central_max_thrust_n], x[3:]])
    ratio = np.concatenate([[x[2]], np.full(len(spins) - 1, x[1])])
    moment = thrust[:, None] * (np.cross(pos, axes) - (ratio * spins)[:, None] * axes)
    return moment.T / inertia[:, None], axes


def _whitener(covariance, used) -> np.ndarray:
    """``W`` with ``W^T W`` the inverse of the used entries' covariance (its eigenvalues
    floored, ``EIGENVALUE_FLOOR``)."""
    cov = np.asarray(covariance, dtype=float)[np.ix_(used.ravel(), used.ravel())]
    values, vectors = np.linalg.eigh(cov)
    values = np.maximum(values, EIGENVALUE_FLOOR * values.max())
    return (vectors / np.sqrt(values)).T


def fit_rotor_geometry(effectiveness, covariance, positions_m, spins, inertia_kg_m2,
                       central_max_thrust_n: float, start) -> RotorGeometryFit:
    """The geometry (module docstring) that best explains ``effectiveness`` (3 x rotors,
    rad/s^2; NaN rows: not measured) with its ``covariance`` (of ``effectiveness.ravel()``,
    as :class:`~heliquad.host.estimate.effectiveness.EffectivenessEstimate` has it), for
    rotors at ``positions_m`` spinning ``spins`` (rotor 1 the central one) on a body of
    ``inertia_kg_m2`` (the rig's about each axis). ``start``: (cant deg, arm torque ratio m,
    central torque ratio m, arm rotors' largest thrust N), where the fit begins."""
    e = np.asarray(effectiveness, dtype=float)
    cov = np.asarray(covariance, dtype=float)
    pos, spins = np.asarray(positions_m, dtype=float), np.asarray(spins, dtype=float)
    inertia = np.asarray(inertia_kg_m2, dtype=float)
    if e.shape != (3, len(spins)) or cov.shape != (e.size,) * 2 or pos.shape != (len(spins), 3):
        raise InputError("the effectiveness, its covariance and the rotors' places disagree "
                         "on how many rotors there are")
    used = np.isfinite(e) & np.isfinite(np.diag(cov)).reshape(e.shape)
    x0 = np.concatenate([[math.radians(start[0]), start[1], start[2]],
                         np.full(len(spins) - 1, float(start[3]))])
    if np.count_nonzero(used) <= x0.size:
        raise InputError(f"{np.count_nonzero(used)} measured entries cannot fit the "
                         f"geometry's {x0.size} parameters")

    whiten = _whitener(cov, used)

    def residuals(x):
        return whiten @ (_effectiveness(x, pos, spins, inertia, central_max_thrust_n)[0]
                         - e)[used]

    sol = scipy.optimize.least_squares(residuals, x0, x_scale=np.abs(x0) + 1e-3)
    cov = np.linalg.pinv(sol.jac.T @ sol.jac)
    psd = np.sqrt(np.diag(cov))
    predicted, axes = _effectiveness(sol.x, pos, spins, inertia, central_max_thrust_n)
    return RotorGeometryFit(
        cant_deg=math.degrees(sol.x[0]), cant_sigma_deg=math.degrees(psd[0]),
        arm_torque_ratio_m=float(sol.x[1]), arm_torque_ratio_sigma_m=float(psd[1]),
        central_torque_ratio_m=float(sol.x[2]), central_torque_ratio_sigma_m=float(psd[2]),
        max_thrust_n=np.concatenate([[central_max_thrust_n], sol.x[3:]]),
        max_thrust_sigma_n=np.concatenate([[np.nan], psd[3:]]), thrust_axes=axes,
        predicted_rad_s2=predicted,
        chi2_dof=float(np.sum(sol.fun ** 2) / (sol.fun.size - sol.x.size)))
