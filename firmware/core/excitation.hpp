// Sine excitation for frequency-response experiments (SPEC.md step 1).
//
// The period is an integer number N of loop samples, so every period ends exactly where it
// started and the host's FSF sees a perfectly periodic input; the frequency actually used,
// loop_rate / N, is reported. The sine fades in and out over whole periods with a raised
// cosine so the vehicle is not kicked; the measured cycles in between have full amplitude.
// Injection points follow ArduPilot's SID_AXIS idea: the signal is added at the angle
// setpoint, the rate setpoint, or the mixer's torque input of one axis.
#pragma once

#include <cstdint>

#include "types.hpp"

namespace hq {

enum class Injection : uint8_t { Angle = 0, Rate = 1, Mixer = 2 };

struct ExcitationConfig {
    Axis axis = Axis::Roll;
    Injection injection = Injection::Mixer;
    float freq_hz = 1.0f;          // requested; the nearest integer-period frequency is used
    float amplitude = 0.0f;        // injection units: rad (angle), rad/s (rate), normalised (mixer)
    uint16_t cycles = 10;          // full-amplitude cycles
    uint16_t fade_cycles = 1;      // cycles of fade in, and again of fade out
};

class Excitation {
public:
    // Arms the excitation; returns false (and stays idle) for an impossible request:
    // frequency not in (0, loop_rate/4], no cycles, or a non-finite amplitude.
    bool start(const ExcitationConfig& config, float loop_rate_hz);
    void stop();

    // The value for this loop sample, then advance. 0 when idle or finished.
    float next();

    bool active() const { return active_; }
    const ExcitationConfig& config() const { return config_; }
    uint32_t period_samples() const { return period_; }
    float actual_freq_hz() const { return actual_freq_hz_; }
    uint32_t sample() const { return k_; }
    uint32_t total_samples() const { return total_; }
    // True while in the full-amplitude cycles (between the fades).
    bool measuring() const;

private:
    ExcitationConfig config_{};
    bool active_ = false;
    uint32_t period_ = 0, total_ = 0, k_ = 0;
    float actual_freq_hz_ = 0.0f;
};

}  // namespace hq
