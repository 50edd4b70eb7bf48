"""The axis command the firmware computes through a predicted step (``heliquad tune``): the
discrete cascade's step response (:func:`.loops.discrete_cascade`) run back through the
firmware's PIDs (its Tustin recurrences, :func:`heliquad.sim.plant.pid_model.pid_z_coeffs`),
so the peak |command| of a design is known before it flies (the firmware clamps the rate
PID's output, the axis command, to its ``output_max``)."""

from __future__ import annotations

import numpy as np

from ...sim.plant.pid_model import pid_z_coeffs
from ..records.gains import DERIVATIVE_FILTER_N
from . import loops as L

__all__ = ["step_traces", "step_command_peak", "STEP_DURATION_S", "SEARCH_STEP_S"]

#: How long a step is followed, s (the integral's slow tail included).
STEP_DURATION_S = 30.0
#: How long the design's search follows a step for its peak command, s: the command peaks
#: in the first moments (the proportional terms' kick); the design's result is followed
#: for STEP_DURATION_S.
SEARCH_STEP_S = 5.0


def _filtered(coeffs, x):
    # scipy.signal (0.3 s) only when a step is run: the commands import this module
    from scipy.signal import lfilter

    num, den = coeffs
    return lfilter(num, den, x)


def step_traces(num, den, delay_s, gains, axis, size, duration_s=STEP_DURATION_S,
                imu_path=None):
    """A step of ``size`` (rad of angle for roll and pitch with an angle loop, else rad/s of
    rate) through the firmware's loops around the model: ``(t, response, command)``, the
    response in the step's quantity and the axis command (the rate PID's output,
    ``C_PI (r - y) + D_m y``) before the firmware's clamp. ``imu_path``: how the logged
    angle follows the rate (:func:`heliquad.host.validate.loops.angle_over_rate`)."""
    # python-control (1 s) only when a loop is simulated: the commands import this module
    import control

    outer = axis != "yaw" and gains.angle is not None
    dt = L.LOOP_DT_S
    cascade = L.discrete_cascade(num, den, delay_s, gains, dt, outer=outer, imu_path=imu_path)
    t = np.arange(0.0, duration_s, dt)
    ref = np.full(t.size, float(size))
    out = np.atleast_2d(control.forced_response(cascade, t, np.vstack([ref, 0 * ref])).outputs)
    rate = out[0]
    c_pi, d_m = pid_z_coeffs(*gains.rate, DERIVATIVE_FILTER_N, dt)
    rate_sp = ref
    if outer:
        k_o, d_o = pid_z_coeffs(gains.angle[0], 0.0, gains.angle[1], DERIVATIVE_FILTER_N, dt)
        rate_sp = _filtered(k_o, ref - out[1]) + _filtered(d_o, out[1])
    command = _filtered(c_pi, rate_sp - rate) + _filtered(d_m, rate)
    return t, out[1] if outer else rate, command


def step_command_peak(num, den, delay_s, gains, axis, size,
                      duration_s=STEP_DURATION_S, imu_path=None) -> float:
    """The peak |axis command| of :func:`step_traces`."""
    return float(np.max(np.abs(step_traces(num, den, delay_s, gains, axis, size,
                                           duration_s, imu_path)[2])))
