// libFuzzer target: the Teensy 3.5 image's USB port as a host drives it. TinyUSB's device
// stack and CDC-ACM class (firmware/third_party/tinyusb, unmodified) with the image's port
// layer (targets/teensy35/usb: usb_descriptors.cpp, usb_serial.cpp), on a fake device
// controller (fake_dcd.hpp) and the few MK64 registers those files touch mapped as host
// memory at their addresses. The input plays the host: bus resets, SETUP packets (any 8
// bytes, and SET_CONTROL_LINE_STATE), OUT data stages of any length (a 1-byte
// SET_LINE_CODING included), IN tokens, bulk OUT data and bulk IN reads, the loop's writes
// and reads, and tud_task() (through UsbCdcSerial::task, as the loop runs it).
// Besides the sanitizers it checks: a control request's IN data is never longer than its
// wLength (the fake controller checks it as the stack offers the bytes); the bootloader flag
// is set only by a SET_LINE_CODING (host to device, to the interface or the device) whose data
// stage the host sent as 134 baud (a dwDTERate of 134, or the 1-byte form: wLength 1, the
// byte 0x86) or ended short of its wLength, and always by one of the first two; write() takes
// a message whole or not at all; the stack never leaves USB0's interrupt masked.
// With HQ_FUZZ_USB_LOG set it prints one line per input (the unit test reads it).
//
//   build: cmake -S firmware -B build/fuzz -DCMAKE_CXX_COMPILER=clang++ -DHQ_FUZZ=ON
//   run:   build/fuzz/fuzz_usb_control CORPUS -max_total_time=60   (or tests/fuzz/run.py)
#include <sys/mman.h>

#include <cstdio>
#include <cstdlib>

#include "fake_dcd.hpp"
#include "fuzz_reader.hpp"
#include "targets/teensy35/mk64f12.hpp"
#include "targets/teensy35/usb/usb_serial.hpp"
#include "tusb.h"

