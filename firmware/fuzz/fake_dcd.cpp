// The host's stand-in for TinyUSB's device controller driver (fake_dcd.hpp): the dcd_* API of
// TinyUSB 0.21.0's device/dcd.h as the Kinetis ci_fs driver provides it (no endpoint close,
// isochronous allocation instead), on plain memory.
#include "fake_dcd.hpp"

#include <cstdlib>
#include <cstring>

#include "tusb.h"
#include "device/dcd.h"

namespace hqfuzz::usb {

namespace {

constexpr uint8_t kEndpoints = TUP_DCD_ENDPOINT_MAX;
constexpr uint8_t kRhport = 0;

struct Endpoint {
    bool open = false;
    bool stalled = false;
    bool pending = false;
    uint16_t max_packet = 0;
    uint8_t* buffer = nullptr;
    uint16_t length = 0;
};

struct Controller {
    Endpoint ep[kEndpoints][2];
    ControlRequest request;
    bool interrupts = false;
    int queued = 0;
    bool ep0_queued = false;
};

Controller g;

Endpoint& endpoint(uint8_t ep_addr) {
    return g.ep[tu_edpt_number(ep_addr) % kEndpoints][tu_edpt_dir(ep_addr)];
}

void queued(uint8_t ep_addr) {
    ++g.queued;
    if (tu_edpt_number(ep_addr) == 0) g.ep0_queued = true;
}

// Every endpoint but EP0 closed; EP0 open with its 64-byte packets.
void close_all_but_ep0() {
    for (uint8_t n = 0; n < kEndpoints; ++n) {
        for (auto& e : g.ep[n]) e = Endpoint{};
    }
    for (auto& e : g.ep[0]) {
        e.open = true;
        e.max_packet = CFG_TUD_ENDPOINT0_SIZE;
    }
}

// The control pipe's rule, checked as the stack offers the bytes.
void check_control_in(uint16_t total_bytes) {
    g.request.in_bytes += total_bytes;
    const bool data_in = (g.request.bm_request_type & TUSB_DIR_IN_MASK) != 0;
    const uint32_t allowed = data_in ? g.request.w_length : 0;
    if (g.request.in_bytes > allowed) std::abort();
}

// A host's token to the endpoint: on EP0 only inside a control transfer in flight.
bool host_sends_to(uint8_t ep_addr) {
    return tu_edpt_number(ep_addr) != 0 || g.request.in_flight;
}

}  // namespace

// As ci_fs's dcd_init leaves the controller: only the bus reset interrupt enabled, EP0 not
// (its process_bus_reset enables EP0 and readies the first SETUP's buffer), so no SETUP is
// received before the host's first bus reset.
void reset() { g = Controller{}; }

void bus_reset() {
    close_all_but_ep0();
    // The host abandons the control transfer in flight; the stack may still answer its SETUP
    // (queued before the reset), and the IN check holds that answer to its wLength.
    g.request.in_flight = false;
    ++g.queued;
    dcd_event_bus_reset(kRhport, TUSB_SPEED_FULL, true);
}

void setup(const uint8_t (&packet)[kSetupBytes]) {
    if (!g.ep[0][TUSB_DIR_OUT].open) return;          // before the first bus reset
    // A SETUP token ends whatever EP0 was doing: its transfers and its stall.
    for (auto& e : g.ep[0]) {
        e.pending = false;
        e.stalled = false;
    }
    g.request = ControlRequest{};
    g.request.in_flight = true;
    g.request.bm_request_type = packet[0];
    g.request.b_request = packet[1];
    g.request.w_value = tu_u16(packet[3], packet[2]);
    g.request.w_index = tu_u16(packet[5], packet[4]);
    g.request.w_length = tu_u16(packet[7], packet[6]);
    queued(0);
    dcd_event_setup_received(kRhport, packet, true);
}

int deliver_out(uint8_t ep_addr, const uint8_t* data, size_t n, uint8_t result) {
    Endpoint& e = endpoint(tu_edpt_addr(tu_edpt_number(ep_addr), TUSB_DIR_OUT));
    if (!e.pending || e.stalled || !host_sends_to(ep_addr)) return kNothingPending;
    const uint16_t got = static_cast<uint16_t>(n < e.length ? n : e.length);
    if (got) std::memcpy(e.buffer, data, got);
    e.pending = false;
    if (tu_edpt_number(ep_addr) == 0) {
        for (uint16_t i = 0; i < got && g.request.out_bytes + i < kLineCodingBytes; ++i) {
            g.request.out_head[g.request.out_bytes + i] = data[i];
        }
        g.request.out_bytes += got;
    }
    queued(ep_addr);
    dcd_event_xfer_complete(kRhport, tu_edpt_addr(tu_edpt_number(ep_addr), TUSB_DIR_OUT), got,
                            result, true);
    return got;
}

int read_in(uint8_t ep_addr, uint8_t result) {
    const uint8_t in = tu_edpt_addr(tu_edpt_number(ep_addr), TUSB_DIR_IN);
    Endpoint& e = endpoint(in);
    if (!e.pending || e.stalled || !host_sends_to(in)) return kNothingPending;
    static uint8_t wire[UINT16_MAX];
    if (e.length) std::memcpy(wire, e.buffer, e.length);   // the host reads every byte
    e.pending = false;
    queued(in);
    dcd_event_xfer_complete(kRhport, in, e.length, result, true);
    return e.length;
}

int queued_events() { return g.queued; }
bool ep0_event_queued() { return g.ep0_queued; }

void task_ran() {
    g.queued = 0;
    g.ep0_queued = false;
}

const ControlRequest& request() { return g.request; }
bool interrupts_enabled() { return g.interrupts; }

}  // namespace hqfuzz::usb

