// MPU6050 FIFO packets as the chip produces them, for the firmware's driver to read.
// Formats and scales are those of firmware/core/mpu6050.hpp (docs/mpu6050.md): a DMP packet is
// 42 bytes (quaternion Q30, gyro and accel as int32 with the value in the high int16, two
// unused bytes), a raw sample 12 bytes (accel x y z, gyro x y z, int16); all big-endian.
// Values come in body FRD and go to the chip frame (x forward, y left, z up) here.
#pragma once

#include <cstddef>
#include <cstdint>

#include "core/mpu6050.hpp"
#include <hq_mavlink.hpp>
#include "plant/rig_plant.hpp"

namespace hqsim {

// The chip's scales and packet sizes: the firmware driver's (one definition).
using hq::mpu6050::kAccelLsbPerG;
using hq::mpu6050::kDmpPacketSize;
using hq::mpu6050::kGyroLsbPerDegS;
using hq::mpu6050::kQuatScale;
using hq::mpu6050::kRawPacketSize;

// Kinds of FIFO data: the dialect's HQ_SENSOR_KIND.
enum class FifoKind : uint8_t { None = HQ_SENSOR_NONE, Dmp = HQ_SENSOR_DMP, Raw = HQ_SENSOR_RAW };

// Writes the packet of `kind` for `s` into `out` (room for kDmpPacketSize); returns its size.
size_t encode_fifo(FifoKind kind, const SensorSample& s, uint8_t* out);

}  // namespace hqsim
