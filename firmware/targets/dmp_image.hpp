// The MPU6050 DMP image compiled into a target at build time (CMake option HQ_DMP_IMAGE, a
// file made with `heliquad dmp-image`). The image is InvenSense's and is never committed:
// the definitions are generated into the build tree. kDmpImageSize is 0 without an image,
// and the firmware then flies on the raw FIFO path (docs/mpu6050.md).
#pragma once

#include <cstdint>

namespace hq {
extern const uint8_t kDmpImage[];
extern const uint16_t kDmpImageSize;
}  // namespace hq
