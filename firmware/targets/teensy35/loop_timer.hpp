// The 200 Hz loop tick: SysTick from the core clock, the loop sleeping in WFI between ticks.
//
// wait() returns when a tick has come since the last wait(); if more than one came (the
// loop overran its period), the extra ticks are counted as overruns and skipped: the loop
// never runs twice back to back to catch up.
#pragma once

#include <cstdint>

namespace hq::teensy {

class LoopTimer {
public:
    // rate_hz must divide the core clock into at most 2^24 cycles (SysTick's reload).
    bool start(uint32_t rate_hz);
    // Sleeps until the next tick; returns the ticks missed since the previous wait(). `idle`,
    // if given, runs after every wake-up before the tick (interrupts enabled): work an
    // interrupt queued that should not wait for the next loop (the USB stack's); not after
    // the wake-up the tick itself brings, so the loop starts on its tick.
    uint32_t wait(void (*idle)() = nullptr);
    // Without sleeping: true when a tick has come since the last wait() or take_tick(), which
    // it then takes (missed ticks counted as in wait()). The card's wait hook runs the loop's
    // step by it while FatFs waits for a busy card (docs/sd-card.md); the wait() around that
    // then sleeps until the tick after.
    bool take_tick();
    uint32_t overruns() const { return overruns_; }
    // True once start() has set the tick going: from then on an interrupt comes at least every
    // period, so a WFI anywhere is bounded by it (the I2C waits rely on that).
    static bool ticking();

private:
    uint32_t take(uint32_t now);

    uint32_t seen_ = 0, overruns_ = 0;
};

}  // namespace hq::teensy
