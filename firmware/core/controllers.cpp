#include "controllers.hpp"

namespace hq {

CascadeGains CascadeGains::paper_defaults() {
    CascadeGains g;
    // Inner loop: Kc, tau_I, tau_D (the paper's rate-loop gains, docs/paper.md).
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
    // Outer loop: Kc, tau_D (the paper's angle-loop gains, docs/paper.md); PD, no integral.
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

AttitudeController::AttitudeController(const CascadeGains& gains)
    : pid_{Pid(gains.angle[0]), Pid(gains.angle[1])} {}

Vec3 AttitudeController::update(const Euler& setpoint, const Euler& measured, float dt_s) {
    Vec3 rate_sp;
    rate_sp.x = pid_[0].update(setpoint.roll, measured.roll, dt_s);
    rate_sp.y = pid_[1].update(setpoint.pitch, measured.pitch, dt_s);
    rate_sp.z = 0.0f;
    return rate_sp;
}

void AttitudeController::reset() {
    for (auto& p : pid_) p.reset();
}

void AttitudeController::set_gains(const CascadeGains& gains) {
    for (int a = 0; a < kAngleAxes; ++a) pid_[a].set_gains(gains.angle[a]);
}

void RateController::set_gains(const CascadeGains& gains) {
    for (int a = 0; a < kAxes; ++a) pid_[a].set_gains(gains.rate[a]);
}

RateController::RateController(const CascadeGains& gains)
    : pid_{Pid(gains.rate[0]), Pid(gains.rate[1]), Pid(gains.rate[2])} {}

Vec3 RateController::update(const Vec3& setpoint, const Vec3& measured, float dt_s) {
    Vec3 torque;
    for (int a = 0; a < kAxes; ++a) torque[a] = pid_[a].update(setpoint[a], measured[a], dt_s);
    return torque;
}

void RateController::reset() {
    for (auto& p : pid_) p.reset();
}

namespace {
float clampf(float x, float lo, float hi) { return x < lo ? lo : (x > hi ? hi : x); }
}  // namespace

CascadeOutput Cascade::update(const CascadeInput& in) {
    CascadeOutput out;
    const int a = static_cast<int>(in.axis);
    out.angle_sp = Euler{in.angle_stick.roll, in.angle_stick.pitch, in.attitude.yaw};
    if (in.injection == Injection::Angle && a < kAngleAxes) {
        (a == 0 ? out.angle_sp.roll : out.angle_sp.pitch) += in.excitation;
    }
    out.angle_sp.roll = clampf(out.angle_sp.roll, -kMaxAngleSetpointRad, kMaxAngleSetpointRad);
    out.angle_sp.pitch = clampf(out.angle_sp.pitch, -kMaxAngleSetpointRad, kMaxAngleSetpointRad);
    out.rate_sp = in.rate_stick;
    if (in.mode == FlightMode::Angle) {
        const Vec3 outer = attitude_.update(out.angle_sp, in.attitude, in.dt_s);
        out.rate_sp.x = outer.x;
        out.rate_sp.y = outer.y;
    }
    if (in.injection == Injection::Rate && a < kAxes) out.rate_sp[a] += in.excitation;
    out.torque = rate_.update(out.rate_sp, in.rate, in.dt_s);
    if (in.injection == Injection::Mixer && a < kAxes) out.torque[a] += in.excitation;
    return out;
}

void Cascade::reset() {
    attitude_.reset();
    rate_.reset();
}

void Cascade::set_gains(const CascadeGains& gains) {
    attitude_.set_gains(gains);
    rate_.set_gains(gains);
}

}  // namespace hq
