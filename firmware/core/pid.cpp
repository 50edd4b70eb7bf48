#include "pid.hpp"

namespace hq {

namespace {
float clamp(float x, float lo, float hi) { return x < lo ? lo : (x > hi ? hi : x); }
}  // namespace

void Pid::reset() {
    p_ = i_ = d_ = out_ = 0.0f;
    prev_error_ = prev_measurement_ = 0.0f;
    have_previous_ = false;
    saturated_ = false;
}

float Pid::update(float setpoint, float measurement, float dt_s) {
    const float error = setpoint - measurement;
    if (!have_previous_) {            // first sample: no history, so no derivative kick
        prev_error_ = error;
        prev_measurement_ = measurement;
        have_previous_ = true;
    }
    p_ = gains_.kc * error;

    // Derivative of -measurement through 1 / (tau_f s + 1), Tustin:
    // d_k = a d_{k-1} - b (y_k - y_{k-1}), a = (2 tau_f - dt) / (2 tau_f + dt),
    // b = 2 Kc tau_D / (2 tau_f + dt).
    if (gains_.tau_d_s > 0.0f) {
        const float tau_f = gains_.tau_d_s / gains_.derivative_filter_n;
        const float den = 2.0f * tau_f + dt_s;
        d_ = ((2.0f * tau_f - dt_s) / den) * d_
             - (2.0f * gains_.kc * gains_.tau_d_s / den) * (measurement - prev_measurement_);
    } else {
        d_ = 0.0f;
    }

    // Integral, trapezoidal; held while saturated in the direction it would grow.
    float i_next = i_;
    if (gains_.tau_i_s >= kMinTimeConstantS) {         // below the floor: off, never infinite
        i_next = i_ + gains_.kc * dt_s / (2.0f * gains_.tau_i_s) * (error + prev_error_);
        i_next = clamp(i_next, -gains_.integral_limit, gains_.integral_limit);
    } else {
        i_next = 0.0f;
    }
    const float unlimited = p_ + i_next + d_;
    const bool high = unlimited > gains_.output_max;
    const bool low = unlimited < gains_.output_min;
    if ((high && i_next > i_) || (low && i_next < i_)) {
        i_next = i_;                  // conditional integration: do not wind up
    }
    i_ = i_next;
    const float raw = p_ + i_ + d_;
    out_ = clamp(raw, gains_.output_min, gains_.output_max);
    saturated_ = (raw != out_);
    prev_error_ = error;
    prev_measurement_ = measurement;
    return out_;
}

}  // namespace hq
