// The MK64's reset cause (hal/reset_cause.hpp): RCM_SRS0 and RCM_SRS1 read, then decoded by
// reset_cause_from (reset_cause_flags.hpp).
#include "reset_cause_flags.hpp"

namespace hq {

ResetCause reset_cause() {
    return reset_cause_from(mk64::RCM::SRS0::read(), mk64::RCM::SRS1::read());
}

}  // namespace hq
