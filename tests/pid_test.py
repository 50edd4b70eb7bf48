"""The firmware's PID (firmware/core/pid.cpp), driven through the bindings.

Modelled on PX4's PID test: zero case, limits, P convergence on a toy plant, integral ramp
up and down, anti-windup; plus agreement with the host's two models of it: the continuous one
of the closed-loop validation and the z-domain one of the simulator's truth.
"""

import math

import control
import numpy as np
import pytest

from heliquad import _firmware as fw
from heliquad.host.validate.closed_loop import pid_tf
from heliquad.sim.base.firmware_facts import LOOP_PERIOD_S
from heliquad.sim.plant.pid_model import pid_s_coeffs, pid_z, pid_z_coeffs

DT = LOOP_PERIOD_S   # the firmware's loop period (5 ms: 200 Hz)


def gains(kc=1.0, tau_i=0.0, tau_d=0.0, lo=-1.0, hi=1.0, i_limit=1.0, n=10.0):
    g = fw.PidGains()
    g.kc, g.tau_i_s, g.tau_d_s = kc, tau_i, tau_d
    g.output_min, g.output_max, g.integral_limit, g.derivative_filter_n = lo, hi, i_limit, n
    return g


def test_zero_error_gives_zero_output():
    pid = fw.Pid(gains(2.422, 0.439, 0.051))
    for _ in range(100):
        assert pid.update(0.3, 0.3, DT) == 0.0
    assert pid.p_term == pid.i_term == pid.d_term == 0.0


def test_output_limits():
    pid = fw.Pid(gains(kc=10.0, lo=-0.5, hi=0.8))
    assert pid.update(1.0, 0.0, DT) == pytest.approx(0.8)
    assert pid.saturated
    assert pid.update(-1.0, 0.0, DT) == pytest.approx(-0.5)


def test_p_controller_converges_on_a_first_order_plant():
    # Plant x' = -x + u; P control with Kc = 4 settles at Kc/(1 + Kc) of the setpoint.
    pid = fw.Pid(gains(kc=4.0, lo=-10, hi=10))
    x = 0.0
    for _ in range(2000):
        u = pid.update(1.0, x, DT)
        x += DT * (-x + u)
    assert x == pytest.approx(4.0 / 5.0, rel=1e-3)


def test_pi_controller_removes_the_steady_state_error():
    pid = fw.Pid(gains(kc=4.0, tau_i=0.5, lo=-10, hi=10, i_limit=10))
    x = 0.0
    for _ in range(4000):
        u = pid.update(1.0, x, DT)
        x += DT * (-x + u)
    assert x == pytest.approx(1.0, abs=1e-4)


def test_integral_ramps_up_and_down_at_kc_over_tau_i():
    pid = fw.Pid(gains(kc=2.0, tau_i=0.5, lo=-100, hi=100, i_limit=100))
    for _ in range(200):                      # 1 s of error +0.1
        pid.update(0.1, 0.0, DT)
    # I = Kc/tau_I * integral(e) = 4 * 0.1 * 1 s (the first trapezoid uses e twice).
    assert pid.i_term == pytest.approx(0.4, rel=1e-5)
    for _ in range(200):                      # 1 s of error -0.1 brings it back ...
        pid.update(-0.1, 0.0, DT)
    # ... less one step: the trapezoid of the step where e flips averages +0.1 and -0.1 to 0.
    assert pid.i_term == pytest.approx(4 * 0.1 * DT, rel=1e-4)


def test_anti_windup_holds_the_integral_while_saturated():
    pid = fw.Pid(gains(kc=1.0, tau_i=0.1, lo=-1.0, hi=1.0, i_limit=5.0))
    for _ in range(2000):                     # 10 s against a saturated output
        pid.update(2.0, 0.0, DT)
    assert pid.saturated
    assert pid.i_term < 0.1                   # no wind-up: P alone saturates
    # When the error reverses, the output leaves saturation at once.
    assert pid.update(-0.5, 0.0, DT) < 0.0


def test_integral_limit():
    pid = fw.Pid(gains(kc=1.0, tau_i=0.1, lo=-100, hi=100, i_limit=0.3))
    for _ in range(2000):
        pid.update(0.2, 0.0, DT)
    assert pid.i_term == pytest.approx(0.3)


