// The simulator's per-frame work in C++ (heliquad._simcore; docs/architecture.md): what a
// plant offers the lockstep engine. Python (sim/plant/*.py) builds and configures every
// plant, draws the random numbers and states the truth; this code only steps it, frame after
// frame.
//
// Units and frames as in docs/units-and-frames.md: body FRD, NED, quaternion w x y z (body
// to NED), rates rad/s, specific force m/s^2, motor commands thrust fractions 0..1.
#pragma once

#include <array>
#include <cstdint>

#include "core/mixer.hpp"
#include "core/types.hpp"

namespace hqsim {

using hq::kMaxRotors;               // the firmware's motor arrays: central rotor first
using hq::kMotors;                  // the firmware mixer's: central, then front, right, back, left
constexpr double kGravity = 9.80665;

// What the MPU6050 reports for one sample (before quantisation), body FRD.
struct SensorSample {
    std::array<double, 4> q{1.0, 0.0, 0.0, 0.0};
    std::array<double, 3> gyro_rad_s{0.0, 0.0, 0.0};
    std::array<double, 3> accel_m_s2{0.0, 0.0, 0.0};
};

// A plant the engine can drive. Per frame, in this order: sensor(noise) gives the sample the
// firmware reads at the start of the period, then step(motor, gust) holds the firmware's
// reply for one period: its first rotors() thrust fractions (the reply's array is kMaxRotors
// wide; the firmware must fly rotors() rotors). `noise` (6 values: gyro rad/s, accel m/s^2,
// already scaled) and `gust` (6 values: gust velocity m/s and gust rates rad/s, body axes)
// may be null.
class RigPlant {
public:
    virtual ~RigPlant() = default;
    virtual SensorSample sensor(const double* noise) = 0;
    virtual void step(const float motor[kMaxRotors], const double* gust) = 0;
    virtual int rotors() const = 0;
};

using Vec3 = std::array<double, 3>;
using Rotation = std::array<double, 9>;   // row-major

// Body FRD -> NED rotation of the unit quaternion (w x y z).
Rotation rotation(const double q[4]);
Vec3 rotate(const Rotation& r, const Vec3& v);        // R v: body -> NED
Vec3 rotate_back(const Rotation& r, const Vec3& v);   // R^T v: NED -> body

// The sample of a body at rest at attitude q turning at `rates`: the accelerometer reads
// gravity only (body FRD).
SensorSample at_rest(const std::array<double, 4>& q, const Vec3& rates);

}  // namespace hqsim
