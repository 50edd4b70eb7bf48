// Sine excitation for frequency-response experiments (the paper's step 1, docs/paper.md).
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

// Where an excitation is added (HQ_INJECTION).
enum class Injection : uint8_t {
    Angle = HQ_INJECTION_ANGLE,
    Rate = HQ_INJECTION_RATE,
    Mixer = HQ_INJECTION_MIXER,
};
constexpr int kInjections = HQ_INJECTION_ENUM_END;

// Where an excitation is in its life (HQ_EXCITATION_STATE).
enum class ExcitationState : uint8_t {
    Idle = HQ_EXCITATION_STATE_IDLE,
    Fading = HQ_EXCITATION_STATE_FADING,
    Running = HQ_EXCITATION_STATE_RUNNING,
};

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
    // frequency not in (0, loop_rate/4], a period longer than kMaxPeriodSamples, no cycles,
    // a total length that does not fit the sample counter, or a non-finite amplitude.
    // This is the signal generator's own guard; the safety bounds (amplitude, band,
    // duration, fade-in) are the Supervisor's (supervisor.hpp).
    bool start(const ExcitationConfig& config, float loop_rate_hz);
    void stop();
    // Ends the excitation in order, earlier than planned: the full-amplitude cycle under way
    // completes (at least one, when called during the fade-in), then the fade-out runs as at
    // the planned end, so the vehicle is not kicked. config().cycles and total_samples()
    // become what will have run; a finish during the fade-out changes nothing. False when
    // idle.
    bool finish();

    // The value for this loop sample, then advance; idle after the last one. 0 when idle.
    float next();

    bool active() const { return active_; }
    const ExcitationConfig& config() const { return config_; }
    uint32_t period_samples() const { return period_; }
    float actual_freq_hz() const { return actual_freq_hz_; }
    uint32_t sample() const { return k_; }
    uint32_t total_samples() const { return total_; }
    // Of the sample the next call to next() returns: true in the full-amplitude cycles
    // (between the fades); the state (idle, fading or running).
    bool measuring() const;
    ExcitationState state() const;

    // The phase is computed as (k mod N) / N in float, exact while N <= 2^24.
    static constexpr uint32_t kMaxPeriodSamples = 1u << 24;
    // Whole excitations stay well inside the 32-bit sample counter.
    static constexpr uint64_t kMaxTotalSamples = 1ull << 31;

private:
    ExcitationConfig config_{};
    bool active_ = false;
    uint32_t period_ = 0, total_ = 0, k_ = 0;
    float actual_freq_hz_ = 0.0f;
};

}  // namespace hq
