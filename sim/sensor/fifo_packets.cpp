#include "sensor/fifo_packets.hpp"

#include <algorithm>
#include <cmath>

namespace hqsim {
namespace {

constexpr double kRadToDeg = 57.29577951308232;

// A converter's count: rounded half to even (as the Python reference and the chip's
// converters do) and saturated to [lo, hi] before any conversion to an integer. A non-finite
// simulator value (a diverged plant) reads as 0: the cast of NaN to an integer is undefined.
int64_t saturated_count(double v, double lo, double hi) {
    if (std::isnan(v)) return 0;
    return static_cast<int64_t>(std::clamp(std::nearbyint(v), lo, hi));
}

int32_t count16(double value, double scale) {
    return static_cast<int32_t>(saturated_count(value * scale, -32768.0, 32767.0));
}

void put_be32(uint8_t* p, int32_t v) {
    const uint32_t u = static_cast<uint32_t>(v);
    p[0] = static_cast<uint8_t>(u >> 24);
    p[1] = static_cast<uint8_t>(u >> 16);
    p[2] = static_cast<uint8_t>(u >> 8);
    p[3] = static_cast<uint8_t>(u);
}

void put_be16(uint8_t* p, int32_t v) {
    const uint16_t u = static_cast<uint16_t>(v);
    p[0] = static_cast<uint8_t>(u >> 8);
    p[1] = static_cast<uint8_t>(u);
}

// Body FRD -> chip frame (x forward, y left, z up).
std::array<double, 3> to_chip(const std::array<double, 3>& v) { return {v[0], -v[1], -v[2]}; }

}  // namespace

size_t encode_fifo(FifoKind kind, const SensorSample& s, uint8_t* out) {
    const auto gyro = to_chip(s.gyro_rad_s);
    const auto accel = to_chip(s.accel_m_s2);
    if (kind == FifoKind::Dmp) {
        // FRD attitude relative to NED -> the DMP's chip-frame quaternion (w, x, -y, -z).
        const double q[4] = {s.q[0], s.q[1], -s.q[2], -s.q[3]};
        for (int i = 0; i < 4; ++i) {
            put_be32(out + 4 * i, static_cast<int32_t>(saturated_count(q[i] * kQuatScale, INT32_MIN,
                                                                       INT32_MAX)));
        }
        for (int i = 0; i < 3; ++i) {
            put_be32(out + 16 + 4 * i, count16(gyro[i] * kRadToDeg, kGyroLsbPerDegS) * 65536);
            put_be32(out + 28 + 4 * i, count16(accel[i] / kGravity, kAccelLsbPerG) * 65536);
        }
        out[40] = out[41] = 0;
        return kDmpPacketSize;
    }
    if (kind == FifoKind::Raw) {
        for (int i = 0; i < 3; ++i) {
            put_be16(out + 2 * i, count16(accel[i] / kGravity, kAccelLsbPerG));
            put_be16(out + 6 + 2 * i, count16(gyro[i] * kRadToDeg, kGyroLsbPerDegS));
        }
        return kRawPacketSize;
    }
    return 0;
}

}  // namespace hqsim
