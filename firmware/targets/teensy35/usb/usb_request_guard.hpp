// The guard in front of TinyUSB's device stack (usb_request_guard.cpp): which standard USB
// requests are well formed (USB 2.0, 9.4, Table 9-3: each one's direction, and no data stage
// for the ones that have none). Class and vendor requests, and standard requests it does not
// know, are left to the stack.
#pragma once

#include <cstdint>

namespace hq::teensy {

bool standard_request_well_formed(uint8_t request_type, uint8_t request, uint16_t length);

}  // namespace hq::teensy
