// Excitation for frequency-response experiments (the paper's step 1, docs/paper.md): one
// sine (the paper's dwell) or a multisine, a sum of sines at chosen harmonics of one base
// period (the whole band in one record, docs/method.md).
//
// The (base) period is an integer number N of loop samples, so every period ends exactly where
// it started and the host's FSF sees a perfectly periodic input; the frequency actually used,
// loop_rate / N, is reported. Harmonic h is a_h sin(2 pi ((h k) mod N) / N + phi_h) at loop
// sample k, its phase index kept as an exact integer. The signal fades in and out with a
// raised cosine so the vehicle is not kicked, over fade_cycles cycles of its lowest harmonic
// (whole periods for a sine); the measured periods in between have full amplitude.
//
// A multisine's amplitude is the peak the sender declares for the sum (it chose the phases
// for a low crest factor and knows the peak). The Supervisor bounds that peak like a sine's
// amplitude; every sample is checked against it, and a sample beyond it (with a round-off
// margin) is not output: the excitation stops at once and says so (peak_exceeded()).
//
// A chirp (as ArduPilot's SystemID mode flies one) sweeps from freq_hz to freq_stop_hz over
// sweep_s seconds at full amplitude, logarithmically (the frequency a constant factor per
// second: as many cycles at each octave's start as the record's windows need) or linearly.
// It fades in over fade_cycles cycles held at its start frequency and out over as many
// samples held at the frequency it reached, phase continuous throughout. It is not periodic:
// the host identifies it from its record by the composite of windows. Its frequency is any,
// not an integer period; its phase is kept in cycles in double precision (the frequency is
// integrated sample by sample), so a long sweep stays exact.
//
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
    Motor1 = HQ_INJECTION_MOTOR1,   // to Motor1 + 7: one rotor's thrust command, rotor 0 first
    Motors = HQ_INJECTION_MOTORS,   // every rotor, a multisine's harmonics interleaved
};
constexpr int kInjections = HQ_INJECTION_ENUM_END;
// The amplitude bounds (SafetyLimits::max_amplitude): angle, rate, mixer, and one for every
// motor injection (a thrust fraction).
constexpr int kInjectionBounds = 4;
inline int amplitude_bound(Injection i) {
    return i < Injection::Motor1 ? static_cast<int>(i) : kInjectionBounds - 1;
}
// The rotor a motor injection adds to (0 the central one), kAllRotors for Motors, kNoRotor
// for the injections before the allocation.
constexpr int kNoRotor = -1, kAllRotors = -2;
inline int injected_rotor(Injection i) {
    if (i == Injection::Motors) return kAllRotors;
    return i >= Injection::Motor1 ? static_cast<int>(i) - static_cast<int>(Injection::Motor1)
                                  : kNoRotor;
}

// Where an excitation is in its life (HQ_EXCITATION_STATE).
enum class ExcitationState : uint8_t {
    Idle = HQ_EXCITATION_STATE_IDLE,
    Fading = HQ_EXCITATION_STATE_FADING,
    Running = HQ_EXCITATION_STATE_RUNNING,
};

// The waveform (HQ_SIGNAL).
enum class Signal : uint8_t {
    Sine = HQ_SIGNAL_SINE,
    Multisine = HQ_SIGNAL_MULTISINE,
    Chirp = HQ_SIGNAL_CHIRP,                // logarithmic sweep
    ChirpLinear = HQ_SIGNAL_CHIRP_LINEAR,
};
inline bool is_chirp(Signal s) { return s == Signal::Chirp || s == Signal::ChirpLinear; }

// The most harmonics a multisine has (HQ_EXCITATION's arrays).
constexpr int kMaxHarmonics = 16;

struct Harmonic {
    uint16_t order = 0;            // h: the harmonic of the base period
    float amplitude = 0.0f;        // injection units
    float phase_rad = 0.0f;
};

struct ExcitationConfig {
    Axis axis = Axis::Roll;
    Injection injection = Injection::Mixer;
    // Requested (base) frequency; the nearest integer-period frequency is used.
    float freq_hz = 1.0f;
    // Injection units: rad (angle), rad/s (rate), normalised (mixer), thrust fraction (motor).
    // A sine's amplitude; a multisine's declared peak (for Motors: of each rotor's own sum).
    float amplitude = 0.0f;
    uint16_t cycles = 10;          // full-amplitude (base) periods
    uint16_t fade_cycles = 1;      // cycles of the lowest harmonic of fade in, and again out
    Signal signal = Signal::Sine;
    uint8_t harmonics = 0;         // multisine: how many of harmonic[] are used
    Harmonic harmonic[kMaxHarmonics] = {};
    // Chirp: the frequency the sweep ends at (freq_hz is where it starts; either may be the
    // higher) and the sweep's length at full amplitude, s. cycles must be 1 (one sweep).
    float freq_stop_hz = 0.0f;
    float sweep_s = 0.0f;
};

