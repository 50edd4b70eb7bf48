"""FIFO packets as the MPU6050 would produce them, for the firmware's driver to read.

Formats and scales are those of ``firmware/core/mpu6050.hpp`` (docs/mpu6050.md): DMP packets
are 42 bytes (quaternion Q30, gyro and accel as int32 with the value in the high int16, two
unused bytes), raw samples 12 bytes (accel then gyro, int16); all big-endian. Values come in
body FRD and are converted to the chip frame (x forward, y left, z up) here.
"""

from __future__ import annotations

import struct

import numpy as np

__all__ = ["GYRO_LSB_PER_DEG_S", "ACCEL_LSB_PER_G", "GRAVITY", "DMP_PACKET_SIZE",
           "RAW_PACKET_SIZE", "dmp_packet", "raw_packet", "frd_to_chip", "quat_frd_to_dmp"]

GYRO_LSB_PER_DEG_S = 16.4     # +/-2000 deg/s full scale
ACCEL_LSB_PER_G = 16384.0     # +/-2 g full scale
GRAVITY = 9.80665
DMP_PACKET_SIZE = 42
RAW_PACKET_SIZE = 12
_INT16 = (-32768, 32767)


def frd_to_chip(v):
    """Body FRD vector -> chip frame (x forward, y left, z up)."""
    return np.array([v[0], -v[1], -v[2]], dtype=float)


def quat_frd_to_dmp(q):
    """Attitude (FRD relative to NED, w x y z) -> the DMP's chip-frame quaternion."""
    w, x, y, z = q
    return np.array([w, x, -y, -z], dtype=float)


def _counts(values, scale):
    return np.clip(np.round(np.asarray(values) * scale), *_INT16).astype(int)


def dmp_packet(q_frd, gyro_rad_s_frd, accel_m_s2_frd) -> bytes:
    """One 42-byte DMP packet (quantised as the chip quantises)."""
    q = np.clip(np.round(quat_frd_to_dmp(q_frd) * (1 << 30)), -(1 << 31), (1 << 31) - 1).astype(int)
    gyro = _counts(np.degrees(frd_to_chip(gyro_rad_s_frd)), GYRO_LSB_PER_DEG_S)
    accel = _counts(frd_to_chip(accel_m_s2_frd) / GRAVITY, ACCEL_LSB_PER_G)
    return struct.pack(">4i3i3i2x", *q, *(int(g) << 16 for g in gyro), *(int(a) << 16 for a in accel))


def raw_packet(gyro_rad_s_frd, accel_m_s2_frd) -> bytes:
    """One 12-byte raw FIFO sample: accel x, y, z then gyro x, y, z."""
    accel = _counts(frd_to_chip(accel_m_s2_frd) / GRAVITY, ACCEL_LSB_PER_G)
    gyro = _counts(np.degrees(frd_to_chip(gyro_rad_s_frd)), GYRO_LSB_PER_DEG_S)
    return struct.pack(">3h3h", *accel, *gyro)
