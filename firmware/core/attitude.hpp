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

// How much the raw path's ComplementaryFilter trusts the accelerometer (docs/mpu6050.md,
// "The raw path's attitude filter"). The accelerometer measures specific force, which points
// away from gravity only when the vehicle does not accelerate. A multirotor in free flight
// accelerates sideways whenever it is tilted (at hover thrust by g tan(tilt)), and its
// accelerometer then reads the thrust axis, i.e. "level", until drag catches up (seconds).
// So, as flight controllers do, the correction gain is low in flight and is weighted down
// when the readings say the accelerometer is not a gravity reference:
//   weight = w_norm * w_rate * w_tilt, each falling linearly from 1 to 0:
//   w_norm: as | |a| / g - 1 | grows to accel_band_g (vibration, thrust changes, impacts);
//   w_rate: as the rotation rate |w| grows to rate_limit_rad_s (turns and manoeuvres, where
//           centripetal acceleration, which cannot be computed without velocity, is large);
//   w_tilt: in flight only, as the estimated tilt grows to tilt_limit_rad (the multirotor's
//           sideways acceleration at that tilt).
// Before arming (on the ground or in the hand) nothing accelerates for long, so the filter
// levels with the fast gain kp_ground and no tilt weight.
struct AttitudeFilterConfig {
    float kp_ground = 2.0f;          // rad/s per unit error while disarmed (time constant 0.5 s)
    float kp_flight = 0.25f;         // rad/s per unit error while armed (time constant 4 s)
    float accel_band_g = 0.15f;      // w_norm reaches 0 at | |a| / g - 1 | = 0.15
    float rate_limit_rad_s = 0.35f;  // w_rate reaches 0 at 0.35 rad/s (20 deg/s)
    float tilt_limit_rad = 0.105f;   // w_tilt reaches 0 at 0.105 rad (6 deg) of estimated tilt
};

// Complementary (Mahony proportional) attitude filter for the raw gyro/accelerometer path:
// integrates the gyro and pulls roll and pitch toward the accelerometer's gravity direction
// with gain kp x weight (rad/s per unit error; AttitudeFilterConfig). Yaw is the integrated
// gyro only.
class ComplementaryFilter {
public:
    explicit ComplementaryFilter(const AttitudeFilterConfig& config = AttitudeFilterConfig())
        : config_(config) {}
    // gyro in rad/s (FRD), accel in m/s^2 (FRD specific force), dt in s; in_flight: armed
    // (the low gain and the tilt weight apply).
    void update(const Vec3& gyro_rad_s, const Vec3& accel_m_s2, float dt_s, bool in_flight);
    void reset(const Quat& q = Quat()) { q_ = q; }
    const Quat& quaternion() const { return q_; }
    // The accelerometer's weight (0..1) in the last update.
    float accel_weight() const { return weight_; }
    const AttitudeFilterConfig& config() const { return config_; }

private:
    AttitudeFilterConfig config_;
    Quat q_{};
    float weight_ = 0.0f;
};

}  // namespace hq
