#include "motors.hpp"

#include <cmath>

#include "cpu.hpp"
#include "mk64f12.hpp"

namespace hq::teensy {

using namespace hq::mk64;

namespace {
// The stop pulse of each channel in microseconds, for the fault path (which has no object).
uint16_t g_stop_us[kMaxRotors] = {};

// CnSC and CnV interleave (C0SC, C0V, C1SC, ...): two registers between channels.
inline volatile uint32_t& channel_value(int i) { return reg_at<FTM0::C0V>(i, 2); }
inline volatile uint32_t& channel_control(int i) { return reg_at<FTM0::C0SC>(i, 2); }
}  // namespace

void Ftm0Motors::begin(const EscEndpoints& cal) {
    for (int i = 0; i < kMaxRotors; ++i) {
        const bool ok = plausible_endpoints(cal.min_us[i], cal.max_us[i]);
        cal_.min_us[i] = ok ? cal.min_us[i] : 1000;
        cal_.max_us[i] = ok ? cal.max_us[i] : 2000;
    }
    SIM::SCGC6::set(SIM::SCGC6::FTM0);
    SIM::SCGC5::set(SIM::SCGC5::PORTC | SIM::SCGC5::PORTD);
    FTM0::SC::write(0);                            // stopped while configured
    FTM0::CNT::write(0);
    FTM0::CNTIN::write(0);
    FTM0::MOD::write(kPeriodCounts - 1);
    for (int i = 0; i < kMaxRotors; ++i) {
        channel_control(i) = FTM0::C0SC::MSB | FTM0::C0SC::ELSB;   // edge-aligned, high-true
        write(i, cal_.min_us[i]);
        g_stop_us[i] = cal_.min_us[i];
    }
    FTM0::SC::write(FTM0::SC::CLKS(1) | FTM0::SC::PS(2));         // bus clock / 4
    // Only now the pins: ALT4 = FTM0, high drive strength.
    const uint32_t pcr = PORTC::PCR1::MUX(4) | PORTC::PCR1::DSE | PORTC::PCR1::SRE;
    PORTC::PCR1::write(pcr);
    PORTC::PCR2::write(pcr);
    PORTC::PCR3::write(pcr);
    PORTC::PCR4::write(pcr);
    PORTD::PCR4::write(pcr);
    PORTD::PCR5::write(pcr);
    PORTD::PCR6::write(pcr);
    PORTD::PCR7::write(pcr);
}

void Ftm0Motors::set_endpoints(const EscEndpoints& endpoints) {
    for (int i = 0; i < kMaxRotors; ++i) {
        if (!plausible_endpoints(endpoints.min_us[i], endpoints.max_us[i])) continue;
        cal_.min_us[i] = endpoints.min_us[i];
        cal_.max_us[i] = endpoints.max_us[i];
        g_stop_us[i] = cal_.min_us[i];
    }
    disarm();
}

void Ftm0Motors::write(int i, uint16_t us) {
    channel_value(i) = static_cast<uint32_t>(us) * kCountsPerUs;
}

// The pulse is set to the FTM0 count, not the microsecond: 15 steps per microsecond, so a
// 1000 us span has 15 000 thrust steps instead of 1 000 (a rounding to whole microseconds
// would add a 1e-3 staircase to every small excitation). Past `count`: the stop pulse.
void Ftm0Motors::set(const float thrust_fraction[kMaxRotors], int count) {
    for (int i = 0; i < kMaxRotors; ++i) {
        float f = i < count ? thrust_fraction[i] : 0.0f;
        if (!std::isfinite(f) || !(f > 0.0f)) f = 0.0f;     // NaN and infinities: stop
        if (f > 1.0f) f = 1.0f;
        const uint32_t min_counts = cal_.min_us[i] * kCountsPerUs;
        const float span = static_cast<float>((cal_.max_us[i] - cal_.min_us[i]) * kCountsPerUs);
        channel_value(i) = min_counts + static_cast<uint32_t>(f * span + 0.5f);
    }
}

void Ftm0Motors::disarm() {
    for (int i = 0; i < kMaxRotors; ++i) write(i, cal_.min_us[i]);
}

void motors_emergency_stop() {
    if (!(SIM::SCGC6::read() & SIM::SCGC6::FTM0)) return;     // never started: pins undriven
    // The stop pulses come from RAM, which a fault may have corrupted: never more than a
    // plausible stop pulse (1100 us), never nothing.
    constexpr uint32_t kMaxStopUs = 1100;
    constexpr uint32_t kDefaultStopUs = 1000;
    for (int i = 0; i < kMaxRotors; ++i) {
        const uint32_t us = g_stop_us[i];
        channel_value(i) = ((us != 0 && us <= kMaxStopUs) ? us : kDefaultStopUs) *
                           Ftm0Motors::kCountsPerUs;
    }
}

}  // namespace hq::teensy
