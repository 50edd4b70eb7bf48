// Why the chip last reset, for the boot report (loop_exchange.hpp's BootReport). Contract:
// reset_cause() says what the hardware recorded for the reset the firmware runs after; it has
// no side effect and answers the same at any time until the next reset (the Teensy reads the
// MK64's reset control module, RCM_SRS0/SRS1, which keep their flags until then). The host
// build is a process started afresh: always PowerOn.
#pragma once

#include <cstdint>

namespace hq {

enum class ResetCause : uint8_t {
    PowerOn,       // power applied (the MK64's POR)
    Pin,           // the RESET pin (the Teensy's program button, its loader after a flash)
    Watchdog,      // the watchdog expired: the loop stopped refreshing it
    Lockup,        // the core locked up (a fault inside a fault handler)
    Software,      // the firmware asked for it (SYSRESETREQ)
    LowVoltage,    // the supply fell below the low-voltage detect threshold
    ClockLoss,     // the external clock or the PLL's lock was lost
    Debugger,      // a debugger's reset (JTAG, the MDM-AP, EzPort)
    Other,         // none of these (a wake-up from a low-power mode, a stop-mode error)
};

ResetCause reset_cause();

}  // namespace hq
