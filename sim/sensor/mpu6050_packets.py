"""FIFO packets as the MPU6050 would produce them, for the firmware's driver to read.

Formats and scales are those of ``firmware/core/mpu6050.hpp`` (docs/mpu6050.md): DMP packets
are 42 bytes (quaternion Q30, gyro and accel as int32 with the value in the high int16, two
unused bytes), raw samples 12 bytes (accel then gyro, int16); all big-endian. Values come in
body FRD and are converted to the chip frame (x forward, y left, z up) by the encoder, which is
C++ (sim/sensor/fifo_packets.cpp) because the lockstep engine encodes a packet every frame;
these are its Python entry points.
"""

from __future__ import annotations

# The scales (gyro LSB per deg/s at +/-2000 deg/s, accel LSB per g at +/-2 g, the DMP
# quaternion's 2^30) and the packet sizes are the firmware driver's constants
# (firmware/core/mpu6050.hpp), through heliquad._simcore: one definition.
from heliquad._simcore import (ACCEL_LSB_PER_G, DMP_PACKET_SIZE, GYRO_LSB_PER_DEG_S, QUAT_SCALE,
                               RAW_PACKET_SIZE, dmp_packet, raw_packet)

__all__ = ["GYRO_LSB_PER_DEG_S", "ACCEL_LSB_PER_G", "QUAT_SCALE", "DMP_PACKET_SIZE",
           "RAW_PACKET_SIZE", "dmp_packet", "raw_packet"]
