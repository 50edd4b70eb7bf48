// The board's own USB port as a serial link: a CDC-ACM device on USB0 (TinyUSB, vendored
// unmodified under firmware/third_party/tinyusb; the port layer in this folder), what a
// computer sees as /dev/ttyACM0, COMn or /dev/cu.usbmodemNNNN.
//
// * begin(): USB0's clock gate, the USB controller's bus-master access to RAM in the system
//   MPU (its buffer descriptors and buffers are in SRAM), the stack started, the pull-up on
//   D+ (attached). The 48 MHz USB clock comes from clock.cpp.
// * task(): the stack's work (tud_task: enumeration, class requests, finished transfers).
//   The loop calls it before reading the link and while it waits for the next tick, never
//   from an interrupt; the USB interrupt only queues events for it.
// * write(): a message fits the transmit buffer whole or is refused (returns 0, the link
//   counts it dropped); nothing ever blocks. While no host holds the port open (DTR low:
//   nobody reads) the bytes are let go as a UART lets them go to an unplugged pin: write()
//   returns n and closed_bytes() counts them. flush() after the loop's writes hands the
//   buffer to the controller.
// * A SET_LINE_CODING the host sends at 134 baud (the 7-byte structure, or the 1-byte form
//   whose only byte is 0x86) is a request for the bootloader; take_bootloader_request()
//   hands it to the loop, which refuses it while armed.
#pragma once

#include <cstddef>
#include <cstdint>

#include "../../../hal/serial.hpp"

namespace hq::teensy {

// What the link carries at the least, bytes a second: one transmit transfer of
// kTxTransferBytes (usb/tusb_config.h) per 200 Hz loop; servicing the stack while the loop
// waits moves more.
constexpr uint32_t kUsbLinkBytesPerS = 512u * 200u;
// What the log protocol may send on the port, bytes a second (LogTransfer::set_link_rate):
// the host empties the transmit buffer (CFG_TUD_CDC_TX_BUFSIZE, 1 KiB) while the loop waits
// for its next tick, so each 200 Hz loop's spare time may fill it again, less a quarter
// kept for the next step's telemetry: 768 bytes a loop, seven LOG_DATA (126 kB/s of data).
constexpr uint32_t kUsbLogBytesPerS = (1024u - 256u) * 200u;

class UsbCdcSerial final : public SerialPort {
public:
    void begin();
    void task();
    size_t read(uint8_t* data, size_t n) override;
    size_t write(const uint8_t* data, size_t n) override;
    void flush();
    bool open() const;                     // a host holds the port open (DTR)
    uint32_t closed_bytes() const;         // let go while the port was closed
    bool take_bootloader_request();        // one since the last call
};

// The baud rate whose SET_LINE_CODING asks for the bootloader (PJRC's convention, which
// teensy_loader_cli's soft reboot uses).
constexpr uint32_t kBootloaderBaud = 134;

// Whether a SET_LINE_CODING asks for the bootloader: `length` the bytes its data stage
// carried, `bit_rate` the line coding's dwDTERate after it (with 1 byte, only the low byte is
// the host's). Only the full dwDTERate and the 1-byte form count: with 2 or 3 bytes the
// host's rate is not 134 by its low byte alone (0x86 0x01 is 390).
constexpr bool bootloader_line_coding(uint16_t length, uint32_t bit_rate) {
    return length >= 4 ? bit_rate == kBootloaderBaud
                       : length == 1 && (bit_rate & 0xFFu) == kBootloaderBaud;
}

}  // namespace hq::teensy
