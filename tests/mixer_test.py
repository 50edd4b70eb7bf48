"""The firmware's mixer (firmware/core/mixer.cpp): 1 central + 4 canted arm rotors."""

import itertools
import math

import numpy as np
import pytest

from heliquad import _firmware as fw

MIXER = fw.Mixer()


def wrench(motor, g=fw.MixerGeometry()):
    """Physical Fz, tau_x, tau_y, tau_z (N, N m) of thrust fractions, from docs/mixer.md."""
    d = math.radians(g.cant_deg)
    t0 = motor[0] * g.central_max_thrust_n
    t = [m * g.arm_max_thrust_n for m in motor[1:]]
    l, c0 = g.arm_length_m, g.central_torque_per_thrust_m
    fz = t0 + math.cos(d) * sum(t)
    tx = -l * math.cos(d) * (t[1] - t[3])
    ty = l * math.cos(d) * (t[0] - t[2])
    tz = c0 * t0 - l * math.sin(d) * sum(t)
    return np.array([fz, tx, ty, tz])


def requested(cmd):
    return np.array([cmd.collective * MIXER.max_vertical_thrust_n,
                     cmd.roll * MIXER.roll_pitch_torque_unit_nm,
                     cmd.pitch * MIXER.roll_pitch_torque_unit_nm,
                     cmd.yaw * MIXER.yaw_torque_unit_nm])


# The commands of the tests below, (collective, roll, pitch, yaw); tests/allocation_test.py
# mixes them with the allocation from the rotor geometry too.
# Feasible without saturation: yaw balance ties the mean arm thrust to the central rotor's
# torque (0.32 N per arm at hover, 0.42 N at collective 0.2), and each arm must stay within
# 0..max; commands are in units of hover authority (docs/mixer.md). Collective above ~0.49
# would need more than the central rotor's maximum.
UNSATURATED = list(itertools.product([0.2, 0.35], [-0.5, 0.0, 0.6], [-0.5, 0.3],
                                     [-0.3, 0.0, 0.2]))
HOVER = (0.3, 0.0, 0.0, 0.0)
SMALL_ROLL, SMALL_PITCH = (0.3, 0.05, 0.0, 0.0), (0.3, 0.0, 0.05, 0.0)
# Large roll and pitch at these collectives: the collective gives way.
SATURATING_COLLECTIVES = [0.0, 0.02, 0.98, 1.0]
ROLL_PITCH_BEYOND_HOVER = (0.8, -0.6)
ROLL_BEYOND_FULL = (0.3, 20.0, 0.0, 0.0)
# (collective, yaw, whether the collective gives way)
YAW_CASES = [
    (0.05, -0.9, False),     # within the authority: both met, nothing flagged
    (0.05, 2.0, True),       # large yaw at low collective: the central rotor must push more
    (0.3, 3.0, True),
]


@pytest.mark.parametrize("c, r, p, y", UNSATURATED)
def test_unsaturated_commands_are_reproduced(c, r, p, y):
    cmd = fw.MixerCommand(c, r, p, y)
    out = MIXER.mix(cmd)
    assert not out.saturated
    assert all(0.0 <= m <= 1.0 for m in out.motor)
    np.testing.assert_allclose(wrench(out.motor), requested(cmd), rtol=1e-4, atol=1e-5)


def test_hover_puts_the_collective_on_the_central_rotor():
    out = MIXER.mix(fw.MixerCommand(*HOVER))
    g = fw.MixerGeometry()
    central = out.motor[0] * g.central_max_thrust_n
    arms = 4 * out.motor[1] * g.arm_max_thrust_n * math.cos(math.radians(g.cant_deg))
    assert central > 5 * arms
    # and the canted arms cancel the central rotor's torque exactly
    assert wrench(out.motor)[3] == pytest.approx(0.0, abs=1e-6)
    assert len(set(np.round(out.motor[1:], 7))) == 1


def test_roll_right_speeds_up_the_left_rotor():
    out = MIXER.mix(fw.MixerCommand(*SMALL_ROLL))
    assert out.motor[4] > out.motor[2]          # left > right
    out = MIXER.mix(fw.MixerCommand(*SMALL_PITCH))
    assert out.motor[1] > out.motor[3]          # pitch up: front > back


@pytest.mark.parametrize("collective", SATURATING_COLLECTIVES)
def test_saturation_keeps_roll_and_pitch_before_collective(collective):
    roll, pitch = ROLL_PITCH_BEYOND_HOVER
    cmd = fw.MixerCommand(collective, roll, pitch, 0.0)
    out = MIXER.mix(cmd)
    got = MIXER.achieved(out.motor)
    assert out.saturated and out.collective_limited
    # roll and pitch are kept; a torque is flagged only when yaw had to give way as well
    assert out.torque_limited == (abs(got.yaw) > 1e-4)
    assert got.roll == pytest.approx(roll, abs=1e-5)
    assert got.pitch == pytest.approx(pitch, abs=1e-5)
    assert all(0.0 <= m <= 1.0 for m in out.motor)


def test_one_unit_of_roll_is_the_hover_arm_thrust_moved_across():
    g = fw.MixerGeometry()
    assert MIXER.hover_arm_thrust_n == pytest.approx(
        g.central_torque_per_thrust_m * g.hover_thrust_n
        / (4 * g.arm_length_m * math.sin(math.radians(g.cant_deg))
           + 4 * math.cos(math.radians(g.cant_deg)) * g.central_torque_per_thrust_m), rel=1e-5)
    assert MIXER.roll_pitch_torque_unit_nm == pytest.approx(
        g.arm_length_m * math.cos(math.radians(g.cant_deg)) * 2 * MIXER.hover_arm_thrust_n, rel=1e-6)


def test_roll_beyond_the_full_differential_is_clipped_and_flagged():
    out = MIXER.mix(fw.MixerCommand(*ROLL_BEYOND_FULL))
    assert out.saturated and out.torque_limited
    full = fw.MixerGeometry().arm_max_thrust_n / (2 * MIXER.hover_arm_thrust_n)
    assert MIXER.achieved(out.motor).roll == pytest.approx(full, rel=1e-5)


@pytest.mark.parametrize("collective, yaw, gives_way", YAW_CASES)
def test_yaw_is_kept_before_collective(collective, yaw, gives_way):
    # The yaw moment is always met here; the collective gives way when both cannot be, and
    # the mixer flags exactly that.
    out = MIXER.mix(fw.MixerCommand(collective, 0.0, 0.0, yaw))
    got = MIXER.achieved(out.motor)
    assert got.yaw == pytest.approx(yaw, abs=1e-4)
    assert not out.torque_limited
    assert out.collective_limited == gives_way == (abs(got.collective - collective) > 1e-4)
