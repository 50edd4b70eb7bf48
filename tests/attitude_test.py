"""Attitude conventions (firmware/core/attitude.cpp): ZYX Euler, DMP frame to FRD."""

import math

import numpy as np
import pytest

from heliquad import _firmware as fw

ANGLES = [(0.3, -0.2, 1.0), (-1.2, 0.7, -2.5), (0.0, 1.5, 0.4), (2.9, -0.1, 3.0)]


def rotation(roll, pitch, yaw):
    """Body FRD -> NED, ZYX: R = Rz(yaw) Ry(pitch) Rx(roll)."""
    cr, sr, cp, sp, cy, sy = (math.cos(roll), math.sin(roll), math.cos(pitch), math.sin(pitch),
                              math.cos(yaw), math.sin(yaw))
    rz = np.array([[cy, -sy, 0], [sy, cy, 0], [0, 0, 1]])
    ry = np.array([[cp, 0, sp], [0, 1, 0], [-sp, 0, cp]])
    rx = np.array([[1, 0, 0], [0, cr, -sr], [0, sr, cr]])
    return rz @ ry @ rx


def quat_matrix(q):
    w, x, y, z = q
    return np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
                     [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
                     [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)]])


@pytest.mark.parametrize("angles", ANGLES)
def test_euler_round_trip_and_rotation_matrix(angles):
    q = fw.from_euler(fw.Euler(*angles))
    np.testing.assert_allclose(quat_matrix(q.to_list()), rotation(*angles), atol=1e-6)
    e = fw.to_euler(q)
    assert (e.roll, e.pitch, e.yaw) == pytest.approx(angles, abs=1e-5)


@pytest.mark.parametrize("angles", ANGLES)
def test_dmp_quaternion_converts_to_frd_without_sign_flips(angles):
    # The DMP's chip frame is x forward, y left, z up; its world is z up. Build the DMP
    # quaternion of a known FRD attitude as the chip would report it and convert back.
    flip = np.diag([1.0, -1.0, -1.0])                     # FRD <-> FLU, NED <-> NWU
    r_chip = flip @ rotation(*angles) @ flip
    w = math.sqrt(max(1 + np.trace(r_chip), 0.0)) / 2
    q = (w, (r_chip[2, 1] - r_chip[1, 2]) / (4 * w), (r_chip[0, 2] - r_chip[2, 0]) / (4 * w),
         (r_chip[1, 0] - r_chip[0, 1]) / (4 * w))
    e = fw.to_euler(fw.dmp_to_frd(fw.Quat(*q)))
    assert (e.roll, e.pitch, e.yaw) == pytest.approx(angles, abs=1e-5)


G = 9.80665
DT = 0.005


def tilt_error_deg(filt, roll, pitch):
    """How far the filter's down direction is from the true one (deg), yaw aside."""
    e = fw.to_euler(filt.quaternion)
    return math.degrees(max(abs(e.roll - roll), abs(e.pitch - pitch)))


def no_weights(kp_flight=0.25):
    """The filter as it was before the weights: a constant gain, the accelerometer always
    believed (for the contrast that shows the tests below can fail)."""
    c = fw.AttitudeFilterConfig()
    c.kp_flight, c.accel_band_g, c.rate_limit_rad_s, c.tilt_limit_rad = kp_flight, 0.0, 0.0, 0.0
    return c


def test_static_tilt_converges_before_arming():
    f = fw.ComplementaryFilter()
    roll, pitch = 0.2, -0.1                       # body rolled right, nose down, at rest
    accel = fw.Vec3(G * math.sin(pitch), -G * math.sin(roll) * math.cos(pitch),
                    -G * math.cos(roll) * math.cos(pitch))
    for _ in range(600):                          # 3 s: six time constants of kp_ground = 2/s
        f.update(fw.Vec3(0, 0, 0), accel, DT, False)
    assert tilt_error_deg(f, roll, pitch) < 0.2
    for _ in range(1400):
        f.update(fw.Vec3(0, 0, 0), accel, DT, False)
    assert tilt_error_deg(f, roll, pitch) < 1e-3


def test_in_flight_a_small_static_tilt_converges_slowly():
    # Armed on a rig or in a steady wind: a 3 deg tilt that does not accelerate. The tilt weight
    # is 0.5 there, so the time constant is 8 s instead of 4 s.
    f = fw.ComplementaryFilter()
    roll = math.radians(3.0)
    accel = fw.Vec3(0.0, -G * math.sin(roll), -G * math.cos(roll))
    for _ in range(12000):                        # 60 s
        f.update(fw.Vec3(0, 0, 0), accel, DT, True)
    assert tilt_error_deg(f, roll, 0.0) < 0.05


