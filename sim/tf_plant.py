"""Per-axis transfer-function plant: normalised torque command in, body rate out.

``G(s) = num/den`` maps the axis's torque command (the mixer's normalised -1..1 input, as the
motors actually produce it) to the body rate in rad/s about that axis. It is discretised
with a zero-order hold at the loop period (python-control ``sample_system``), because the
motors hold each command for one loop. The axis's angle is the integral of the rate.

Known delay, for checking identification against it: the firmware computes the command from
the sample at ``t_k`` and the plant holds it over ``[t_k, t_k+1)``, so the logged (u_k, y_k)
pairs follow the ZOH discretisation ``H(z)`` exactly; to first order
``H(e^{j w T}) = G(j w) e^{-j w T / 2} sinc(w T / 2)``. :meth:`TfPlant.truth` gives it.
"""

from __future__ import annotations

import math

import control
import numpy as np

__all__ = ["TfPlant"]

AXES = ("roll", "pitch", "yaw")


class TfPlant:
    """Single-axis plant with the vehicle otherwise held level (as on a one-axis rig).

    Parameters
    ----------
    axis : str
        ``roll``, ``pitch`` or ``yaw``.
    num, den : sequence of float
        ``G(s)``, descending powers of s, torque command -> rate (rad/s).
    dt_s : float
        Loop period.
    """

    def __init__(self, axis: str, num, den, dt_s: float):
        if axis not in AXES:
            raise ValueError(f"axis must be one of {', '.join(AXES)}")
        self.axis = axis
        self.index = AXES.index(axis)
        self.dt_s = dt_s
        self.G = control.tf(list(map(float, num)), list(map(float, den)))
        sys_d = control.sample_system(control.ss(self.G), dt_s, method="zoh")
        # Plain floats: the state is a handful of numbers, and numpy's per-call overhead on
        # 2 x 2 arrays costs more than the arithmetic (this runs every loop).
        self.A = [list(map(float, row)) for row in np.asarray(sys_d.A)]
        self.B = [float(b) for b in np.asarray(sys_d.B).ravel()]
        self.C = [float(c) for c in np.asarray(sys_d.C).ravel()]
        self.x = [0.0] * len(self.B)
        self.angle_rad = 0.0
        self.rate_rad_s = 0.0

    def step_motors(self, motor, mixer) -> float:
        """Drive the plant with the motors' thrust fractions: the axis's torque command is what
        the firmware's mixer equations say these thrusts produce (``Mixer.achieved``)."""
        got = mixer.achieved(motor)
        return self.step((got.roll, got.pitch, got.yaw)[self.index])

    def step(self, u: float) -> float:
        """Hold ``u`` for one period; returns the rate at the end of it."""
        x = self.x
        self.x = [sum(a * xi for a, xi in zip(row, x)) + b * u for row, b in zip(self.A, self.B)]
        rate = sum(c * xi for c, xi in zip(self.C, self.x))   # strictly proper: no feed-through
        # angle: trapezoid of the rate over the period
        self.angle_rad += 0.5 * (self.rate_rad_s + rate) * self.dt_s
        self.rate_rad_s = rate
        return rate

    def body_state(self):
        """(quaternion w x y z, body rates FRD) of the vehicle on its one-axis rig."""
        half = 0.5 * self.angle_rad
        q = [math.cos(half), 0.0, 0.0, 0.0]
        q[1 + self.index] = math.sin(half)
        rates = [0.0, 0.0, 0.0]
        rates[self.index] = self.rate_rad_s
        return q, rates

    def sensor_sample(self):
        """(quaternion, body rates, specific force) as the IMU reports them: ideal here."""
        q, rates = self.body_state()
        return q, rates, self.specific_force()

    def specific_force(self):
        """Accelerometer reading on the rig (held still): gravity only, in body FRD."""
        (w, x, y, z), _ = self.body_state()
        g = 9.80665
        return (-g * 2 * (x * z - w * y), -g * 2 * (y * z + w * x), -g * (w * w - x * x - y * y + z * z))

    def truth(self, omega_rad_s):
        """The sampled-data response from logged command to logged rate (ZOH at dt)."""
        z = np.exp(1j * np.asarray(omega_rad_s) * self.dt_s)
        Hd = control.sample_system(self.G, self.dt_s, method="zoh")
        num, den = np.asarray(Hd.num[0][0]), np.asarray(Hd.den[0][0])
        return np.polyval(num, z) / np.polyval(den, z)
