#include "controllers.hpp"

namespace hq {

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
