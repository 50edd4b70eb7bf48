#include "excitation.hpp"

#include <cmath>

namespace hq {

namespace {
constexpr float kTwoPi = 6.283185307179586f;
// At least four samples per period: a sine needs more than two (Nyquist), and the FSF's
// harmonics are meaningless much closer to it.
constexpr float kMinSamplesPerPeriod = 4.0f;
}  // namespace

bool Excitation::start(const ExcitationConfig& config, float loop_rate_hz) {
    active_ = false;
    if (!(config.freq_hz > 0.0f) || !(loop_rate_hz > 0.0f) || !std::isfinite(loop_rate_hz) ||
        config.freq_hz * kMinSamplesPerPeriod > loop_rate_hz || config.cycles == 0 ||
        !std::isfinite(config.amplitude)) {
        return false;
    }
    // In double: a tiny frequency must be refused, not wrapped into a short period.
    const double samples = static_cast<double>(loop_rate_hz) / static_cast<double>(config.freq_hz);
    if (!(samples <= static_cast<double>(kMaxPeriodSamples))) return false;
    const uint32_t period = static_cast<uint32_t>(std::llround(samples));
    const uint64_t total =
        uint64_t{period} * (uint64_t{config.cycles} + 2u * uint64_t{config.fade_cycles});
    if (total > kMaxTotalSamples) return false;
    config_ = config;
    period_ = period;
    actual_freq_hz_ = loop_rate_hz / static_cast<float>(period_);
    total_ = static_cast<uint32_t>(total);
    k_ = 0;
    active_ = true;
    return true;
}

void Excitation::stop() { active_ = false; }

bool Excitation::finish() {
    if (!active_) return false;
    const uint32_t fade = period_ * config_.fade_cycles;
    // Whole full-amplitude cycles once the one under way ends (k_ is the next sample).
    const uint32_t cycles = k_ <= fade ? 1u : (k_ - fade + period_ - 1u) / period_;
    const uint64_t total = uint64_t{period_} * (uint64_t{cycles} + 2u * config_.fade_cycles);
    if (total < total_) {
        total_ = static_cast<uint32_t>(total);
        config_.cycles = static_cast<uint16_t>(cycles);
    }
    return true;
}

bool Excitation::measuring() const {
    const uint32_t fade = period_ * config_.fade_cycles;
    return active_ && k_ >= fade && k_ < total_ - fade;
}

ExcitationState Excitation::state() const {
    if (!active_) return ExcitationState::Idle;
    return measuring() ? ExcitationState::Running : ExcitationState::Fading;
}

float Excitation::next() {
    if (!active_) return 0.0f;
    const uint32_t fade = period_ * config_.fade_cycles;
    float envelope = 1.0f;
    if (k_ < fade) {
        envelope = 0.5f * (1.0f - std::cos(kTwoPi * 0.5f * static_cast<float>(k_) /
                                           static_cast<float>(fade)));
    } else if (k_ >= total_ - fade) {
        envelope = 0.5f * (1.0f - std::cos(kTwoPi * 0.5f * static_cast<float>(total_ - k_) /
                                           static_cast<float>(fade)));
    }
    const uint32_t phase = k_ % period_;          // exact: no accumulated phase error
    const float value = config_.amplitude * envelope *
                        std::sin(kTwoPi * static_cast<float>(phase) / static_cast<float>(period_));
    if (++k_ >= total_) active_ = false;      // that was the last sample
    return value;
}

}  // namespace hq
