#include "led.hpp"

#include "clock.hpp"
#include "cpu.hpp"
#include "mk64f12.hpp"
#include "motors.hpp"
#include "watchdog.hpp"

namespace hq::teensy {

using namespace hq::mk64;

namespace {
constexpr uint32_t kLedBit = 1u << 5;     // PTC5
constexpr uint32_t kOnMs = 200, kOffMs = 300, kPauseMs = 1500;
}  // namespace

void led_begin() {
    SIM::SCGC5::set(SIM::SCGC5::PORTC);
    PORTC::PCR5::write(PORTC::PCR5::MUX(1) | PORTC::PCR5::DSE);
    GPIOC::PCOR::write(kLedBit);
    GPIOC::PDDR::set(kLedBit);
}

void led_set(bool on) {
    if (on) GPIOC::PSOR::write(kLedBit);
    else GPIOC::PCOR::write(kLedBit);
}

bool blink_code_on(uint32_t code, uint32_t t_ms) {
    const uint32_t cycle = code * (kOnMs + kOffMs) + kPauseMs;
    const uint32_t t = t_ms % cycle;
    if (t >= code * (kOnMs + kOffMs)) return false;
    return t % (kOnMs + kOffMs) < kOnMs;
}

void led_update(uint64_t now_us, LedPattern pattern) {
    const uint32_t t_ms = static_cast<uint32_t>(now_us / 1000u);
    switch (pattern) {
        case LedPattern::Armed: led_set(true); break;
        case LedPattern::Disarmed: led_set(t_ms % 1000u < 500u); break;
        case LedPattern::ImuFault:
            led_set(blink_code_on(static_cast<uint32_t>(FaultCode::ImuFault), t_ms));
            break;
    }
}

}  // namespace hq::teensy

extern "C" [[noreturn]] void hq_fatal(uint32_t code) {
    using namespace hq::teensy;
    irq_disable();
    motors_emergency_stop();
    led_begin();
    const uint32_t per_ms = core_hz() / 1000u;
    uint32_t t_ms = 0, last = cycles32();
    for (;;) {
        // The fault path is a deliberate, safe state (ESCs at their stop pulse): keep the
        // watchdog from resetting out of it, so the blink code stays readable.
        Watchdog::refresh();
        led_set(blink_code_on(code, t_ms));
        while (cycles32() - last < per_ms) {
        }
        last += per_ms;
        ++t_ms;
    }
}
