// The image's USB descriptors, as TinyUSB's callbacks give them to the host: the device (the
// identity of usb_identity.hpp: Teensyduino's USB Serial IDs, heliquad's strings, the chip's
// unique ID as the serial number) and one configuration holding a CDC-ACM function
// (communication interface with its notification endpoint, data interface with 64-byte bulk
// endpoints). docs/usb.md lists them byte by byte as the emulated host reads them.
#include <cstddef>
#include <cstdint>

#include "../mk64f12.hpp"
#include "../usb_identity.hpp"
#include "tusb.h"

namespace {

namespace sim = hq::mk64::SIM;

enum StringIndex : uint8_t { kLanguages, kManufacturer, kProduct, kSerial };
constexpr uint16_t kLangEnglishUs = 0x0409;  // USB LANGIDs, English (United States)
constexpr uint8_t kItfCdcControl = 0;        // the CDC-ACM pair: notification + data
constexpr uint8_t kItfCount = 2;
constexpr uint8_t kEpNotify = 0x81;          // IN 1, interrupt
constexpr uint8_t kEpDataOut = 0x02;         // OUT 2, bulk
constexpr uint8_t kEpDataIn = 0x82;          // IN 2, bulk
constexpr uint16_t kNotifySize = 8;          // a SERIAL_STATE notification's header
constexpr uint16_t kBulkSize = 64;           // full-speed bulk maximum
constexpr uint16_t kPowerMa = 100;           // one unit load
constexpr uint16_t kUsb20 = 0x0200;
constexpr uint16_t kDeviceRelease = 0x0100;
constexpr uint16_t kConfigLen = TUD_CONFIG_DESC_LEN + TUD_CDC_DESC_LEN;

const tusb_desc_device_t kDevice = {
    sizeof(tusb_desc_device_t), TUSB_DESC_DEVICE, kUsb20,
    // Interface association: the CDC pair is one function (IAD class triple).
    TUSB_CLASS_MISC, MISC_SUBCLASS_COMMON, MISC_PROTOCOL_IAD, CFG_TUD_ENDPOINT0_SIZE,
    hq::kUsbVendorId, hq::kUsbProductId, kDeviceRelease,
    kManufacturer, kProduct, kSerial, 1};

const uint8_t kConfiguration[] = {
    TUD_CONFIG_DESCRIPTOR(1, kItfCount, 0, kConfigLen, 0, kPowerMa),
    TUD_CDC_DESCRIPTOR(kItfCdcControl, 0, kEpNotify, kNotifySize, kEpDataOut, kEpDataIn,
                       kBulkSize)};
static_assert(sizeof(kConfiguration) == kConfigLen);

// The longest string is the serial number; one more element for the descriptor's header.
uint16_t string_buffer[1 + hq::kUsbSerialDigits];

// Writes ASCII text as the descriptor's UTF-16 code units; returns their count.
size_t put_ascii(const char* text, size_t max_units) {
    size_t n = 0;
    for (; n < max_units && text[n] != '\0'; ++n) {
        string_buffer[1 + n] = static_cast<uint8_t>(text[n]);
    }
    return n;
}

size_t put_serial() {
    const uint32_t uid[4] = {sim::UIDH::read(), sim::UIDMH::read(), sim::UIDML::read(),
                             sim::UIDL::read()};
    char digits[hq::kUsbSerialDigits];
    hq::usb_serial_number(uid, digits);
    for (size_t i = 0; i < hq::kUsbSerialDigits; ++i) {
        string_buffer[1 + i] = static_cast<uint8_t>(digits[i]);
    }
    return hq::kUsbSerialDigits;
}

}  // namespace

extern "C" {

const uint8_t* tud_descriptor_device_cb() { return reinterpret_cast<const uint8_t*>(&kDevice); }

const uint8_t* tud_descriptor_configuration_cb(uint8_t index) {
    (void)index;  // one configuration
    return kConfiguration;
}

const uint16_t* tud_descriptor_string_cb(uint8_t index, uint16_t langid) {
    (void)langid;  // one language
    constexpr size_t kMaxUnits = hq::kUsbSerialDigits;
    size_t units = 0;
    switch (index) {
    case kLanguages: string_buffer[1] = kLangEnglishUs; units = 1; break;
    case kManufacturer: units = put_ascii(hq::kUsbManufacturer, kMaxUnits); break;
    case kProduct: units = put_ascii(hq::kUsbProduct, kMaxUnits); break;
    case kSerial: units = put_serial(); break;
    default: return nullptr;  // no such string: the stack stalls the request
    }
    // Header: bLength (bytes, header included) and bDescriptorType STRING.
    string_buffer[0] = static_cast<uint16_t>((TUSB_DESC_STRING << 8) | (2 * units + 2));
    return string_buffer;
}

}  // extern "C"
