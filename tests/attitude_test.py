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


def test_complementary_filter_levels_to_the_accelerometer():
    f = fw.ComplementaryFilter(2.0)
    roll = 0.2                                    # body rolled right by 0.2 rad, at rest
    accel = fw.Vec3(0.0, -9.81 * math.sin(roll), -9.81 * math.cos(roll))
    for _ in range(2000):
        f.update(fw.Vec3(0, 0, 0), accel, 0.005)
    e = fw.to_euler(f.quaternion)
    assert e.roll == pytest.approx(roll, abs=1e-3) and e.pitch == pytest.approx(0.0, abs=1e-3)


def test_complementary_filter_integrates_the_gyro():
    f = fw.ComplementaryFilter(0.0)
    for _ in range(200):                          # 1 s at 0.5 rad/s yaw
        f.update(fw.Vec3(0, 0, 0.5), fw.Vec3(0, 0, -9.81), 0.005)
    assert fw.to_euler(f.quaternion).yaw == pytest.approx(0.5, abs=1e-3)
