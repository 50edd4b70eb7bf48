// The Teensy 3.5 image's USB identity: what its CDC-ACM port's descriptors say and what the host
// tool's --port auto matches (host/acquire/ports.py). A fact of the Teensy's USB port, not of
// the core (the host build has no USB), in a header of its own with no register access so that
// the bindings give Python the same values (sim/base/firmware_facts.py). docs/usb.md.
#pragma once

#include <cstddef>
#include <cstdint>

namespace hq {

// Teensyduino's USB Serial IDs (PJRC's vendor ID, the product ID of its "USB Serial" type):
// teensy_loader_cli's soft reboot looks for them, so the board can be flashed without the
// button. A stock Teensyduino sketch has the same pair; the product string tells them apart.
constexpr uint16_t kUsbVendorId = 0x16C0;
constexpr uint16_t kUsbProductId = 0x0483;
constexpr const char* kUsbManufacturer = "heliquad";
// What the host matches on besides the IDs: the product string contains "heliquad".
constexpr const char* kUsbProduct = "heliquad flight controller";

// The serial number: the chip's unique identification (SIM_UIDH, UIDMH, UIDML, UIDL, 128
// bits) in upper-case hexadecimal, most significant digit first, so unique per chip.
constexpr size_t kUsbSerialDigits = 32;

constexpr char hex_digit(uint32_t nibble) {
    return static_cast<char>(nibble < 10 ? '0' + nibble : 'A' + (nibble - 10));
}

// uid: UIDH, UIDMH, UIDML, UIDL as read; out: kUsbSerialDigits characters, no terminator.
constexpr void usb_serial_number(const uint32_t (&uid)[4], char (&out)[kUsbSerialDigits]) {
    for (size_t i = 0; i < kUsbSerialDigits; ++i) {
        const uint32_t word = uid[i / 8];
        out[i] = hex_digit((word >> (28 - 4 * (i % 8))) & 0xFu);
    }
}

}  // namespace hq
