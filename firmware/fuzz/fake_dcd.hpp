// A USB device controller for TinyUSB's device stack on the host, in place of the MK64's
// ci_fs driver (the dcd_* functions usbd.c calls, in fake_dcd.cpp): it records endpoint opens,
// stalls and the transfers the stack hands it, and completes them when the fuzz target plays
// the host (a SETUP packet, OUT data, an IN token, a bus reset). Like the controller it
// mirrors, it enables EP0 at the first bus reset (a SETUP before it is never received),
// cancels EP0's transfers at a SETUP and clears every endpoint at a bus reset.
// As a host does, it sends EP0 data and status tokens only inside a control transfer it began
// with a SETUP: a bus reset abandons the transfer in flight, so whatever the stack arms on EP0
// for that transfer afterwards (it may handle a completion queued before the reset after it)
// is never read.
//
// It also checks the one rule of the control pipe a device must keep whatever the host asks:
// the IN bytes a control request's data stage offers are never more than its wLength (a
// request with an OUT data stage, or none, gets a zero-length status packet only). A breach
// aborts, as a sanitizer report does.
#pragma once

#include <cstddef>
#include <cstdint>

namespace hqfuzz::usb {

constexpr size_t kSetupBytes = 8;
constexpr size_t kLineCodingBytes = 7;      // CDC PSTN 1.2, 6.3.11: dwDTERate, 3 one-byte fields

// The SETUP packet the stack is answering and what its data stage carried so far.
struct ControlRequest {
    bool in_flight = false;                 // begun with a SETUP, not abandoned by a bus reset
    uint8_t bm_request_type = 0;
    uint8_t b_request = 0;
    uint16_t w_value = 0;
    uint16_t w_index = 0;
    uint16_t w_length = 0;
    uint32_t in_bytes = 0;                  // offered by the device on EP0 IN
    uint32_t out_bytes = 0;                 // delivered by the host on EP0 OUT
    uint8_t out_head[kLineCodingBytes] = {};  // the first OUT bytes
};

// What an operation did: nothing was waiting on that endpoint, or the bytes it moved.
constexpr int kNothingPending = -1;

// The controller's state back to its power-on state, EP0 not yet enabled (dcd_init does the
// same).
void reset();
// Host actions: each queues the event the controller's interrupt would (tud_task handles it).
void bus_reset();
void setup(const uint8_t (&packet)[kSetupBytes]);
// OUT data (up to n bytes; fewer ends the transfer with a short packet) or an IN token read
// in full, on the transfer pending at ep_addr; result is an xfer_result_t.
int deliver_out(uint8_t ep_addr, const uint8_t* data, size_t n, uint8_t result);
int read_in(uint8_t ep_addr, uint8_t result);
// Events queued since the stack last ran (tud_task empties the queue), and whether any is an
// EP0 completion.
int queued_events();
bool ep0_event_queued();
void task_ran();

const ControlRequest& request();
bool interrupts_enabled();

}  // namespace hqfuzz::usb
