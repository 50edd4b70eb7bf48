"""The firmware's PID (firmware/core/pid.cpp, the one that flies) as transfer functions.

:func:`pid_form` reads its gains once, the firmware's way: Kc, the integral time (none for
tau_I <= 0), the derivative time and its filter's tau_f = tau_D / N (none for tau_D <= 0).
From that come both forms the Python side uses:

* :func:`pid_z_coeffs` (and :func:`pid_z`): what the firmware computes at the loop period,
  its Tustin recurrences written in z: ``C_PI`` on the error (P and the trapezoidal
  integral) and ``D_m`` on the measurement (the filtered derivative), so that
  ``output = C_PI (r - y) + D_m y``. The simulator's closed-loop truth and the validation's
  discrete cascade use it.
* :func:`pid_s_coeffs`: the continuous PID the firmware approximates, on the error as the
  paper writes it, ``Kc (1 + 1/(tau_I s) + tau_D s / (tau_f s + 1))``.

tests/pid_test.py checks both against the firmware's Pid through its bindings (the steady
sine response and the step response in z, the response to a sine in s).
"""

from __future__ import annotations

import dataclasses

import numpy as np

__all__ = ["PidForm", "pid_form", "pid_z_coeffs", "pid_z", "pid_s_coeffs"]


@dataclasses.dataclass(frozen=True)
class PidForm:
    """The terms of a PID: Kc; tau_I, s (None: no integral); tau_D and the derivative
    filter's time constant tau_f, s (None: no derivative)."""

    kc: float
    tau_i_s: float | None
    tau_d_s: float | None
    tau_f_s: float | None


def pid_form(kc, tau_i_s, tau_d_s, derivative_filter_n) -> PidForm:
    """The terms the firmware's Pid has with these gains (module docstring)."""
    derivative = tau_d_s > 0
    return PidForm(kc, tau_i_s if tau_i_s > 0 else None, tau_d_s if derivative else None,
                   tau_d_s / derivative_filter_n if derivative else None)


def pid_z_coeffs(kc, tau_i_s, tau_d_s, derivative_filter_n, dt_s):
    """The firmware's Pid at the period ``dt_s`` as ``(C_PI, D_m)``, each ``(num, den)`` in
    descending powers of ``z`` (module docstring)."""
    form = pid_form(kc, tau_i_s, tau_d_s, derivative_filter_n)
    if form.tau_i_s is not None:
        ki = kc * dt_s / (2 * form.tau_i_s)       # kc + ki (z + 1) / (z - 1)
        c_pi = ([kc + ki, ki - kc], [1.0, -1.0])
    else:
        c_pi = ([kc], [1.0])
    d_m = ([0.0], [1.0])
    if form.tau_d_s is not None:
        tf = form.tau_f_s
        a = (2 * tf - dt_s) / (2 * tf + dt_s)
        b = 2 * kc * form.tau_d_s / (2 * tf + dt_s)
        d_m = ([-b, b], [1.0, -a])                # -b (z - 1) / (z - a)
    return c_pi, d_m


def pid_z(gains, dt_s, z):
    """:func:`pid_z_coeffs` of the firmware's ``gains`` (a ``PidGains``) evaluated at the
    points ``z``: ``(C_PI(z), D_m(z))``."""
    (pn, pd), (dn, dd) = pid_z_coeffs(gains.kc, gains.tau_i_s, gains.tau_d_s,
                                      gains.derivative_filter_n, dt_s)
    return np.polyval(pn, z) / np.polyval(pd, z), np.polyval(dn, z) / np.polyval(dd, z)


def pid_s_coeffs(kc, tau_i_s, tau_d_s, derivative_filter_n):
    """The continuous PID on the error, ``(num, den)`` in descending powers of ``s``
    (module docstring)."""
    form = pid_form(kc, tau_i_s, tau_d_s, derivative_filter_n)
    num, den = np.array([float(kc)]), np.array([1.0])
    if form.tau_i_s is not None:                  # Kc (tau_I s + 1) / (tau_I s)
        num, den = kc * np.array([form.tau_i_s, 1.0]), np.array([form.tau_i_s, 0.0])
    if form.tau_d_s is not None:                  # + Kc tau_D s / (tau_f s + 1)
        d_num, d_den = np.array([kc * form.tau_d_s, 0.0]), np.array([form.tau_f_s, 1.0])
        num = np.polyadd(np.polymul(num, d_den), np.polymul(d_num, den))
        den = np.polymul(den, d_den)
    return num, den
