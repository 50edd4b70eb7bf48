#include "mixer.hpp"

#include <cmath>

namespace hq {

namespace {
float clamp(float x, float lo, float hi) { return x < lo ? lo : (x > hi ? hi : x); }
float fabs_(float x) { return x < 0.0f ? -x : x; }
constexpr float kDegToRad = 0.017453292519943295f;
}  // namespace

Mixer::Mixer(const MixerGeometry& geometry) : g_(geometry) {
    cos_d_ = std::cos(g_.cant_deg * kDegToRad);
    sin_d_ = std::sin(g_.cant_deg * kDegToRad);
    sign_c0_ = g_.central_torque_per_thrust_m >= 0.0f ? 1.0f : -1.0f;
    lat_ = sign_c0_ * 4.0f * g_.arm_length_m * sin_d_;        // yaw moment per N of T_a
    det_ = -lat_ - 4.0f * cos_d_ * g_.central_torque_per_thrust_m;
    fz_max_ = g_.central_max_thrust_n + 4.0f * cos_d_ * g_.arm_max_thrust_n;
    // Mean arm thrust at hover (Fz = weight, no yaw moment): second row of the 2 x 2 solve.
    ta_hover_ = (-g_.central_torque_per_thrust_m * g_.hover_thrust_n) / det_;
    txy_unit_ = g_.arm_length_m * cos_d_ * 2.0f * ta_hover_;
    tz_unit_ = fabs_(lat_) * ta_hover_;
}

MixerOutput Mixer::mix(const MixerCommand& cmd) const {
    MixerOutput out;
    const float ta_max = g_.arm_max_thrust_n;
    const float t0_max = g_.central_max_thrust_n;
    const float c0 = g_.central_torque_per_thrust_m;
    const float lat = lat_;

    // 1. Roll and pitch: differential arm thrust, each at most the full arm thrust.
    const float unit = 2.0f * ta_hover_;                     // Dx per unit of roll command
    const float dx = clamp(-cmd.roll * unit, -ta_max, ta_max);
    const float dy = clamp(cmd.pitch * unit, -ta_max, ta_max);
    out.torque_limited = dx != -cmd.roll * unit || dy != cmd.pitch * unit;

    // 2. Collective and yaw: solve [1, 4 cos d; c0, -lat] [T0; Ta] = [Fz; tau_z].
    const float fz = clamp(cmd.collective, 0.0f, 1.0f) * fz_max_;
    const float tz = cmd.yaw * tz_unit_;
    float t0 = (-lat * fz - 4.0f * cos_d_ * tz) / det_;
    float ta = (tz - c0 * fz) / det_;
    out.collective_limited = fz != cmd.collective * fz_max_;

    // 3. Arms must hold the differential: T_a within [h, Ta_max - h].
    const float h = 0.5f * (fabs_(dx) > fabs_(dy) ? fabs_(dx) : fabs_(dy));
    const float ta_lo = h, ta_hi = ta_max - h;
    if (ta < ta_lo || ta > ta_hi) {
        ta = clamp(ta, ta_lo, ta_hi);
        t0 = (tz + lat * ta) / c0;           // keep yaw with the central rotor ...
        out.collective_limited = true;       // ... the vertical thrust gives way
    }
    if (t0 < 0.0f || t0 > t0_max) {          // ... unless it cannot: then yaw gives way too
        t0 = clamp(t0, 0.0f, t0_max);
        const float ta_yaw = (c0 * t0 - tz) / lat;
        ta = clamp(ta_yaw, ta_lo, ta_hi);
        out.collective_limited = true;
        out.torque_limited = out.torque_limited || ta != ta_yaw;
    }
    out.saturated = out.torque_limited || out.collective_limited;

    out.motor[0] = t0 / t0_max;
    out.motor[1] = (ta + 0.5f * dy) / ta_max;
    out.motor[2] = (ta + 0.5f * dx) / ta_max;
    out.motor[3] = (ta - 0.5f * dy) / ta_max;
    out.motor[4] = (ta - 0.5f * dx) / ta_max;
    for (float& m : out.motor) m = clamp(m, 0.0f, 1.0f);   // round-off only
    return out;
}

MixerCommand Mixer::achieved(const float motor[kMotors]) const {
    const float ta_max = g_.arm_max_thrust_n;
    const float t0 = motor[0] * g_.central_max_thrust_n;
    float t[4];
    for (int i = 0; i < 4; ++i) t[i] = motor[i + 1] * ta_max;
    const float ta = 0.25f * (t[0] + t[1] + t[2] + t[3]);
    MixerCommand c;
    c.collective = (t0 + 4.0f * cos_d_ * ta) / fz_max_;
    c.roll = -g_.arm_length_m * cos_d_ * (t[1] - t[3]) / txy_unit_;
    c.pitch = g_.arm_length_m * cos_d_ * (t[0] - t[2]) / txy_unit_;
    c.yaw = (g_.central_torque_per_thrust_m * t0 - lat_ * ta) / tz_unit_;
    return c;
}

}  // namespace hq
