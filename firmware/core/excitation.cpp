#include "excitation.hpp"

#include <cmath>

namespace hq {

namespace {
constexpr float kTwoPi = 6.283185307179586f;
// At least four samples per period: a sine needs more than two (Nyquist), and the FSF's
// harmonics are meaningless much closer to it.
constexpr float kMinSamplesPerPeriod = 4.0f;
constexpr uint32_t kMinSamplesPerCycle = 4;

float raised_cosine(uint32_t i, uint32_t length) {
    if (length == 0) return 0.0f;             // no fade: nothing to ramp (and no 0/0)
    return 0.5f * (1.0f - std::cos(kTwoPi * 0.5f * static_cast<float>(i) / static_cast<float>(length)));
}
}  // namespace

uint16_t lowest_order(const ExcitationConfig& c) {
    return c.signal == Signal::Multisine && c.harmonics > 0 ? c.harmonic[0].order : 1;
}

uint16_t highest_order(const ExcitationConfig& c) {
    return c.signal == Signal::Multisine && c.harmonics > 0 ? c.harmonic[c.harmonics - 1].order : 1;
}

float lowest_freq_hz(const ExcitationConfig& c) {
    if (is_chirp(c.signal)) return std::fmin(c.freq_hz, c.freq_stop_hz);
    return c.freq_hz * static_cast<float>(lowest_order(c));
}

float highest_freq_hz(const ExcitationConfig& c) {
    if (is_chirp(c.signal)) return std::fmax(c.freq_hz, c.freq_stop_hz);
    return c.freq_hz * static_cast<float>(highest_order(c));
}

uint64_t sweep_samples_for(const ExcitationConfig& c, float loop_rate_hz) {
    if (!is_chirp(c.signal)) return 0;
    const double samples = static_cast<double>(c.sweep_s) * static_cast<double>(loop_rate_hz);
    return samples >= 1.0 && samples <= static_cast<double>(Excitation::kMaxTotalSamples)
               ? static_cast<uint64_t>(std::llround(samples))
               : 0;
}

uint64_t chirp_fade_samples_for(const ExcitationConfig& c, float loop_rate_hz) {
    if (!is_chirp(c.signal)) return 0;
    // In double: the same samples for the Supervisor's cap and for the generator.
    const double cycle = std::ceil(static_cast<double>(loop_rate_hz) /
                                   static_cast<double>(lowest_freq_hz(c)));
    if (!(cycle >= 1.0 && cycle <= static_cast<double>(Excitation::kMaxPeriodSamples))) return 0;
    return uint64_t{c.fade_cycles} * static_cast<uint64_t>(cycle);
}

bool chirp_valid(const ExcitationConfig& c, float loop_rate_hz) {
    if (!is_chirp(c.signal)) return true;
    return std::isfinite(c.freq_stop_hz) && c.freq_stop_hz > 0.0f && c.freq_stop_hz != c.freq_hz &&
           std::isfinite(c.sweep_s) && c.sweep_s > 0.0f && c.cycles == 1 && c.fade_cycles > 0 &&
           sweep_samples_for(c, loop_rate_hz) > 0 && chirp_fade_samples_for(c, loop_rate_hz) > 0;
}

uint64_t fade_samples_for(const ExcitationConfig& c, uint32_t period_samples) {
    const uint32_t lowest = lowest_order(c);
    return uint64_t{c.fade_cycles} * ((period_samples + lowest - 1u) / lowest);
}

bool harmonics_valid(const ExcitationConfig& c, uint32_t period_samples) {
    if (c.signal == Signal::Sine || is_chirp(c.signal)) return true;
    if (c.signal != Signal::Multisine || c.harmonics == 0 || c.harmonics > kMaxHarmonics) return false;
    float power = 0.0f;
    uint32_t previous = 0;
    for (int i = 0; i < c.harmonics; ++i) {
        const Harmonic& h = c.harmonic[i];
        if (h.order <= previous || uint64_t{h.order} * kMinSamplesPerCycle > period_samples ||
            !(std::isfinite(h.amplitude) && h.amplitude > 0.0f) || !std::isfinite(h.phase_rad)) {
            return false;
        }
        previous = h.order;
        power += 0.5f * h.amplitude * h.amplitude;
    }
    // The peak of a signal is at least its RMS.
    return std::isfinite(power) && c.amplitude * c.amplitude >= power * (1.0f - Excitation::kPeakMargin);
}

bool Excitation::start(const ExcitationConfig& config, float loop_rate_hz) {
    active_ = false;
    peak_exceeded_ = false;
    if (!(config.freq_hz > 0.0f) || !(loop_rate_hz > 0.0f) || !std::isfinite(loop_rate_hz) ||
        config.freq_hz * kMinSamplesPerPeriod > loop_rate_hz || config.cycles == 0 ||
        !std::isfinite(config.amplitude)) {
        return false;
    }
    // In double: a tiny frequency must be refused, not wrapped into a short period.
    const double samples = static_cast<double>(loop_rate_hz) / static_cast<double>(config.freq_hz);
    if (!(samples <= static_cast<double>(kMaxPeriodSamples))) return false;
    const uint32_t period = static_cast<uint32_t>(std::llround(samples));
    if (!harmonics_valid(config, period) || !chirp_valid(config, loop_rate_hz)) return false;
    if (is_chirp(config.signal) && config.freq_stop_hz * kMinSamplesPerPeriod > loop_rate_hz) {
        return false;
    }
    // A chirp fades over whole cycles of its lower end (so both fades hold at least
    // fade_cycles cycles of the frequency they hold); its full-amplitude part is the sweep.
    const uint64_t fade = is_chirp(config.signal) ? chirp_fade_samples_for(config, loop_rate_hz)
                                                  : fade_samples_for(config, period);
    const uint64_t middle = is_chirp(config.signal) ? sweep_samples_for(config, loop_rate_hz)
                                                    : uint64_t{period} * config.cycles;
    const uint64_t total = middle + 2u * fade;
    if (total > kMaxTotalSamples) return false;
    config_ = config;
    if (config_.signal == Signal::Sine) {          // one harmonic: the fundamental
        config_.harmonics = 1;
        config_.harmonic[0] = Harmonic{1, config.amplitude, 0.0f};
    }
    period_ = period;
    // A chirp's frequencies are as requested (it has no period to round to).
    actual_freq_hz_ = is_chirp(config.signal) ? config.freq_hz
                                              : loop_rate_hz / static_cast<float>(period_);
    loop_rate_hz_ = loop_rate_hz;
    hold_hz_ = config.freq_stop_hz;
    phase_cycles_ = 0.0;
    total_ = static_cast<uint32_t>(total);
    fade_ = static_cast<uint32_t>(fade);
    k_ = 0;
    for (uint32_t& index : index_) index = 0;
    active_ = true;
    return true;
}

void Excitation::stop() { active_ = false; }

bool Excitation::finish() {
    if (!active_) return false;
    if (is_chirp(config_.signal)) {       // fade out from here, at the frequency reached
        if (k_ < total_ - fade_) {
            hold_hz_ = frequency_hz();
            total_ = (k_ < fade_ ? fade_ : k_) + fade_;
        }
        return true;
    }
    // Whole full-amplitude periods once the one under way ends (k_ is the next sample).
    const uint32_t cycles = k_ <= fade_ ? 1u : (k_ - fade_ + period_ - 1u) / period_;
    const uint64_t total = uint64_t{period_} * cycles + 2u * uint64_t{fade_};
    if (total < total_) {
        total_ = static_cast<uint32_t>(total);
        config_.cycles = static_cast<uint16_t>(cycles);
    }
    return true;
}

float Excitation::frequency_hz() const {
    if (!active_) return 0.0f;
    if (!is_chirp(config_.signal)) return actual_freq_hz_;
    if (k_ < fade_) return config_.freq_hz;
    if (k_ >= total_ - fade_) return hold_hz_;
    const float into = static_cast<float>(k_ - fade_) / loop_rate_hz_ / config_.sweep_s;
    if (config_.signal == Signal::ChirpLinear) {
        return config_.freq_hz + (config_.freq_stop_hz - config_.freq_hz) * into;
    }
    return config_.freq_hz * std::exp(std::log(config_.freq_stop_hz / config_.freq_hz) * into);
}

// The chirp's sample: the envelope times the sine of its phase, then the phase advanced by
// this sample's frequency (phase continuous, in double so that no cycles are lost).
float Excitation::chirp_value(float envelope) {
    const float value = config_.amplitude * envelope *
                        std::sin(kTwoPi * static_cast<float>(phase_cycles_));
    output_hz_ = frequency_hz();
    phase_cycles_ += static_cast<double>(output_hz_) / static_cast<double>(loop_rate_hz_);
    phase_cycles_ -= std::floor(phase_cycles_);
    return value;
}

bool Excitation::measuring() const {
    return active_ && k_ >= fade_ && k_ < total_ - fade_;
}

ExcitationState Excitation::state() const {
    if (!active_) return ExcitationState::Idle;
    return measuring() ? ExcitationState::Running : ExcitationState::Fading;
}

float Excitation::next(float* per_group, int groups) {
    if (!active_) return 0.0f;
    float envelope = 1.0f;
    if (k_ < fade_) {
        envelope = raised_cosine(k_, fade_);
    } else if (k_ >= total_ - fade_) {
        envelope = raised_cosine(total_ - k_, fade_);
    }
    const float n = static_cast<float>(period_);
    float value;
    if (is_chirp(config_.signal)) {
        value = chirp_value(envelope);
    } else if (config_.signal == Signal::Sine) {
        value = config_.amplitude * envelope * std::sin(kTwoPi * static_cast<float>(index_[0]) / n);
    } else {
        float sum = 0.0f;
        for (int g = 0; g < groups; ++g) per_group[g] = 0.0f;
        for (int i = 0; i < config_.harmonics; ++i) {
            const Harmonic& h = config_.harmonic[i];
            const float part =
                h.amplitude * std::sin(kTwoPi * static_cast<float>(index_[i]) / n + h.phase_rad);
            sum += part;
            if (groups > 0) per_group[i % groups] += part;
        }
        bool over = !(std::fabs(sum) <= config_.amplitude * (1.0f + kPeakMargin));
        if (groups > 0) {
            over = false;
            for (int g = 0; g < groups; ++g) {
                over = over || !(std::fabs(per_group[g]) <= config_.amplitude * (1.0f + kPeakMargin));
                per_group[g] *= envelope;
            }
        }
        if (over) {
            peak_exceeded_ = true;                // not output: stop at once
            active_ = false;
            for (int g = 0; g < groups; ++g) per_group[g] = 0.0f;
            return 0.0f;
        }
        value = envelope * sum;
    }
    // Exact phase indices: (order * k) mod period, advanced without accumulated error.
    for (int i = 0; i < config_.harmonics; ++i) {
        index_[i] += config_.harmonic[i].order;
        if (index_[i] >= period_) index_[i] -= period_;
    }
    if (++k_ >= total_) active_ = false;      // that was the last sample
    return value;
}

}  // namespace hq
