#include "rc_input.hpp"

#include "clock.hpp"
#include "cpu.hpp"
#include "mk64f12.hpp"

namespace hq::teensy {

using namespace hq::mk64;

namespace {

constexpr int kN = Ftm3RcInput::kChannels;

// Written by the FTM3 interrupt, read with interrupts masked.
struct Captures {
    uint16_t rise[kN] = {};
    bool high[kN] = {};
    uint16_t pulse_us[kN] = {};
    uint64_t when_cycles[kN] = {};
    bool valid[kN] = {};
    uint32_t rejected = 0;
};
Captures g_cap;

// Pin level per channel, to tell a rising from a falling edge.
bool pin_high(int ch) {
    if (ch < 4) return (GPIOD::PDIR::read() >> ch) & 1u;      // PTD0-3
    return (GPIOC::PDIR::read() >> (ch + 4)) & 1u;            // PTC8-10
}

// CnSC and CnV interleave (C0SC, C0V, C1SC, ...): two registers between channels.
inline volatile uint32_t& channel_control(int i) { return reg_at<FTM3::C0SC>(i, 2); }
inline volatile uint32_t& channel_value(int i) { return reg_at<FTM3::C0V>(i, 2); }

// Counts of 1.875 MHz to microseconds: x 8 / 15.
constexpr uint32_t counts_to_us(uint32_t counts) { return counts * 8u / 15u; }

}  // namespace

void Ftm3RcInput::begin() {
    SIM::SCGC3::set(SIM::SCGC3::FTM3);
    SIM::SCGC5::set(SIM::SCGC5::PORTC | SIM::SCGC5::PORTD);
    FTM3::SC::write(0);
    FTM3::CNTIN::write(0);
    FTM3::MOD::write(0xFFFF);
    FTM3::CNT::write(0);
    for (int i = 0; i < kN; ++i) {
        channel_control(i) = FTM3::C0SC::ELSA | FTM3::C0SC::ELSB | FTM3::C0SC::CHIE;
    }
    FTM3::SC::write(FTM3::SC::CLKS(1) | FTM3::SC::PS(5));          // bus / 32
    // ALT4 = FTM3 on PTD0-3, ALT3 = FTM3 on PTC8-10; inputs with a pull-down, so a missing or
    // broken receiver lead reads a steady low (no pulses: no signal) instead of floating
    // into noise on the highest-priority interrupt.
    const uint32_t d = PORTD::PCR0::MUX(4) | PORTD::PCR0::PE;     // PS = 0: pull-down
    PORTD::PCR0::write(d);
    PORTD::PCR1::write(d);
    PORTD::PCR2::write(d);
    PORTD::PCR3::write(d);
    PORTC::PCR8::write(PORTC::PCR8::MUX(3) | PORTC::PCR8::PE);
    PORTC::PCR9::write(PORTC::PCR9::MUX(3) | PORTC::PCR9::PE);
    PORTC::PCR10::write(PORTC::PCR10::MUX(3) | PORTC::PCR10::PE);
    nvic_enable(irq::FTM3, 4);
}

RcInput Ftm3RcInput::read() const {
    Captures c;
    uint64_t now_cycles;
    {
        IrqGuard guard;
        c = g_cap;
        now_cycles = cycles64();    // taken with the snapshot: no capture can be newer than now
    }
    // Ages in cycles, one division at the end (this runs every loop).
    RcInput in;
    const uint32_t per_us = core_hz() / 1000000u;
    const uint64_t timeout_cycles = static_cast<uint64_t>(kChannelTimeoutUs) * per_us;
    uint64_t oldest_stick = 0;
    bool sticks_live = true;
    for (int i = 0; i < kN; ++i) {
        const uint64_t when = c.when_cycles[i];
        const bool fresh = c.valid[i] && (when >= now_cycles || now_cycles - when <= timeout_cycles);
        in.channel_us[i] = fresh ? c.pulse_us[i] : 0;
        if (i < 4) {
            if (!c.valid[i]) sticks_live = false;
            else if (i == 0 || when < oldest_stick) oldest_stick = when;
        }
    }
    if (sticks_live) {
        const uint64_t cycles = now_cycles > oldest_stick ? now_cycles - oldest_stick : 0;
        const uint64_t age = divide_time(cycles, per_us);
        in.age_us = age > 0xFFFFFFFEu ? 0xFFFFFFFEu : static_cast<uint32_t>(age);
    }
    return in;
}

uint32_t Ftm3RcInput::rejected() const {
    IrqGuard guard;
    return g_cap.rejected;
}

}  // namespace hq::teensy

extern "C" void FTM3_IRQHandler() {
    using namespace hq::teensy;
    using namespace hq::mk64;
    const uint64_t now = cycles64();
    for (int i = 0; i < kN; ++i) {
        const uint32_t sc = channel_control(i);
        if (!(sc & FTM3::C0SC::CHF)) continue;
        const uint16_t v = static_cast<uint16_t>(channel_value(i));
        channel_control(i) = sc & ~FTM3::C0SC::CHF;        // read-then-write-0 clears CHF
        if (pin_high(i)) {
            g_cap.rise[i] = v;
            g_cap.high[i] = true;
            continue;
        }
        if (!g_cap.high[i]) continue;                       // a fall without its rise
        g_cap.high[i] = false;
        const uint32_t us = counts_to_us(static_cast<uint16_t>(v - g_cap.rise[i]));
        if (us < Ftm3RcInput::kMinPulseUs || us > Ftm3RcInput::kMaxPulseUs) {
            ++g_cap.rejected;
            continue;
        }
        g_cap.pulse_us[i] = static_cast<uint16_t>(us);
        g_cap.when_cycles[i] = now;
        g_cap.valid[i] = true;
    }
}