namespace {

using hqfuzz::Reader;
namespace usb = hqfuzz::usb;
namespace mk64 = hq::mk64;

constexpr int kMaxOps = 256;               // per input: keeps executions fast
// The stack's event queue holds CFG_TUD_TASK_QUEUE_SZ (16, usbd.c's default) events; the
// loop runs tud_task before the interrupt could fill it, and so does the harness.
constexpr int kTaskAfterEvents = 12;
constexpr uint8_t kCdcItf = 0;             // usb_descriptors.cpp: the CDC-ACM control interface
constexpr uint8_t kClassToInterface = 0x21, kClassToDevice = 0x20;   // bmRequestType, host to device
constexpr uint8_t kEpDataOut = 0x02, kEpDataIn = 0x82, kEpNotify = 0x81;
constexpr size_t kMaxWrite = CFG_TUD_CDC_TX_BUFSIZE + 64;   // larger than the buffer too
constexpr uint8_t kBootloaderOneByte = hq::teensy::kBootloaderBaud;  // 134 = 0x86
// A made-up chip identity (SIM_UIDH..UIDL) for the serial number.
constexpr uint32_t kUid[4] = {0x00123456u, 0x789ABCDEu, 0xF0123456u, 0x789ABCDEu};

hq::teensy::UsbCdcSerial g_port;
bool g_log = false;

// The MK64 registers the port layer touches (SIM's clock gate and unique ID, the system MPU's
// region 0 access) as host memory at their addresses: one page for SIM's, one for the MPU's.
void map_page_of(uint32_t address) {
    const uintptr_t page = address & ~uintptr_t{0xFFF};
    void* at = mmap(reinterpret_cast<void*>(page), 0x1000, PROT_READ | PROT_WRITE,
                    MAP_PRIVATE | MAP_ANONYMOUS | MAP_FIXED_NOREPLACE, -1, 0);
    if (at != reinterpret_cast<void*>(page)) {
        std::fprintf(stderr, "fuzz_usb_control: cannot map the register page at 0x%lx\n",
                     static_cast<unsigned long>(page));
        std::abort();
    }
}

void map_registers() {
    static_assert((mk64::SIM::SCGC4::address >> 12) == (mk64::SIM::UIDH::address >> 12) &&
                  (mk64::SIM::UIDH::address >> 12) == (mk64::SIM::UIDL::address >> 12));
    map_page_of(mk64::SIM::SCGC4::address);
    map_page_of(mk64::MPU::RGDAAC0::address);
    mk64::SIM::UIDH::write(kUid[0]);
    mk64::SIM::UIDMH::write(kUid[1]);
    mk64::SIM::UIDML::write(kUid[2]);
    mk64::SIM::UIDL::write(kUid[3]);
}

// What the host sent in the SET_LINE_CODING requests whose status stage it completed since
// the stack last ran: may the bootloader flag be set, must it be.
struct LineCodingSent {
    bool allowed = false;
    bool required = false;
};

struct Host {
    LineCodingSent sent;
    bool asked = false;                    // the flag was set since the stack's queue was empty
    int tasks = 0;
    int bootloader = 0;
};

// The status stage of the request in flight was just read by the host: if that request is
// SET_LINE_CODING, its line coding takes effect now.
void status_read(Host& host) {
    const usb::ControlRequest& r = usb::request();
    // Class, host to device, to the interface or to the device: usbd.c hands a class request
    // to the device to the driver of the interface its wIndex names, and the CDC driver
    // applies it as it applies one to the interface.
    const bool set_line_coding = (r.bm_request_type == kClassToInterface ||
                                  r.bm_request_type == kClassToDevice) &&
                                 r.b_request == CDC_REQUEST_SET_LINE_CODING;
    if (!set_line_coding) return;
    const uint8_t* d = r.out_head;
    const uint32_t rate = d[0] | (d[1] << 8) | (d[2] << 16) | (static_cast<uint32_t>(d[3]) << 24);
    const bool full_rate = r.out_bytes >= 4 && rate == hq::teensy::kBootloaderBaud;
    const bool one_byte = r.w_length == 1 && r.out_bytes == 1 && d[0] == kBootloaderOneByte;
    // A host sends exactly wLength bytes in an OUT data stage (USB 2.0, 9.3.5); the fake one
    // may end it short, and what the port makes of a line coding the host left partly unsent
    // (the bytes it keeps from the last one) is not judged.
    const bool short_stage = r.out_bytes < r.w_length;
    host.sent.allowed |= full_rate || one_byte || short_stage;
    host.sent.required |= r.w_index == kCdcItf &&
                          ((full_rate && r.out_bytes >= usb::kLineCodingBytes) || one_byte);
}

// tud_task as the loop runs it, then the loop's question: did a host ask for the bootloader?
// tud_task returns with events still queued when one of its assertions fails (a transfer
// completing on an endpoint no driver holds, as after a reset); the loop's next call goes on
// with them. Until the queue is empty the requests sent are not all answered, and the fake
// controller's count of queued events stands.
void run_task(Host& host) {
    g_port.task();
    ++host.tasks;
    if (!usb::interrupts_enabled()) std::abort();
    const bool asked = g_port.take_bootloader_request();
    if (asked && !host.sent.allowed) std::abort();
    host.bootloader += asked;
    host.asked |= asked;
    if (tud_task_event_ready()) return;
    usb::task_ran();
    if (host.sent.required && !host.asked) std::abort();
    host.sent = {};
    host.asked = false;
}

uint8_t result(Reader& in) {
    const uint8_t r = in.u8();
    return r < 0xF0 ? XFER_RESULT_SUCCESS : static_cast<uint8_t>(r % 4);   // failed, stalled
}

void send_setup(Reader& in, Host& host, bool line_state) {
    uint8_t packet[usb::kSetupBytes];
    if (line_state) {
        const uint16_t lines = in.u8() & 3;                  // DTR, RTS
        const uint8_t p[] = {0x21, CDC_REQUEST_SET_CONTROL_LINE_STATE, static_cast<uint8_t>(lines),
                             0, kCdcItf, 0, 0, 0};
        for (size_t i = 0; i < sizeof p; ++i) packet[i] = p[i];
    } else {
        in.bytes(packet, sizeof packet);
    }
    // An EP0 event still queued (a SETUP, a completion) would be handled after this SETUP is
    // recorded as the request in flight: the loop would have run the stack between the two,
    // at each wake-up until its queue is empty (tud_task may return early with events kept).
    while (usb::ep0_event_queued()) run_task(host);
    usb::setup(packet);
}

void application(Reader& in) {
    static uint8_t data[kMaxWrite];
    const size_t n = in.u16() % kMaxWrite;
    for (size_t i = 0; i < n; ++i) data[i] = static_cast<uint8_t>(i);
    const size_t written = g_port.write(data, n);
    if (written != 0 && written != n) std::abort();
    g_port.flush();
    g_port.read(data, in.u8() % kMaxWrite);
}

void step(Reader& in, Host& host) {
    if (usb::queued_events() >= kTaskAfterEvents) run_task(host);
    uint8_t data[CFG_TUD_ENDPOINT0_SIZE];
    switch (in.u8() % 9) {
        case 0: usb::bus_reset(); break;
        case 1: send_setup(in, host, false); break;
        case 2: send_setup(in, host, true); break;
        case 3: {
            const size_t n = in.bytes(data, in.u8() % (sizeof data + 1));
            usb::deliver_out(0, data, n, result(in));
            break;
        }
        case 4:
            if (usb::read_in(0, result(in)) == 0) status_read(host);
            break;
        case 5: {
            const size_t n = in.bytes(data, in.u8() % (sizeof data + 1));
            usb::deliver_out(kEpDataOut, data, n, result(in));
            break;
        }
        case 6: usb::read_in(in.u8() & 1 ? kEpNotify : kEpDataIn, result(in)); break;
        case 7: run_task(host); break;
        default: application(in); break;
    }
}

}  // namespace

extern "C" int LLVMFuzzerInitialize(int*, char***) {
    map_registers();
    g_log = std::getenv("HQ_FUZZ_USB_LOG") != nullptr;
    return 0;
}

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
    tud_deinit(0);                         // the stack as at power-on, for every input
    g_port.begin();
    Reader in(data, size);
    Host host;
    for (int op = 0; op < kMaxOps && !in.done(); ++op) step(in, host);
    do run_task(host);                     // each call takes one event at the least
    while (tud_task_event_ready());
    if (g_log) {
        std::printf("usb: mounted %d open %d bootloader %d tasks %d\n", tud_mounted(),
                    g_port.open(), host.bootloader, host.tasks);
    }
    return 0;
}
