// The MK64's reset cause (hal/reset_cause.hpp) decoded from its reset control module's two
// status registers, RCM_SRS0 and RCM_SRS1, which hold one flag per source of the last reset
// until the next (K64 reference manual, chapter 13). A pure function of the two bytes, with no
// register access, in a header of its own so that the bindings test the decoding
// (tests/teensy35_boot_test.py); reset_cause.cpp reads the registers and calls it.
#pragma once

#include <cstdint>

#include "../../hal/reset_cause.hpp"
#include "mk64f12.hpp"

namespace hq {

// A power-on reset also sets LVD, so POR is looked at first; the rest by how much each says
// about the firmware (a watchdog or a lockup reset first).
inline ResetCause reset_cause_from(uint8_t srs0, uint8_t srs1) {
    namespace rcm = mk64::RCM;
    if (srs0 & rcm::SRS0::POR) return ResetCause::PowerOn;
    if (srs0 & rcm::SRS0::WDOG) return ResetCause::Watchdog;
    if (srs1 & rcm::SRS1::LOCKUP) return ResetCause::Lockup;
    if (srs0 & rcm::SRS0::LVD) return ResetCause::LowVoltage;
    if (srs0 & (rcm::SRS0::LOC | rcm::SRS0::LOL)) return ResetCause::ClockLoss;
    if (srs1 & rcm::SRS1::SW) return ResetCause::Software;
    const uint8_t debugger = rcm::SRS1::JTAG | rcm::SRS1::MDM_AP | rcm::SRS1::EZPT;
    if (srs1 & debugger) return ResetCause::Debugger;
    if (srs0 & rcm::SRS0::PIN) return ResetCause::Pin;
    return ResetCause::Other;
}

}  // namespace hq
