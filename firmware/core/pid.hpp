// PID controller in the ideal (ISA) form of the paper's gain tables (docs/paper.md):
//
//     u = Kc * ( e + (1 / tau_I) * integral(e) dt + tau_D * d/dt(-y_f) )
//
// discretised at the loop's dt with the Tustin (trapezoidal) rule, so the discrete
// controller follows the continuous one to second order in (omega * dt).
//
// - Derivative on measurement (no derivative kick on setpoint steps), filtered by a
//   first-order low-pass of time constant tau_f = tau_D / N (N = derivative_filter_n;
//   Astrom and Hagglund recommend N between 8 and 20).
// - Anti-windup by conditional integration: while the output is saturated, the integral
//   is not allowed to grow further in the direction of the saturation.
// - Integral limit and output limits.
// - The P, I and D terms of the last update are readable for logging.
// - tau_I <= 0 disables the integral (a PD controller, as in the paper's outer loop), and
//   so does a tau_I below kMinTimeConstantS: the parameters never give one (they take 0 or
//   at least the floor), and should a caller do, the integral is off rather than infinite.
//   The derivative is finite for any tau_D >= 0 (its denominator is at least dt).
#pragma once

namespace hq {

// The shortest integral or derivative time the parameters take, s: a fifth of the 5 ms loop
// period. Below it the discrete terms are no longer the continuous PID (the Tustin integral
// adds Kc dt / (2 tau_I) of the error sum per loop, 2.5 Kc at the floor; the derivative
// filter's tau_D / N is a fiftieth of a loop), and at a tiny tau_I (a denormal float)
// Kc dt / (2 tau_I) overflows to infinity and the output to NaN.
constexpr float kMinTimeConstantS = 1e-3f;

struct PidGains {
    float kc = 0.0f;        // proportional gain Kc (output units per error unit)
    float tau_i_s = 0.0f;   // integral time tau_I, s; below kMinTimeConstantS: no integral
    float tau_d_s = 0.0f;   // derivative time tau_D, s; 0 disables the derivative
    float derivative_filter_n = 10.0f;  // N: tau_f = tau_D / N
    float output_min = -1.0f;
    float output_max = 1.0f;
    float integral_limit = 1.0f;        // |I term| is kept at or below this
};

class Pid {
public:
    Pid() = default;
    explicit Pid(const PidGains& gains) : gains_(gains) {}

    // One controller step. dt_s > 0. Returns the limited output.
    float update(float setpoint, float measurement, float dt_s);

    // Forget the integral, the derivative filter and the previous sample.
    void reset();

    void set_gains(const PidGains& gains) { gains_ = gains; }
    const PidGains& gains() const { return gains_; }

    float p_term() const { return p_; }
    float i_term() const { return i_; }
    float d_term() const { return d_; }
    float output() const { return out_; }
    bool saturated() const { return saturated_; }

private:
    PidGains gains_{};
    float p_ = 0.0f, i_ = 0.0f, d_ = 0.0f, out_ = 0.0f;
    float prev_error_ = 0.0f, prev_measurement_ = 0.0f;
    bool have_previous_ = false;
    bool saturated_ = false;
};

}  // namespace hq