using hqfuzz::usb::g;

extern "C" {

// The stack's clock (the application's to give, without an RTOS). Nothing in the image's use
// of the stack waits; were it to, each look moves time on a millisecond, so a wait ends.
uint32_t tusb_time_millis_api(void) {
    static uint32_t ms = 0;
    return ms++;
}

bool dcd_init(uint8_t rhport, const tusb_rhport_init_t* rh_init) {
    (void)rhport;
    (void)rh_init;
    hqfuzz::usb::reset();
    return true;
}

bool dcd_deinit(uint8_t rhport) {
    (void)rhport;
    hqfuzz::usb::reset();
    return true;
}

void dcd_int_enable(uint8_t rhport) {
    (void)rhport;
    g.interrupts = true;
}

void dcd_int_disable(uint8_t rhport) {
    (void)rhport;
    g.interrupts = false;
}

void dcd_int_handler(uint8_t rhport) { (void)rhport; }

// As ci_fs does: the status stage's zero-length IN (the address itself means nothing here).
void dcd_set_address(uint8_t rhport, uint8_t dev_addr) {
    (void)dev_addr;
    dcd_edpt_xfer(rhport, tu_edpt_addr(0, TUSB_DIR_IN), nullptr, 0, false);
}

void dcd_remote_wakeup(uint8_t rhport) { (void)rhport; }
void dcd_connect(uint8_t rhport) { (void)rhport; }
void dcd_disconnect(uint8_t rhport) { (void)rhport; }
void dcd_sof_enable(uint8_t rhport, bool en) {
    (void)rhport;
    (void)en;
}

bool dcd_edpt_open(uint8_t rhport, const tusb_desc_endpoint_t* desc_ep) {
    (void)rhport;
    const uint8_t addr = desc_ep->bEndpointAddress;
    // ci_fs: no control endpoint but EP0, which is always open.
    if (tu_edpt_number(addr) == 0 || desc_ep->bmAttributes.xfer == TUSB_XFER_CONTROL) return false;
    auto& e = hqfuzz::usb::endpoint(addr);
    e = {};
    e.open = true;
    e.max_packet = tu_edpt_packet_size(desc_ep);
    return true;
}

bool dcd_edpt_iso_alloc(uint8_t rhport, uint8_t ep_addr, uint16_t largest_packet_size) {
    (void)rhport;
    auto& e = hqfuzz::usb::endpoint(ep_addr);
    e = {};
    e.open = true;
    e.max_packet = largest_packet_size;
    return true;
}

bool dcd_edpt_iso_activate(uint8_t rhport, const tusb_desc_endpoint_t* desc_ep) {
    (void)rhport;
    hqfuzz::usb::endpoint(desc_ep->bEndpointAddress).max_packet = tu_edpt_packet_size(desc_ep);
    return true;
}

void dcd_edpt_close_all(uint8_t rhport) {
    (void)rhport;
    hqfuzz::usb::close_all_but_ep0();
}

bool dcd_edpt_xfer(uint8_t rhport, uint8_t ep_addr, uint8_t* buffer, uint16_t total_bytes,
                   bool is_isr) {
    (void)rhport;
    (void)is_isr;
    auto& e = hqfuzz::usb::endpoint(ep_addr);
    if (total_bytes && buffer == nullptr) std::abort();               // the stack's mistake
    // An endpoint a bus reset closed before the stack has seen the reset: ci_fs takes the
    // transfer and the disabled endpoint never moves it.
    if (!e.open) return true;
    if (tu_edpt_number(ep_addr) != 0 && e.pending) return false;      // ci_fs: BD still owned
    if (ep_addr == tu_edpt_addr(0, TUSB_DIR_IN)) hqfuzz::usb::check_control_in(total_bytes);
    e.pending = true;
    e.buffer = buffer;
    e.length = total_bytes;
    return true;
}

void dcd_edpt_stall(uint8_t rhport, uint8_t ep_addr) {
    (void)rhport;
    auto& e = hqfuzz::usb::endpoint(ep_addr);
    if (tu_edpt_number(ep_addr) != 0 && e.pending) return;            // ci_fs: BD still owned
    e.stalled = true;
}

void dcd_edpt_clear_stall(uint8_t rhport, uint8_t ep_addr) {
    (void)rhport;
    if (tu_edpt_number(ep_addr) == 0) return;
    auto& e = hqfuzz::usb::endpoint(ep_addr);
    e.stalled = false;
    e.pending = false;
}

}  // extern "C"
