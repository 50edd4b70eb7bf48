// A guard in front of TinyUSB's device stack (vendored unmodified): a standard request whose
// direction or data stage is not the one USB 2.0 defines for it (9.4, Table 9-3) is answered
// with a request error (EP0 stalled, as the stack answers a request it does not support) and
// never reaches the stack. TinyUSB 0.21.0 answers GET_STATUS, GET_CONFIGURATION and
// GET_INTERFACE from a local variable whatever the direction bit says: sent host-to-device
// with a data stage, the host's bytes would be written to that variable after its function
// returned, into the stack of whatever runs then (found by fuzz_usb_control). The link wraps
// dcd_event_handler, which the controller driver calls with every event, so this sees each
// SETUP first (-Wl,--wrap=dcd_event_handler, usb/CMakeLists.txt and the fuzz target's).
#include "usb_request_guard.hpp"

#include "tusb.h"
#include "device/dcd.h"

namespace hq::teensy {

bool standard_request_well_formed(uint8_t request_type, uint8_t request, uint16_t length) {
    constexpr uint8_t kTypeMask = 0x60, kTypeStandard = 0x00, kDeviceToHost = 0x80;
    if ((request_type & kTypeMask) != kTypeStandard) return true;     // class, vendor: theirs
    const bool in = (request_type & kDeviceToHost) != 0;
    switch (request) {
        case TUSB_REQ_GET_STATUS:
        case TUSB_REQ_GET_DESCRIPTOR:
        case TUSB_REQ_GET_CONFIGURATION:
        case TUSB_REQ_GET_INTERFACE:
        case TUSB_REQ_SYNCH_FRAME:
            return in;                                     // data, if any, to the host
        case TUSB_REQ_CLEAR_FEATURE:
        case TUSB_REQ_SET_FEATURE:
        case TUSB_REQ_SET_ADDRESS:
        case TUSB_REQ_SET_CONFIGURATION:
        case TUSB_REQ_SET_INTERFACE:
            return !in && length == 0;                     // no data stage
        case TUSB_REQ_SET_DESCRIPTOR:
            return !in;
        default:
            return true;                                   // unknown: the stack refuses it
    }
}

}  // namespace hq::teensy

extern "C" {

void __real_dcd_event_handler(const dcd_event_t* event, bool in_isr);

void __wrap_dcd_event_handler(const dcd_event_t* event, bool in_isr) {
    if (event->event_id == DCD_EVENT_SETUP_RECEIVED) {
        const tusb_control_request_t& r = event->setup_received;
        if (!hq::teensy::standard_request_well_formed(r.bmRequestType, r.bRequest, r.wLength)) {
            dcd_edpt_stall(event->rhport, 0x00);          // EP0, both directions
            dcd_edpt_stall(event->rhport, 0x80);
            return;
        }
    }
    __real_dcd_event_handler(event, in_isr);
}

}  // extern "C"
