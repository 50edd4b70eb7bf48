#include "watchdog.hpp"

#include "cpu.hpp"
#include "mk64f12.hpp"

namespace hq::teensy {

using namespace hq::mk64;

namespace {
bool g_running = false;
}

void Watchdog::start(uint32_t timeout_ms) {
    IrqGuard guard;                         // the unlock and the update must not be split
    WDOG::UNLOCK::write(0xC520);
    WDOG::UNLOCK::write(0xD928);
    __asm volatile("nop\n nop");
    WDOG::TOVALH::write(static_cast<uint16_t>(timeout_ms >> 16));
    WDOG::TOVALL::write(static_cast<uint16_t>(timeout_ms & 0xFFFFu));
    WDOG::PRESC::write(WDOG::PRESC::PRESCVAL(0));          // LPO 1 kHz, undivided: 1 ms per count
    // The reset value (which keeps the reserved bit 8 set and ALLOWUPDATE) with CLKSRC = LPO
    // and WDOGEN on.
    WDOG::STCTRLH::write(static_cast<uint16_t>(
        (WDOG::STCTRLH::RESET_VALUE & ~WDOG::STCTRLH::CLKSRC) | WDOG::STCTRLH::WDOGEN));
    g_running = true;
}

void Watchdog::refresh() {
    if (!g_running) return;
    IrqGuard guard;                         // the two keys must follow each other closely
    WDOG::REFRESH::write(0xA602);
    WDOG::REFRESH::write(0xB480);
}

}  // namespace hq::teensy
