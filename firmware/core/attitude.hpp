// Attitude maths with stated conventions (docs/units-and-frames.md).
//
// Quaternions are Hamilton, scalar first, and rotate body FRD vectors into NED:
// v_ned = q * v_body * q^-1. Euler angles are ZYX Tait-Bryan (yaw, then pitch, then roll).
//
// The MPU6050 DMP reports the chip's orientation relative to a z-up world with the chip's
// own axes (for a chip mounted upright with x forward: x forward, y left, z up). Converting
// with a 180 deg turn about x on both sides gives FRD relative to NED:
// (w, x, y, z)_dmp -> (w, x, -y, -z). Applying the usual gravity-vector formulas to the raw
// DMP quaternion instead flips the signs of pitch and yaw and mixes yaw into roll when tilted;
// dmp_to_frd followed by to_euler avoids that.
#pragma once

#include "types.hpp"

namespace hq {

Euler to_euler(const Quat& q);
Quat from_euler(const Euler& e);
Quat normalise(const Quat& q);
Quat multiply(const Quat& a, const Quat& b);

// DMP quaternion (chip frame, z-up world) -> body FRD relative to NED.
Quat dmp_to_frd(const Quat& q_dmp);
// Chip-frame vector (x forward, y left, z up) -> FRD.
Vec3 chip_to_frd(const Vec3& v);

// Complementary (Mahony proportional) attitude filter for the raw gyro/accelerometer path:
// integrates the gyro and pulls roll and pitch toward the accelerometer's gravity direction
// with gain kp (rad/s per unit error). Yaw is the integrated gyro only.
class ComplementaryFilter {
public:
    explicit ComplementaryFilter(float kp = 1.0f) : kp_(kp) {}
    // gyro in rad/s (FRD), accel in m/s^2 (FRD specific force), dt in s.
    void update(const Vec3& gyro_rad_s, const Vec3& accel_m_s2, float dt_s);
    void reset(const Quat& q = Quat()) { q_ = q; }
    const Quat& quaternion() const { return q_; }

private:
    float kp_;
    Quat q_{};
};

}  // namespace hq
