// UsbCdcSerial (usb_serial.hpp) on TinyUSB's device stack and CDC-ACM class, and the class
// request the image watches: the line coding (134 baud: the bootloader), judged by a thin
// driver in front of the stack's own CDC driver when a SET_LINE_CODING the host sent ends.
#include "usb_serial.hpp"

#include "../mk64f12.hpp"
#include "tusb.h"
#include "device/usbd_pvt.h"

namespace hq::teensy {

namespace {

namespace mk64 = hq::mk64;

static_assert(kUsbLogBytesPerS / 200u == CFG_TUD_CDC_TX_BUFSIZE * 3u / 4u,
              "kUsbLogBytesPerS: three quarters of the transmit buffer each 200 Hz loop");

uint32_t g_closed_bytes = 0;
bool g_bootloader_asked = false;

// A SET_LINE_CODING whose data stage the host sent: class, host to device. To the interface,
// or to the device with the interface in wIndex, which usbd.c hands to the same driver. The
// CDC driver takes the bRequest whatever the direction bit says: sent device to host, its
// data stage gives the host the line coding the port already has, and its end must not be
// read as the host's line coding (the low byte of 9606 baud, 0x2586, is 0x86).
bool line_coding_from_host(const tusb_control_request_t& request) {
    return request.bmRequestType_bit.type == TUSB_REQ_TYPE_CLASS &&
           request.bmRequestType_bit.direction == TUSB_DIR_OUT &&
           request.bRequest == CDC_REQUEST_SET_LINE_CODING;
}

// The stack's CDC driver, with one thing added: at the end (status stage) of a line coding
// the host sent, the coding it left is judged with that request's own wLength (usbd.c hands
// every stage the request of the transfer in flight, so nothing is kept between requests).
// Listed before the built-in drivers, it is the one that opens the CDC interfaces; the
// built-in one's init and reset run too, and are the same functions.
void driver_init() {}
bool driver_deinit() { return true; }

bool driver_control(uint8_t rhport, uint8_t stage, const tusb_control_request_t* request) {
    if (!cdcd_control_xfer_cb(rhport, stage, request)) return false;
    if (stage == CONTROL_STAGE_ACK && line_coding_from_host(*request)) {
        cdc_line_coding_t coding;
        tud_cdc_get_line_coding(&coding);         // one CDC interface, the one wIndex named
        if (bootloader_line_coding(request->wLength, coding.bit_rate)) g_bootloader_asked = true;
    }
    return true;
}

const usbd_class_driver_t kDrivers[] = {{"hq-cdc", driver_init, driver_deinit, cdcd_reset,
                                         cdcd_open, driver_control, cdcd_xfer_cb, nullptr,
                                         nullptr}};

}  // namespace

void UsbCdcSerial::begin() {
    mk64::SIM::SCGC4::write(mk64::SIM::SCGC4::read() | mk64::SIM::SCGC4::USBOTG);
    // The USB controller is bus master 4: it reads and writes the buffer descriptors and
    // buffers in SRAM, which the MPU's region 0 allows only the core and debugger at reset.
    namespace mpu = mk64::MPU;
    mpu::RGDAAC0::write(mpu::RGDAAC0::read() | mpu::RGDAAC0::M4RE | mpu::RGDAAC0::M4WE);
    const tusb_rhport_init_t device = {TUSB_ROLE_DEVICE, TUSB_SPEED_FULL};
    tusb_init(0, &device);
}

// Only when the interrupt queued an event: tud_task() masks and unmasks USB0's interrupt each
// time it runs, and the loop's wait calls this at every wake-up.
void UsbCdcSerial::task() {
    if (tud_task_event_ready()) tud_task();
}

size_t UsbCdcSerial::read(uint8_t* data, size_t n) {
    return tud_cdc_read(data, static_cast<uint32_t>(n));
}

size_t UsbCdcSerial::write(const uint8_t* data, size_t n) {
    if (!tud_cdc_connected()) {
        g_closed_bytes += static_cast<uint32_t>(n);
        return n;
    }
    if (tud_cdc_write_available() < n) return 0;
    return tud_cdc_write(data, static_cast<uint32_t>(n));
}

void UsbCdcSerial::flush() { tud_cdc_write_flush(); }

bool UsbCdcSerial::open() const { return tud_cdc_connected(); }

uint32_t UsbCdcSerial::closed_bytes() const { return g_closed_bytes; }

bool UsbCdcSerial::take_bootloader_request() {
    const bool asked = g_bootloader_asked;
    g_bootloader_asked = false;
    return asked;
}

}  // namespace hq::teensy

extern "C" {

const usbd_class_driver_t* usbd_app_driver_get_cb(uint8_t* driver_count) {
    *driver_count = static_cast<uint8_t>(sizeof(hq::teensy::kDrivers) / sizeof(hq::teensy::kDrivers[0]));
    return hq::teensy::kDrivers;
}

}  // extern "C"
