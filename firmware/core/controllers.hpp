// The cascade of the paper's step 4 (docs/paper.md): an outer PD loop on roll and pitch
// angle gives rate setpoints; an inner PID loop on the body rates p, q, r gives normalised
// torque commands (fraction of each axis's authority, -1..1, see mixer.hpp). Yaw is
// rate-only. Default gains are the paper's auto-tuned values (Hoshu et al., Drones 2022,
// 6(10), 309; docs/paper.md).
#pragma once

#include "excitation.hpp"
#include "pid.hpp"
#include "types.hpp"

namespace hq {

// Largest rate setpoint the angle loop may ask for, rad/s (400 deg/s).
constexpr float kMaxRateSetpoint = 6.9813f;

struct CascadeGains {
    PidGains rate[kAxes];           // inner loop, rad/s in, normalised torque out
    PidGains angle[kAngleAxes];     // outer loop (roll, pitch), rad in, rad/s out
    // The paper's gains (docs/paper.md); constexpr, so the parameters' defaults are constants.
    static constexpr CascadeGains paper_defaults() {
        CascadeGains g;
        // Inner loop: Kc, tau_I, tau_D (the paper's rate-loop gains).
        const float rate[kAxes][3] = {{2.422f, 0.439f, 0.051f},
                                      {2.386f, 0.439f, 0.048f},
                                      {7.393f, 0.397f, 0.043f}};
        for (int a = 0; a < kAxes; ++a) {
            g.rate[a].kc = rate[a][0];
            g.rate[a].tau_i_s = rate[a][1];
            g.rate[a].tau_d_s = rate[a][2];
            g.rate[a].output_min = -1.0f;
            g.rate[a].output_max = 1.0f;
            g.rate[a].integral_limit = 0.5f;
        }
        // Outer loop: Kc, tau_D (the paper's angle-loop gains); PD, no integral.
        const float angle[kAngleAxes][2] = {{1.488f, 0.107f}, {1.501f, 0.106f}};
        for (int a = 0; a < kAngleAxes; ++a) {
            g.angle[a].kc = angle[a][0];
            g.angle[a].tau_i_s = 0.0f;
            g.angle[a].tau_d_s = angle[a][1];
            g.angle[a].output_min = -kMaxRateSetpoint;
            g.angle[a].output_max = kMaxRateSetpoint;
            g.angle[a].integral_limit = 0.0f;
        }
        return g;
    }
};

// Angle setpoints (sticks plus an angle-injection excitation) are clamped here: 80 deg.
constexpr float kMaxAngleSetpointRad = 1.3962634f;

class AttitudeController {
public:
    explicit AttitudeController(const CascadeGains& gains);
    // Angle setpoints and measured angles (rad) -> roll and pitch rate setpoints (rad/s).
    Vec3 update(const Euler& setpoint, const Euler& measured, float dt_s);
    void reset();
    void set_gains(const CascadeGains& gains);
    // The loop of roll or pitch; nullptr for yaw, which has no angle loop.
    const Pid* loop(Axis axis) const {
        const int a = static_cast<int>(axis);
        return a < kAngleAxes ? &pid_[a] : nullptr;
    }

private:
    Pid pid_[kAngleAxes];
};

class RateController {
public:
    explicit RateController(const CascadeGains& gains);
    // Rate setpoints and measured body rates (rad/s) -> normalised torque commands.
    Vec3 update(const Vec3& setpoint, const Vec3& measured, float dt_s);
    void reset();
    void set_gains(const CascadeGains& gains);
    const Pid* loop(Axis axis) const {
        const int a = static_cast<int>(axis);
        return a < kAxes ? &pid_[a] : nullptr;
    }

private:
    Pid pid_[kAxes];
};

// One pass of the whole cascade with an excitation added at its injection point, as the
// flight loop runs it (PX4-style: a plain class, update() in, setpoints and torque out).
// Angle mode: the sticks give roll and pitch angle setpoints (plus an angle-injection
// excitation, clamped to kMaxAngleSetpointRad), the angle loop turns them into rate
// setpoints, the sticks give the yaw rate. Rate mode: the sticks give all three rates and the
// angle loop does not run. Then a rate-injection excitation is added to the axis's rate
// setpoint, the rate loop gives torques, and a mixer-injection excitation is added to the
// axis's torque.
struct CascadeInput {
    FlightMode mode = FlightMode::Angle;
    Euler angle_stick{};            // rad (roll, pitch)
    Vec3 rate_stick{};              // rad/s
    Axis axis = Axis::Roll;         // the excitation's axis and injection point
    Injection injection = Injection::Mixer;
    float excitation = 0.0f;        // this loop's value, in the injection point's units
    Euler attitude{};               // measured
    Vec3 rate{};                    // measured
    float dt_s = 0.005f;
};

struct CascadeOutput {
    Euler angle_sp{};               // roll, pitch after injection and clamp (yaw: measured)
    Vec3 rate_sp{};                 // after injection
    Vec3 torque{};                  // normalised, after injection
};

class Cascade {
public:
    explicit Cascade(const CascadeGains& gains) : attitude_(gains), rate_(gains) {}
    CascadeOutput update(const CascadeInput& in);
    void reset();
    // New gains; each loop keeps its state (the integral term is in output units, so the
    // change is bumpless).
    void set_gains(const CascadeGains& gains);
    const AttitudeController& attitude() const { return attitude_; }
    const RateController& rate() const { return rate_; }

private:
    AttitudeController attitude_;
    RateController rate_;
};

}  // namespace hq
