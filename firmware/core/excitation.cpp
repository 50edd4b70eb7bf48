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
    return 0.5f * (1.0f - std::cos(kTwoPi * 0.5f * static_cast<float>(i) / static_cast<float>(length)));
}
}  // namespace

uint16_t lowest_order(const ExcitationConfig& c) {
    return c.signal == Signal::Multisine && c.harmonics > 0 ? c.harmonic[0].order : 1;
}

uint16_t highest_order(const ExcitationConfig& c) {
    return c.signal == Signal::Multisine && c.harmonics > 0 ? c.harmonic[c.harmonics - 1].order : 1;
}

uint64_t fade_samples_for(const ExcitationConfig& c, uint32_t period_samples) {
    const uint32_t lowest = lowest_order(c);
    return uint64_t{c.fade_cycles} * ((period_samples + lowest - 1u) / lowest);
}

bool harmonics_valid(const ExcitationConfig& c, uint32_t period_samples) {
    if (c.signal == Signal::Sine) return true;
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
    if (!harmonics_valid(config, period)) return false;
    const uint64_t fade = fade_samples_for(config, period);
    const uint64_t total = uint64_t{period} * config.cycles + 2u * fade;
    if (total > kMaxTotalSamples) return false;
    config_ = config;
    if (config_.signal == Signal::Sine) {          // one harmonic: the fundamental
        config_.harmonics = 1;
        config_.harmonic[0] = Harmonic{1, config.amplitude, 0.0f};
    }
    period_ = period;
    actual_freq_hz_ = loop_rate_hz / static_cast<float>(period_);
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
    // Whole full-amplitude periods once the one under way ends (k_ is the next sample).
    const uint32_t cycles = k_ <= fade_ ? 1u : (k_ - fade_ + period_ - 1u) / period_;
    const uint64_t total = uint64_t{period_} * cycles + 2u * uint64_t{fade_};
    if (total < total_) {
        total_ = static_cast<uint32_t>(total);
        config_.cycles = static_cast<uint16_t>(cycles);
    }
    return true;
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
    if (config_.signal == Signal::Sine) {
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
