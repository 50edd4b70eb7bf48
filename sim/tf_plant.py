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

import numpy as np

from heliquad import _simcore

from .dialect import AXES

__all__ = ["TfPlant"]


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
        import control          # here, not at the top: a command refused earlier never loads it

        if axis not in AXES:
            raise ValueError(f"axis must be one of {', '.join(AXES)}")
        self.axis = axis
        self.index = AXES[axis]
        self.dt_s = dt_s
        self.G = control.tf(list(map(float, num)), list(map(float, den)))
        sys_d = control.sample_system(control.ss(self.G), dt_s, method="zoh")
        # The per-frame arithmetic runs in C++ (sim/native/tf_axis.cpp), the same code the
        # lockstep engine steps.
        self.core = _simcore.TfAxis(np.asarray(sys_d.A, dtype=float).ravel().tolist(),
                                    np.asarray(sys_d.B, dtype=float).ravel().tolist(),
                                    np.asarray(sys_d.C, dtype=float).ravel().tolist(),
                                    dt_s, self.index)

    @property
    def rate_rad_s(self) -> float:
        return self.core.rate_rad_s

    @property
    def angle_rad(self) -> float:
        return self.core.angle_rad

    def step_motors(self, motor) -> float:
        """Drive the plant with the motors' thrust fractions: the axis's torque command is what
        the firmware's mixer equations (default geometry, as the firmware flies) say these
        thrusts produce (``Mixer.achieved``)."""
        self.core.step_motors(list(map(float, motor)))
        return self.core.rate_rad_s

    def step(self, u: float) -> float:
        """Hold ``u`` for one period; returns the rate at the end of it (the angle is the
        trapezoid integral of the rate)."""
        return self.core.step_command(float(u))

    def body_state(self):
        """(quaternion w x y z, body rates FRD) of the vehicle on its one-axis rig."""
        return list(self.core.quaternion), list(self.core.rates)

    def sensor_sample(self):
        """(quaternion, body rates, specific force) as the IMU reports them: ideal here, the
        rig held still (gravity only)."""
        return self.core.sensor()

    def fifo(self, kind: int) -> bytes:
        """This frame's FIFO bytes of the HQ_SENSOR_KIND ``kind``."""
        return self.core.fifo(kind)

    def frame_inputs(self, frames: int):
        """Random inputs of the next ``frames`` frames: none for this plant."""
        return None, None

    def truth(self, omega_rad_s, inject: str = "mixer"):
        """The sampled-data response from logged command to logged rate (ZOH at dt): what
        mixer injection identifies (this plant has no model of the closed loops)."""
        if inject != "mixer":
            raise ValueError("a transfer-function plant's truth is for mixer injection only")
        import control

        z = np.exp(1j * np.asarray(omega_rad_s) * self.dt_s)
        Hd = control.sample_system(self.G, self.dt_s, method="zoh")
        num, den = np.asarray(Hd.num[0][0]), np.asarray(Hd.den[0][0])
        return np.polyval(num, z) / np.polyval(den, z)