def test_the_integrated_gyro_alone():
    c = fw.AttitudeFilterConfig()
    c.kp_ground = 0.0
    f = fw.ComplementaryFilter(c)
    for _ in range(200):                          # 1 s at 0.5 rad/s yaw
        f.update(fw.Vec3(0, 0, 0.5), fw.Vec3(0, 0, -G), DT, False)
    assert fw.to_euler(f.quaternion).yaw == pytest.approx(0.5, abs=1e-3)


@pytest.mark.parametrize("norm_g, rate_deg_s, in_flight, tilt_deg, weight", [
    (1.0, 0.0, True, 0.0, 1.0),
    (1.075, 0.0, True, 0.0, 0.5),        # half of the 0.15 g band
    (0.8, 0.0, True, 0.0, 0.0),          # beyond it
    (1.0, 10.0, True, 0.0, 1 - 10 / math.degrees(0.35)),
    (1.0, 30.0, False, 0.0, 0.0),        # turning faster than 20 deg/s
    (1.0, 0.0, True, 3.0, 1 - math.radians(3.0) / 0.105),
    (1.0, 0.0, False, 3.0, 1.0),         # no tilt weight before arming
])
def test_the_accelerometer_weight(norm_g, rate_deg_s, in_flight, tilt_deg, weight):
    f = fw.ComplementaryFilter()
    f.reset(fw.from_euler(fw.Euler(math.radians(tilt_deg), 0.0, 0.0)))
    f.update(fw.Vec3(0.0, 0.0, math.radians(rate_deg_s)), fw.Vec3(0.0, 0.0, -norm_g * G), 1e-6,
             in_flight)
    assert f.accel_weight == pytest.approx(weight, abs=2e-3)


def banked_acceleration(config, bank_deg, seconds):
    """Free flight at a constant bank and thrust, no rotation: the vehicle accelerates sideways
    at g tan(bank) and the accelerometer reads the thrust axis (body -z) only. The worst tilt
    error (deg) of a filter started at the true attitude."""
    f = fw.ComplementaryFilter(config)
    bank = math.radians(bank_deg)
    f.reset(fw.from_euler(fw.Euler(bank, 0.0, 0.0)))
    accel = fw.Vec3(0.0, 0.0, -G / math.cos(bank))
    worst = 0.0
    for _ in range(int(seconds / DT)):
        f.update(fw.Vec3(0, 0, 0), accel, DT, True)
        worst = max(worst, tilt_error_deg(f, bank, 0.0))
    return worst


def test_sustained_sideways_acceleration_does_not_drag_the_estimate():
    # Stated bound: a 10 deg bank held for 20 s in free flight moves the estimate by less than
    # 0.01 deg (the accelerometer's weight is 0 beyond 6 deg of estimated tilt). The unweighted
    # filter at the same gain is dragged most of the way to level.
    assert banked_acceleration(fw.AttitudeFilterConfig(), 10.0, 20.0) < 0.01
    assert banked_acceleration(no_weights(), 10.0, 20.0) > 8.0


def coordinated_turn(config, bank_deg, speed_m_s, seconds):
    """A level, constant-rate coordinated turn: bank phi, turn rate g tan(phi) / V about NED
    down, specific force along body -z (|a| = g / cos phi). The worst tilt error (deg) of a
    filter started at the true attitude; the truth's roll stays phi and its pitch 0."""
    f = fw.ComplementaryFilter(config)
    bank = math.radians(bank_deg)
    turn = G * math.tan(bank) / speed_m_s
    f.reset(fw.from_euler(fw.Euler(bank, 0.0, 0.0)))
    gyro = fw.Vec3(0.0, turn * math.sin(bank), turn * math.cos(bank))   # R^T [0 0 turn]
    accel = fw.Vec3(0.0, 0.0, -G / math.cos(bank))
    worst = 0.0
    for _ in range(int(seconds / DT)):
        f.update(gyro, accel, DT, True)
        worst = max(worst, tilt_error_deg(f, bank, 0.0))
    return worst


def test_a_coordinated_turn_does_not_drag_the_estimate():
    # Stated bounds, 60 s (more than a full circle) each: a 20 deg turn at 10 m/s (21 deg/s)
    # and a 10 deg turn at 10 m/s (10 deg/s) move the estimate by less than 0.1 deg; the error
    # left is the integration's own. Unweighted, the estimate is pulled toward level.
    assert coordinated_turn(fw.AttitudeFilterConfig(), 20.0, 10.0, 60.0) < 0.1
    assert coordinated_turn(fw.AttitudeFilterConfig(), 10.0, 10.0, 60.0) < 0.1
    assert coordinated_turn(no_weights(), 20.0, 10.0, 60.0) > 8.0


def test_a_gentle_turn_can_drag_the_estimate_by_no_more_than_its_bank():
    # The limit of the method, stated: below 6 deg of bank the accelerometer keeps some weight,
    # so a long gentle turn pulls the estimate toward level, but never past it.
    assert coordinated_turn(fw.AttitudeFilterConfig(), 4.0, 10.0, 60.0) < 4.0
