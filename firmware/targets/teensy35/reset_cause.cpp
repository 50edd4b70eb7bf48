// The MK64's reset cause (hal/reset_cause.hpp) from its reset control module: RCM_SRS0 and
// RCM_SRS1 hold one flag per source of the last reset until the next (K64 reference manual,
// chapter 13). A power-on reset also sets LVD, so POR is looked at first; the rest by how
// much each says about the firmware (a watchdog or a lockup reset first).
#include "../../hal/reset_cause.hpp"
#include "mk64f12.hpp"

namespace hq {

ResetCause reset_cause() {
    namespace rcm = mk64::RCM;
    const uint8_t srs0 = rcm::SRS0::read();
    const uint8_t srs1 = rcm::SRS1::read();
    if (srs0 & rcm::SRS0::POR) return ResetCause::PowerOn;
    if (srs0 & rcm::SRS0::WDOG) return ResetCause::Watchdog;
    if (srs1 & rcm::SRS1::LOCKUP) return ResetCause::Lockup;
    if (srs0 & rcm::SRS0::LVD) return ResetCause::LowVoltage;
    if (srs0 & (rcm::SRS0::LOC | rcm::SRS0::LOL)) return ResetCause::ClockLoss;
    if (srs1 & rcm::SRS1::SW) return ResetCause::Software;
    if (srs1 & (rcm::SRS1::JTAG | rcm::SRS1::MDM_AP | rcm::SRS1::EZPT)) return ResetCause::Debugger;
    if (srs0 & rcm::SRS0::PIN) return ResetCause::Pin;
    return ResetCause::Other;
}

}  // namespace hq
