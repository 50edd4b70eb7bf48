"""Per-axis transfer-function plant: normalised torque command in, body rate out.

``G(s) = num/den`` maps the axis's torque command (the mixer's normalised -1..1 input, as the
motors actually produce it) to the body rate in rad/s about that axis. It is discretised
with a zero-order hold at the loop period (:func:`zoh`: the controller canonical form of
:func:`tf2ss` and the matrix exponential, as python-control's ``sample_system`` and
``scipy.signal.cont2discrete`` compute it, to the bit), because the motors hold each command
for one loop. The axis's angle is the integral of the rate.

Known delay, for checking identification against it: the firmware computes the command from
the sample at ``t_k`` and the plant holds it over ``[t_k, t_k+1)``, so the logged (u_k, y_k)
pairs follow the ZOH discretisation ``H(z)`` exactly; to first order
``H(e^{j w T}) = G(j w) e^{-j w T / 2} sinc(w T / 2)``. :meth:`TfPlant.truth` gives it.
"""

from __future__ import annotations

import numpy as np

from heliquad import _simcore

from ..base.dialect import AXES

__all__ = ["TfPlant", "tf2ss", "zoh"]


def tf2ss(num, den):
    """``(A, B, C, D)`` of ``num/den`` (descending powers of s, proper) in controller canonical
    form, the realisation scipy.signal.tf2ss and python-control give (here so that a run
    need not import either: python-control takes about a second to import)."""
    den = np.trim_zeros(np.atleast_1d(np.asarray(den, dtype=float)), "f")
    num = np.atleast_1d(np.asarray(num, dtype=float)) / den[0]
    den = den / den[0]
    lead = 0
    while lead < num.size - 1 and abs(num[lead]) <= 1e-14:
        lead += 1
    num = num[lead:]
    if num.size > den.size:
        raise ValueError("improper transfer function: the numerator is longer than the "
                         "denominator")
    num = np.concatenate([np.zeros(den.size - num.size), num])
    k = den.size
    if k == 1:
        return np.zeros((1, 1)), np.zeros((1, 1)), np.zeros((1, 1)), num.reshape(1, 1)
    A = np.vstack([-den[1:][None, :], np.eye(k - 2, k - 1)])
    B = np.eye(k - 1, 1)
    C = (num[1:] - num[0] * den[1:])[None, :]
    return A, B, C, np.array([[num[0]]])


def zoh(A, B, dt_s: float):
    """``(A_d, B_d)``: the state-space system sampled with a zero-order hold over ``dt_s``
    (the exponential of ``[[A, B], [0, 0]] dt``)."""
    # scipy.linalg (0.2 s) only for the transfer-function plant: every sil run imports this
    import scipy.linalg

    n, m = A.shape[0], B.shape[1]
    em = np.zeros((n + m, n + m))
    em[:n, :n], em[:n, n:] = A, B
    ms = scipy.linalg.expm(dt_s * em)[:n, :]
    return ms[:, :n], ms[:, n:]


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
        self.index = AXES[axis]
        self.dt_s = dt_s
        A, B, self._C, self._D = tf2ss(list(map(float, num)), list(map(float, den)))
        self._Ad, self._Bd = zoh(A, B, dt_s)
        # The per-frame arithmetic runs in C++ (sim/plant/tf_axis.cpp), the same code the
        # lockstep engine steps.
        self.core = _simcore.TfAxis(self._Ad.ravel().tolist(), self._Bd.ravel().tolist(),
                                    self._C.ravel().tolist(), dt_s, self.index)

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
        # H(z) as a ratio of polynomials (scipy.signal.ss2tf's arithmetic, as python-control
        # samples a transfer function).
        den = np.poly(self._Ad)
        num = np.poly(self._Ad - self._Bd @ self._C) + (self._D[0, 0] - 1) * den
        z = np.exp(1j * np.asarray(omega_rad_s) * self.dt_s)
        return np.polyval(num, z) / np.polyval(den, z)
