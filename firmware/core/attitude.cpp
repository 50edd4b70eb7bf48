#include "attitude.hpp"

#include <cmath>

namespace hq {

Euler to_euler(const Quat& q) {
    Euler e;
    e.roll = std::atan2(2.0f * (q.w * q.x + q.y * q.z), 1.0f - 2.0f * (q.x * q.x + q.y * q.y));
    float s = 2.0f * (q.w * q.y - q.x * q.z);
    s = s > 1.0f ? 1.0f : (s < -1.0f ? -1.0f : s);     // round-off at +/-90 deg pitch
    e.pitch = std::asin(s);
    e.yaw = std::atan2(2.0f * (q.w * q.z + q.x * q.y), 1.0f - 2.0f * (q.y * q.y + q.z * q.z));
    return e;
}

Quat from_euler(const Euler& e) {
    const float cr = std::cos(0.5f * e.roll), sr = std::sin(0.5f * e.roll);
    const float cp = std::cos(0.5f * e.pitch), sp = std::sin(0.5f * e.pitch);
    const float cy = std::cos(0.5f * e.yaw), sy = std::sin(0.5f * e.yaw);
    Quat q;
    q.w = cr * cp * cy + sr * sp * sy;
    q.x = sr * cp * cy - cr * sp * sy;
    q.y = cr * sp * cy + sr * cp * sy;
    q.z = cr * cp * sy - sr * sp * cy;
    return q;
}

Quat normalise(const Quat& q) {
    const float n = std::sqrt(q.w * q.w + q.x * q.x + q.y * q.y + q.z * q.z);
    if (!(n > 0.0f)) return Quat();
    return Quat{q.w / n, q.x / n, q.y / n, q.z / n};
}

Quat multiply(const Quat& a, const Quat& b) {
    return Quat{a.w * b.w - a.x * b.x - a.y * b.y - a.z * b.z,
                a.w * b.x + a.x * b.w + a.y * b.z - a.z * b.y,
                a.w * b.y - a.x * b.z + a.y * b.w + a.z * b.x,
                a.w * b.z + a.x * b.y - a.y * b.x + a.z * b.w};
}

Quat dmp_to_frd(const Quat& q) { return normalise(Quat{q.w, q.x, -q.y, -q.z}); }

Vec3 chip_to_frd(const Vec3& v) { return Vec3{v.x, -v.y, -v.z}; }

namespace {
// 1 at x = 0, falling linearly to 0 at x = limit (and 0 beyond); a limit <= 0 disables it.
float ramp_down(float x, float limit) {
    if (!(limit > 0.0f)) return 1.0f;
    const float w = 1.0f - x / limit;
    return w > 0.0f ? w : 0.0f;
}
}  // namespace

void ComplementaryFilter::update(const Vec3& gyro, const Vec3& accel, float dt_s, bool in_flight) {
    Vec3 w = gyro;
    weight_ = 0.0f;
    const float an = std::sqrt(accel.x * accel.x + accel.y * accel.y + accel.z * accel.z);
    if (an > 1e-3f) {
        // Estimated down: third row of the body->NED rotation, i.e. R^T [0 0 1].
        const Quat& q = q_;
        const Vec3 de{2.0f * (q.x * q.z - q.w * q.y), 2.0f * (q.y * q.z + q.w * q.x),
                      q.w * q.w - q.x * q.x - q.y * q.y + q.z * q.z};
        const float rate = std::sqrt(gyro.x * gyro.x + gyro.y * gyro.y + gyro.z * gyro.z);
        float weight = ramp_down(std::fabs(an / kGravity - 1.0f), config_.accel_band_g) *
                       ramp_down(rate, config_.rate_limit_rad_s);
        if (in_flight) {
            const float cos_tilt = de.z > 1.0f ? 1.0f : (de.z < -1.0f ? -1.0f : de.z);
            weight *= ramp_down(std::acos(cos_tilt), config_.tilt_limit_rad);
        }
        weight_ = weight;
        const float k = (in_flight ? config_.kp_flight : config_.kp_ground) * weight;
        if (k > 0.0f) {
            // Measured "down" in body axes: at rest the specific force points up, so down = -a.
            const Vec3 dm{-accel.x / an, -accel.y / an, -accel.z / an};
            // Rotate the estimate toward the measurement: e = dm x de.
            w.x += k * (dm.y * de.z - dm.z * de.y);
            w.y += k * (dm.z * de.x - dm.x * de.z);
            w.z += k * (dm.x * de.y - dm.y * de.x);
        }
    }
    const Quat dq = multiply(q_, Quat{0.0f, w.x, w.y, w.z});
    q_ = normalise(Quat{q_.w + 0.5f * dt_s * dq.w, q_.x + 0.5f * dt_s * dq.x,
                        q_.y + 0.5f * dt_s * dq.y, q_.z + 0.5f * dt_s * dq.z});
}

}  // namespace hq
