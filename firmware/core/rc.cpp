#include "rc.hpp"

namespace hq {

namespace {
float clampf(float x, float lo, float hi) { return x < lo ? lo : (x > hi ? hi : x); }
}  // namespace

float stick(const RcInput& in, int channel) {
    if (!has_signal(in, channel)) return 0.0f;
    const float us = static_cast<float>(in.channel_us[channel]);
    return clampf((us - rc::kCenterUs) / rc::kHalfSpanUs, -1.0f, 1.0f);
}

float throttle(const RcInput& in) {
    if (!has_signal(in, rc::kThrottle)) return 0.0f;
    const float us = static_cast<float>(in.channel_us[rc::kThrottle]);
    return clampf((us - rc::kMinUs) / (2.0f * rc::kHalfSpanUs), 0.0f, 1.0f);
}

Sticks sticks(const RcInput& in, const StickLimits& limits) {
    Sticks s;
    const float roll = stick(in, rc::kRoll), pitch = stick(in, rc::kPitch);
    s.angle.roll = roll * limits.angle_rad;
    s.angle.pitch = pitch * limits.angle_rad;
    s.rate = Vec3{roll * limits.rate_rad_s, pitch * limits.rate_rad_s,
                  stick(in, rc::kYaw) * limits.yaw_rate_rad_s};
    s.throttle = throttle(in);
    return s;
}

}  // namespace hq