def test_no_derivative_kick_on_a_setpoint_step():
    pid = fw.Pid(gains(kc=1.0, tau_d=0.05, lo=-100, hi=100))
    pid.update(0.0, 0.0, DT)
    pid.update(1.0, 0.0, DT)                  # setpoint step, measurement unchanged
    assert pid.d_term == 0.0


def flown_rate_gains(axis=fw.Axis.ROLL):
    """The firmware's own rate-loop gains of an axis, with limits too wide to act."""
    g = fw.CascadeGains.paper_defaults().rate(axis)
    g.output_min, g.output_max, g.integral_limit = -1e6, 1e6, 1e6
    return g


def test_matches_the_hosts_continuous_pid():
    # The firmware's roll rate loop. With setpoint 0 and measurement -e(t), the firmware PID is
    # the host's continuous model (host/validate/closed_loop.py, pid_tf: Kc (1 + 1/(tau_I s) +
    # tau_D s / (tau_D/N s + 1)), N its derivative filter) applied to e. The reference is
    # python-control's response on a 20x finer grid. Tustin's error is O((w dt)^2): at 2 Hz
    # and 200 Hz it is ~1e-3 of the output, so 1 % of the output's amplitude is the bound,
    # after the first 0.1 s: the derivative filter (tau_f = 5 ms, about one sample) starts
    # differently from the continuous one and needs ~20 tau_f to forget it.
    g = flown_rate_gains()
    C = pid_tf(g.kc, g.tau_i_s, g.tau_d_s)
    f_hz, duration = 2.0, 3.0
    fine = np.arange(0, duration, DT / 20)
    ref = control.forced_response(C, fine, np.sin(2 * math.pi * f_hz * fine)).outputs[::20]
    pid = fw.Pid(g)
    t = np.arange(ref.size) * DT
    out = np.array([pid.update(0.0, -math.sin(2 * math.pi * f_hz * tk), DT) for tk in t])
    settled = t >= 0.1
    assert np.max(np.abs(out - ref)[settled]) < 0.01 * np.max(np.abs(ref))


def steady_gain(pid, on_setpoint, f_hz, periods=40):
    """The complex gain of the firmware Pid from a sine on the setpoint (or the measurement)
    to its output, fitted over the last half of ``periods`` whole periods (with an offset:
    the integral holds one)."""
    n = int(round(1 / (f_hz * DT)))
    k = np.arange(periods * n)
    x = np.sin(2 * math.pi * k / n)
    out = np.array([pid.update(v, 0.0, DT) if on_setpoint else pid.update(0.0, v, DT) for v in x])
    last = k >= periods * n // 2
    basis = np.column_stack([np.sin(2 * math.pi * k / n), np.cos(2 * math.pi * k / n),
                             np.ones(k.size)])[last]
    a, b, _ = np.linalg.lstsq(basis, out[last], rcond=None)[0]
    return complex(a, b), 2 * math.pi / (n * DT)


@pytest.mark.parametrize("f_hz", [0.5, 4.0, 20.0])
def test_the_simulators_z_domain_pid_is_the_firmwares(f_hz):
    # sim/plant/pid_model.py states the firmware's Pid in z for the closed loops' truth: output
    # = C_PI (r - y) + D_m y. The firmware's own steady state must be exactly that.
    g = flown_rate_gains()
    on_error, w = steady_gain(fw.Pid(g), True, f_hz)
    on_measurement, _ = steady_gain(fw.Pid(g), False, f_hz)
    c_pi, d_m = pid_z(g, DT, np.exp(1j * w * DT))
    assert on_error == pytest.approx(c_pi, rel=1e-5)
    assert on_measurement == pytest.approx(d_m - c_pi, rel=1e-5)


@pytest.mark.parametrize("axis", [fw.Axis.ROLL, fw.Axis.YAW])
@pytest.mark.parametrize("on_setpoint", [True, False])
def test_the_z_domain_pid_steps_as_the_firmwares(axis, on_setpoint):
    # The same statement in z sample by sample: a unit step on the setpoint (or the
    # measurement) from the second update on (the first is the firmware's start, which
    # takes its one sample as the history), through C_PI on the error and D_m on the
    # measurement, is the firmware's output to single precision, integral ramp included.
    from scipy.signal import lfilter

    g = flown_rate_gains(axis)
    step = (np.arange(400) >= 1).astype(float)
    pid = fw.Pid(g)
    out = np.array([pid.update(x, 0.0, DT) if on_setpoint else pid.update(0.0, x, DT)
                    for x in step])
    (pn, pd), (dn, dd) = pid_z_coeffs(g.kc, g.tau_i_s, g.tau_d_s, g.derivative_filter_n, DT)
    r, y = (step, 0 * step) if on_setpoint else (0 * step, step)
    expected = lfilter(pn, pd, r - y) + lfilter(dn, dd, y)
    assert out == pytest.approx(expected, rel=1e-5, abs=1e-5 * np.max(np.abs(expected)))


