"""FIFO packets as the MPU6050 would produce them, for the firmware's driver to read.

Formats and scales are those of ``firmware/core/mpu6050.hpp`` (docs/mpu6050.md): DMP packets
are 42 bytes (quaternion Q30, gyro and accel as int32 with the value in the high int16, two
unused bytes), raw samples 12 bytes (accel then gyro, int16); all big-endian. Values come in
body FRD and are converted to the chip frame (x forward, y left, z up) here.
"""

from __future__ import annotations

import math
import struct

__all__ = ["GYRO_LSB_PER_DEG_S", "ACCEL_LSB_PER_G", "GRAVITY", "DMP_PACKET_SIZE",
           "RAW_PACKET_SIZE", "dmp_packet", "raw_packet", "frd_to_chip", "quat_frd_to_dmp"]

GYRO_LSB_PER_DEG_S = 16.4     # +/-2000 deg/s full scale
ACCEL_LSB_PER_G = 16384.0     # +/-2 g full scale
GRAVITY = 9.80665
DMP_PACKET_SIZE = 42
RAW_PACKET_SIZE = 12
_INT16 = (-32768, 32767)
_DMP = struct.Struct(">4i3i3i2x")
_RAW = struct.Struct(">3h3h")


def frd_to_chip(v):
    """Body FRD vector -> chip frame (x forward, y left, z up)."""
    return (v[0], -v[1], -v[2])


def quat_frd_to_dmp(q):
    """Attitude (FRD relative to NED, w x y z) -> the DMP's chip-frame quaternion."""
    return (q[0], q[1], -q[2], -q[3])


def _count(value: float, scale: float) -> int:
    return max(_INT16[0], min(_INT16[1], round(value * scale)))


_DEG = 180.0 / math.pi
_Q30 = float(1 << 30)


def dmp_packet(q_frd, gyro_rad_s_frd, accel_m_s2_frd) -> bytes:
    """One 42-byte DMP packet (quantised as the chip quantises)."""
    q = [max(-(1 << 31), min((1 << 31) - 1, round(c * _Q30))) for c in quat_frd_to_dmp(q_frd)]
    gyro = [_count(g * _DEG, GYRO_LSB_PER_DEG_S) << 16 for g in frd_to_chip(gyro_rad_s_frd)]
    accel = [_count(a / GRAVITY, ACCEL_LSB_PER_G) << 16 for a in frd_to_chip(accel_m_s2_frd)]
    return _DMP.pack(*q, *gyro, *accel)


def raw_packet(gyro_rad_s_frd, accel_m_s2_frd) -> bytes:
    """One 12-byte raw FIFO sample: accel x, y, z then gyro x, y, z."""
    accel = [_count(a / GRAVITY, ACCEL_LSB_PER_G) for a in frd_to_chip(accel_m_s2_frd)]
    gyro = [_count(g * _DEG, GYRO_LSB_PER_DEG_S) for g in frd_to_chip(gyro_rad_s_frd)]
    return _RAW.pack(*accel, *gyro)