// The multisine's own checks (not the safety bounds): 1..kMaxHarmonics harmonics, strictly
// increasing orders from 1, each with at least four samples per cycle of a period_samples
// base period, finite positive amplitudes, finite phases, and a declared peak no lower than
// the sum's RMS (no signal is below its RMS everywhere). A sine passes trivially.
bool harmonics_valid(const ExcitationConfig& config, uint32_t period_samples);
// The length of each fade for a base period of period_samples: fade_cycles whole cycles of
// the lowest harmonic, rounded up to a sample (whole periods for a sine).
uint64_t fade_samples_for(const ExcitationConfig& config, uint32_t period_samples);
// The lowest and highest harmonic order (1 and 1 for a sine and a chirp).
uint16_t lowest_order(const ExcitationConfig& config);
uint16_t highest_order(const ExcitationConfig& config);
// The lowest and highest frequency excited, Hz, as requested: a sine's, a multisine's lowest
// and highest harmonic of freq_hz, a chirp's two ends.
float lowest_freq_hz(const ExcitationConfig& config);
float highest_freq_hz(const ExcitationConfig& config);
// A chirp's own checks (true for the other signals): both ends finite and positive and not
// equal, the sweep's length finite and positive, cycles 1, a fade of at least one cycle, and
// its sweep's and fades' samples within their counters at loop_rate_hz.
bool chirp_valid(const ExcitationConfig& config, float loop_rate_hz);
// A chirp's full-amplitude samples at loop_rate_hz (0 for the other signals).
uint64_t sweep_samples_for(const ExcitationConfig& config, float loop_rate_hz);
// Each of a chirp's fades in samples at loop_rate_hz: fade_cycles whole cycles of its lower
// end, each rounded up to a sample (0 for the other signals, or a cycle beyond
// Excitation::kMaxPeriodSamples). The generator and the Supervisor's cap use this one count.
uint64_t chirp_fade_samples_for(const ExcitationConfig& config, float loop_rate_hz);

class Excitation {
public:
    // Arms the excitation; returns false (and stays idle) for an impossible request:
    // frequency not in (0, loop_rate/4], a period longer than kMaxPeriodSamples, no cycles,
    // a total length that does not fit the sample counter, a non-finite amplitude, or
    // harmonics that fail harmonics_valid().
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

    // The value for this loop sample, then advance; idle after the last one. 0 when idle,
    // and 0 (and idle, peak_exceeded()) for a sample beyond the declared peak. With `groups`
    // > 0 (a multisine), harmonic i's part also goes to per_group[i % groups], and the declared
    // peak bounds each group's sum instead of the whole (Injection::Motors).
    float next(float* per_group = nullptr, int groups = 0);

    bool active() const { return active_; }
    const ExcitationConfig& config() const { return config_; }
    uint32_t period_samples() const { return period_; }
    float actual_freq_hz() const { return actual_freq_hz_; }
    // The frequency of the sample the next call to next() returns: a chirp's instantaneous
    // one, the used frequency of the others; 0 when idle.
    float frequency_hz() const;
    // The frequency of the sample the last call to next() returned (ArduPilot's SIDD.F: a
    // chirp's instantaneous one, the used frequency of the others).
    float output_frequency_hz() const { return is_chirp(config_.signal) ? output_hz_ : actual_freq_hz_; }
    uint32_t sample() const { return k_; }
    uint32_t total_samples() const { return total_; }
    uint32_t fade_samples() const { return fade_; }
    // True when the last start ended because a sample passed the declared peak.
    bool peak_exceeded() const { return peak_exceeded_; }
    // Of the sample the next call to next() returns: true in the full-amplitude cycles
    // (between the fades); the state (idle, fading or running).
    bool measuring() const;
    ExcitationState state() const;

    // The phase is computed as (k mod N) / N in float, exact while N <= 2^24.
    static constexpr uint32_t kMaxPeriodSamples = 1u << 24;
    // Whole excitations stay well inside the 32-bit sample counter.
    static constexpr uint64_t kMaxTotalSamples = 1ull << 31;
    // Round-off allowed above a declared peak: the sender computes it in double, the
    // firmware the signal in float (sinf is accurate to a few ulp).
    static constexpr float kPeakMargin = 1e-3f;

private:
    ExcitationConfig config_{};
    bool active_ = false, peak_exceeded_ = false;
    uint32_t period_ = 0, total_ = 0, k_ = 0, fade_ = 0;
    uint32_t index_[kMaxHarmonics] = {};     // (order * k) mod period, per harmonic
    float actual_freq_hz_ = 0.0f;
    // A chirp: the loop rate, its phase in cycles (in [0, 1)), and the frequency its
    // fade-out holds (the stop frequency, or the one reached when finished early).
    float loop_rate_hz_ = 0.0f, hold_hz_ = 0.0f, output_hz_ = 0.0f;
    double phase_cycles_ = 0.0;
    float chirp_value(float envelope);
};

}  // namespace hq