def test_the_continuous_pid_is_the_z_domain_ones_limit():
    # Both forms come from one reading of the gains (sim/plant/pid_model.py): at a short
    # period the Tustin PID's response on the error is the continuous one's (their difference
    # O((w dt)^2)), and the validation's python-control PID is the same polynomial pair.
    g = flown_rate_gains()
    num, den = pid_s_coeffs(g.kc, g.tau_i_s, g.tau_d_s, g.derivative_filter_n)
    w = np.array([0.5, 5.0, 50.0])
    continuous = np.polyval(num, 1j * w) / np.polyval(den, 1j * w)
    dt = 1e-5
    (pn, pd), (dn, dd) = pid_z_coeffs(g.kc, g.tau_i_s, g.tau_d_s, g.derivative_filter_n, dt)
    z = np.exp(1j * w * dt)
    on_error = np.polyval(pn, z) / np.polyval(pd, z) - np.polyval(dn, z) / np.polyval(dd, z)
    assert on_error == pytest.approx(continuous, rel=1e-6)
    C = pid_tf(g.kc, g.tau_i_s, g.tau_d_s)
    assert np.asarray(C(1j * w)).ravel() == pytest.approx(continuous, rel=1e-12)


def test_cascade_defaults_are_the_papers_gains():
    g = fw.CascadeGains.paper_defaults()
    assert (g.rate(fw.Axis.ROLL).kc, g.rate(fw.Axis.ROLL).tau_i_s) == pytest.approx((2.422, 0.439))
    assert g.rate(fw.Axis.YAW).tau_d_s == pytest.approx(0.043)
    assert (g.angle(fw.Axis.PITCH).kc, g.angle(fw.Axis.PITCH).tau_d_s) == pytest.approx((1.501, 0.106))
    assert g.angle(fw.Axis.ROLL).tau_i_s == 0.0


def test_rate_loop_holds_a_rate_on_a_toy_plant():
    # Body rate p' = 2 (torque command) - p per axis: the PID drives p to the setpoint.
    ctl = fw.RateController(fw.CascadeGains.paper_defaults())
    p = [0.0, 0.0, 0.0]
    sp = fw.Vec3(0.5, -0.3, 0.2)
    for _ in range(2000):
        cmd = ctl.update(sp, fw.Vec3(*p), DT).to_list()
        p = [pk + DT * (2 * ck - pk) for pk, ck in zip(p, cmd)]
    assert p == pytest.approx([0.5, -0.3, 0.2], abs=1e-3)


@pytest.mark.parametrize("tau_i", [1.4e-45, 1e-38, 5e-4])
def test_an_integral_time_below_the_floor_never_makes_the_output_non_finite(tau_i):
    """Defence in depth behind the parameters' floor (0 or at least 1 ms): a tau_I below
    fw.MIN_TIME_CONSTANT_S (a denormal: 1.4e-45 is the INT32 1 read as a float) turns the
    integral off instead of dividing by it; Kc dt / (2 tau_I) would be infinite and the
    output NaN from the first zero error on."""
    assert fw.MIN_TIME_CONSTANT_S == pytest.approx(1e-3)
    pid = fw.Pid(gains(2.422, tau_i, 0.051))
    for k in range(200):
        setpoint = 0.0 if k < 50 else 0.1
        out = pid.update(setpoint, 0.02 * math.sin(0.1 * k), DT)
        assert math.isfinite(out) and math.isfinite(pid.i_term), (k, out)
    assert pid.i_term == 0.0
    below, pd = fw.Pid(gains(2.422, tau_i, 0.051)), fw.Pid(gains(2.422, 0.0, 0.051))
    for k in range(50):                                  # exactly the PD (tau_I = 0: off)
        y = 0.02 * math.sin(0.1 * k)
        assert below.update(0.1, y, DT) == pd.update(0.1, y, DT)
