"""Per-rotor excitation (HQ_INJECTION_MOTOR1..8, MOTORS; docs/effectiveness.md): the
excitation is added to one rotor's thrust fraction after the allocation, on both firmwares;
MOTORS gives each rotor its own lines of one multisine (harmonic j to rotor j mod the rotor
count); a motor that is not in use, a sine on every rotor, a multisine with fewer lines than
rotors and an amplitude above EXC_MAX_MOT are refused with their reasons.

The check of what reached the rotors uses the default vehicle's symmetry: the right and left
arm rotors (rotors 2 and 4, ESCs 3 and 5) share the allocation's collective, pitch (none) and
yaw coefficients and have opposite roll ones, so their difference is twice the right rotor's
roll coefficient times the loop's roll torque command (HQ_SYSID_SAMPLE's axis_cmd) plus
whatever was injected into the two."""

from __future__ import annotations

import numpy as np
import pytest

from firmware_rig import DT_US
from heliquad import _firmware as fw
from safety_test import MAV, reason, rig  # noqa: F401  (rig: a fixture)

RIGHT, LEFT = 2, 4
#: The right arm rotor's thrust fraction per unit of roll command, as the firmware computes it.
ROLL_COEFF = fw.Allocation(fw.params_geometry()).allocation[RIGHT][1]
#: The samples are float32 on the link; the difference of three of them is good to a few
#: ulps of 1 (the thrust fractions) and of the roll command.
TOL = 2e-6


def _running(rig, since_us):
    return [m for _, m in rig.of_type("HQ_SYSID_SAMPLE", since_us)
            if m.exc_state == MAV.HQ_EXCITATION_STATE_RUNNING]


def _injected(m):
    """What reached the right rotor beyond the allocation, less what reached the left."""
    return m.motor[RIGHT] - m.motor[LEFT] - 2 * ROLL_COEFF * m.axis_cmd


def test_a_motor_injection_is_added_to_that_rotors_thrust_after_the_allocation(rig):
    rig.hover()
    t = rig.ping()
    _, status = rig.excitation_answer(injection="motor3", freq_hz=2.0, amplitude=0.05, cycles=4)
    assert status.accepted, status
    rig.step(int(6 * 200 / 2.0))
    running = _running(rig, t)
    assert len(running) >= 150             # the Teensy's link may drop a sample now and then
    injected = np.array([_injected(m) for m in running])
    exc = np.array([m.excitation for m in running])
    assert np.max(np.abs(exc)) == pytest.approx(0.05, rel=0.01)
    np.testing.assert_allclose(injected, exc, rtol=0, atol=TOL)
    assert all(m.injection == MAV.HQ_INJECTION_MOTOR3 for m in running)


def test_motors_gives_each_rotor_its_own_lines_of_one_multisine(rig):
    """Ten harmonics of 0.5 Hz on five rotors: rotor 2 gets harmonics 3 and 8 (j = 2, 7),
    rotor 4 harmonics 5 and 10 (j = 4, 9); the right-left difference carries exactly those,
    with rotor 4's negated, and nothing at the other rotors' lines."""
    base_hz, amp = 0.5, 0.012
    harmonics = [(j + 1, amp, 0.3 * j) for j in range(10)]
    rig.hover()
    t = rig.ping()
    _, status = rig.excitation_answer(injection="motors", freq_hz=base_hz, amplitude=0.05,
                                      cycles=2, harmonics=harmonics)
    assert status.accepted, status
    period = int(round(1e6 / base_hz / DT_US))
    for _ in range(5 * period // 100):             # the host's heartbeat keeps it running
        rig.step(100)
        rig.ping()
    running = _running(rig, t)
    assert len(running) >= 1.5 * period      # two periods, a dropped sample or two aside
    # Each line's complex amplitude, by least squares over the samples that came (a dropped
    # one leaves no gap in the fit), in what reached the rotors and in the logged sum of
    # every injection: their ratio is +1 on rotor 2's lines, -1 on rotor 4's, 0 elsewhere.
    t_s = np.array([m.time_us for m in running]) * 1e-6
    w = 2 * np.pi * base_hz * np.array([order for order, _, _ in harmonics])
    basis = np.hstack([np.cos(np.outer(t_s, w)), np.sin(np.outer(t_s, w))])

    def lines(values):
        c, *_ = np.linalg.lstsq(basis, np.asarray(values), rcond=None)
        return c[:len(w)] + 1j * c[len(w):]

    ratio = lines([_injected(m) for m in running]) / lines([m.excitation for m in running])
    want = [{RIGHT: 1, LEFT: -1}.get(j % 5, 0) for j in range(len(harmonics))]
    np.testing.assert_allclose(ratio, want, rtol=0, atol=1e-3)


@pytest.mark.parametrize("change, why", [
    ({"injection": "motor6"}, "AXIS_INJECTION"),           # the default vehicle has five
    ({"injection": "motor8"}, "AXIS_INJECTION"),
    ({"injection": "motors"}, "HARMONICS"),                # a sine on every rotor
    ({"injection": "motors", "harmonics": [(1, 0.01, 0.0), (2, 0.01, 0.0)]}, "HARMONICS"),
    ({"injection": "motor1", "amplitude": 0.21}, "AMPLITUDE"),   # EXC_MAX_MOT is 0.2
])
def test_a_motor_injection_the_vehicle_cannot_take_is_refused(rig, change, why):
    rig.hover()
    rig.ping()
    _, status = rig.excitation_answer(**change)
    assert status.accepted == 0 and status.reason == reason(why)
