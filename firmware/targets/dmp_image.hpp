// The MPU6050's MotionApps 2.0 DMP firmware (the image, the configuration table dmpConfig and
// the update table dmpUpdates), which is InvenSense's and never committed:
// - compiled into a target at build time (CMake option HQ_DMP_IMAGE names a file made with
//   `heliquad dmp-image`); CMake checks the file and generates these definitions into the
//   build tree. The sizes are 0 without a file, and the firmware then flies on the raw FIFO
//   path (docs/mpu6050.md);
// - or read at run time from the same kind of file (heliquad-fw-host --dmp-image), with
//   use_dmp_file().
// The file format (magic, version, sizes, CRC-32, then the three parts): docs/file-formats.md.
#pragma once

#include <cstddef>
#include <cstdint>

#include "../core/mpu6050.hpp"

namespace hq {

extern const uint8_t kDmpImage[];
extern const uint16_t kDmpImageSize;
extern const uint8_t kDmpConfig[];
extern const uint16_t kDmpConfigSize;
extern const uint8_t kDmpUpdates[];
extern const uint16_t kDmpUpdatesSize;

namespace dmp_file {
constexpr uint8_t kMagic[4] = {'H', 'Q', 'D', 'M'};
constexpr uint16_t kVersion = 1;
constexpr size_t kHeaderSize = 16;    // magic, version, three sizes (uint16 LE), CRC-32 (LE)
constexpr uint16_t kMaxImage = mpu6050::kDmpMemorySize, kMaxTable = 1024;
constexpr size_t kBareImageSize = 1929;   // what `heliquad dmp-image` wrote before version 1
}  // namespace dmp_file

// Checks a DMP firmware file's bytes and points `imu` at the three parts inside them (they are
// borrowed: keep `data` alive). nullptr when it is good, else why not, in one line.
const char* use_dmp_file(const uint8_t* data, size_t n, Mpu6050Config& imu);
// Points `imu` at the compiled-in DMP firmware; false (and `imu` untouched) without one.
bool use_built_in_dmp(Mpu6050Config& imu);

}  // namespace hq
