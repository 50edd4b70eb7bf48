#include "loop_timer.hpp"

#include "clock.hpp"
#include "cpu.hpp"
#include "mk64f12.hpp"

namespace {
volatile uint32_t g_ticks = 0;
bool g_ticking = false;
}

extern "C" void SysTick_Handler() { g_ticks = g_ticks + 1; }

namespace hq::teensy {

using namespace hq::mk64;

bool LoopTimer::start(uint32_t rate_hz) {
    if (rate_hz == 0) return false;
    const uint32_t period = core_hz() / rate_hz;
    if (period < 2 || period > (1u << 24)) return false;
    SysTick::CSR::write(0);
    SysTick::RVR::write(period - 1);
    SysTick::CVR::write(0);
    // Lowest priority of the interrupts in use (RC capture 4, UART 8, I2C0 10, SysTick 12).
    SystemControl::SHPR3::write(static_cast<uint32_t>(
        (SystemControl::SHPR3::read() & ~SystemControl::SHPR3::PRI_15_MASK) |
        SystemControl::SHPR3::PRI_15(12u << 4)));
    seen_ = g_ticks;
    SysTick::CSR::write(SysTick::CSR::CLKSOURCE | SysTick::CSR::TICKINT | SysTick::CSR::ENABLE);
    g_ticking = true;
    return true;
}

bool LoopTimer::ticking() { return g_ticking; }

uint32_t LoopTimer::wait(void (*idle)()) {
    // With interrupts masked, WFI still wakes on a pending interrupt; unmasking then lets the
    // handler run. A tick between the check and the WFI therefore cannot be slept through.
    // The idle work runs only while no tick has come: the one that woke the core with the
    // tick starts the loop at once (its work waits for the loop's own turn at it), so the
    // loop's time does not depend on what else woke it.
    irq_disable();
    while (g_ticks == seen_) {
        wfi();
        irq_enable();
        isb();
        if (idle != nullptr && g_ticks == seen_) idle();
        irq_disable();
    }
    const uint32_t now = g_ticks;
    irq_enable();
    return take(now);
}

bool LoopTimer::take_tick() {
    const uint32_t now = g_ticks;     // one aligned word: read whole
    if (now == seen_) return false;
    take(now);
    return true;
}

uint32_t LoopTimer::take(uint32_t now) {
    const uint32_t missed = now - seen_ - 1;
    overruns_ += missed;
    seen_ = now;
    return missed;
}

}  // namespace hq::teensy
