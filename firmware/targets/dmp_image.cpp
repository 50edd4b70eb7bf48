#include "dmp_image.hpp"

#include "../core/crc32.hpp"

namespace hq {

namespace {

uint16_t le16(const uint8_t* p) { return static_cast<uint16_t>(p[0] | (p[1] << 8)); }

}  // namespace

const char* use_dmp_file(const uint8_t* data, size_t n, Mpu6050Config& imu) {
    using namespace dmp_file;
    const bool magic = n >= 4 && data[0] == kMagic[0] && data[1] == kMagic[1] &&
                       data[2] == kMagic[2] && data[3] == kMagic[3];
    if (!magic && n == kBareImageSize) {
        return "a bare 1929-byte DMP image (the old format, without the MotionApps "
               "configuration): regenerate it with heliquad dmp-image";
    }
    if (!magic) return "not a heliquad DMP firmware file (no HQDM magic): make one with heliquad dmp-image";
    if (n < kHeaderSize) return "DMP firmware file: shorter than its 16-byte header";
    if (le16(data + 4) != kVersion) return "DMP firmware file: version is not 1 (regenerate it with heliquad dmp-image)";
    const uint16_t image = le16(data + 6), config = le16(data + 8), updates = le16(data + 10);
    if (image == 0 || image > kMaxImage || config < 3 || config > kMaxTable || updates < 3 ||
        updates > kMaxTable) {
        return "DMP firmware file: a part's size is out of range";
    }
    if (n != kHeaderSize + image + config + updates) {
        return "DMP firmware file: its length does not match the sizes in its header (truncated?)";
    }
    const uint32_t stored = static_cast<uint32_t>(le16(data + 12)) |
                            (static_cast<uint32_t>(le16(data + 14)) << 16);
    // The CRC-32 of the header's first 12 bytes and then everything after the header.
    const uint32_t crc = crc32(data + kHeaderSize, n - kHeaderSize, crc32(data, 12));
    if (crc != stored) return "DMP firmware file: CRC-32 mismatch (damaged)";
    imu.dmp_image = data + kHeaderSize;
    imu.dmp_image_size = image;
    imu.dmp_config = imu.dmp_image + image;
    imu.dmp_config_size = config;
    imu.dmp_updates = imu.dmp_config + config;
    imu.dmp_updates_size = updates;
    return nullptr;
}

bool use_built_in_dmp(Mpu6050Config& imu) {
    if (kDmpImageSize == 0) return false;
    imu.dmp_image = kDmpImage;
    imu.dmp_image_size = kDmpImageSize;
    imu.dmp_config = kDmpConfig;
    imu.dmp_config_size = kDmpConfigSize;
    imu.dmp_updates = kDmpUpdates;
    imu.dmp_updates_size = kDmpUpdatesSize;
    return true;
}

}  // namespace hq
