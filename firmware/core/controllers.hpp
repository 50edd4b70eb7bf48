// The cascade of SPEC.md step 4: an outer PD loop on roll and pitch angle gives rate
// setpoints; an inner PID loop on the body rates p, q, r gives normalised torque commands
// (fraction of each axis's authority, -1..1, see mixer.hpp). Yaw is rate-only.
// Default gains are the paper's auto-tuned values (SPEC.md tables; Drones 2022, 6(10), 309).
#pragma once

#include "pid.hpp"
#include "types.hpp"

namespace hq {

struct CascadeGains {
    PidGains rate[kAxes];      // inner loop, rad/s in, normalised torque out
    PidGains angle[2];         // outer loop (roll, pitch), rad in, rad/s out
    static CascadeGains paper_defaults();
};

// Largest rate setpoint the angle loop may ask for, rad/s (400 deg/s).
constexpr float kMaxRateSetpoint = 6.9813f;

class AttitudeController {
public:
    explicit AttitudeController(const CascadeGains& gains);
    // Angle setpoints and measured angles (rad) -> roll and pitch rate setpoints (rad/s).
    Vec3 update(const Euler& setpoint, const Euler& measured, float dt_s);
    void reset();
    const Pid& loop(Axis axis) const { return pid_[static_cast<int>(axis)]; }

private:
    Pid pid_[2];
};

class RateController {
public:
    explicit RateController(const CascadeGains& gains);
    // Rate setpoints and measured body rates (rad/s) -> normalised torque commands.
    Vec3 update(const Vec3& setpoint, const Vec3& measured, float dt_s);
    void reset();
    const Pid& loop(Axis axis) const { return pid_[static_cast<int>(axis)]; }

private:
    Pid pid_[kAxes];
};

}  // namespace hq
