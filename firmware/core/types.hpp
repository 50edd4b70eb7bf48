// Small value types shared by the core. Frames and units (docs/units-and-frames.md):
// body frame FRD (x forward, y right, z down); angles in rad, rates in rad/s; roll, pitch and
// yaw are the ZYX (yaw-pitch-roll) Tait-Bryan angles of the body relative to NED.
//
// The enums that cross a link take their values from the generated dialect
// (firmware/mavlink/heliquad.xml): one definition, no copies.
#pragma once

#include <hq_mavlink.hpp>

#include <cstdint>

namespace hq {

// HQ_AXIS; the value is also the body axis index (x, y, z) of Vec3 and Euler.
enum class Axis : uint8_t { Roll = HQ_AXIS_ROLL, Pitch = HQ_AXIS_PITCH, Yaw = HQ_AXIS_YAW };
constexpr int kAxes = HQ_AXIS_ENUM_END;
constexpr int kAngleAxes = 2;          // roll and pitch: yaw has no angle loop

// The most rotors the firmware drives: rotor 0 the central one, up to seven more. The loop's
// motor arrays, the ESC outputs and the links' motor fields are this wide; the entries past
// the rotor count the loop flies are 0 (docs/link-contract.md).
constexpr int kMaxRotors = 8;

// Standard gravity, m/s^2: the accelerometer's g and the attitude filter's 1 g.
constexpr float kGravity = 9.80665f;

// Flight mode (HQ_MODE): which loops run. Independent of being armed and of an excitation.
enum class FlightMode : uint8_t { Angle = HQ_MODE_ANGLE, Rate = HQ_MODE_RATE };

struct Vec3 {
    float x = 0.0f, y = 0.0f, z = 0.0f;
    float& operator[](int i) { return i == 0 ? x : (i == 1 ? y : z); }
    float operator[](int i) const { return i == 0 ? x : (i == 1 ? y : z); }
};

// Unit quaternion, Hamilton convention, scalar first.
struct Quat {
    float w = 1.0f, x = 0.0f, y = 0.0f, z = 0.0f;
};

// Roll, pitch, yaw in rad (ZYX order).
struct Euler {
    float roll = 0.0f, pitch = 0.0f, yaw = 0.0f;
    float operator[](int i) const { return i == 0 ? roll : (i == 1 ? pitch : yaw); }
};

}  // namespace hq
