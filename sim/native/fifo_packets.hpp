// MPU6050 FIFO packets as the chip produces them, for the firmware's driver to read.
// Formats and scales are those of firmware/core/mpu6050.hpp (docs/mpu6050.md): a DMP packet is
// 42 bytes (quaternion Q30, gyro and accel as int32 with the value in the high int16, two
// unused bytes), a raw sample 12 bytes (accel x y z, gyro x y z, int16); all big-endian.
// Values come in body FRD and go to the chip frame (x forward, y left, z up) here.
#pragma once

#include <cstddef>
#include <cstdint>

#include "rig_plant.hpp"

namespace hqsim {

constexpr double kGyroLsbPerDegS = 16.4;      // +/-2000 deg/s full scale
constexpr double kAccelLsbPerG = 16384.0;     // +/-2 g full scale
constexpr size_t kDmpPacketSize = 42;
constexpr size_t kRawPacketSize = 12;

// Kinds of FIFO data (HQ_SENSOR_KIND in firmware/mavlink/heliquad.xml).
enum class FifoKind : uint8_t { None = 0, Dmp = 1, Raw = 2 };

// Writes the packet of `kind` for `s` into `out` (room for kDmpPacketSize); returns its size.
size_t encode_fifo(FifoKind kind, const SensorSample& s, uint8_t* out);

}  // namespace hqsim
