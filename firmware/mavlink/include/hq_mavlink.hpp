// The one way into the MAVLink C library generated from heliquad.xml: every source includes
// this header, never <heliquad/mavlink.h> itself (tests/firmware_includes_test.py checks).
//
// What it adds: the packets' checksum (CRC-16/MCRF4XX, MAVLink's X.25 CRC) by a 256-entry
// table, one lookup a byte, instead of the library's shifts and XORs (some ten instructions
// a byte). The library lets a program give its own crc_accumulate (HAVE_CRC_ACCUMULATE);
// its crc_calculate, crc_accumulate_buffer and every packer and parser then use this one.
// Checksumming was the largest single cost of the Teensy image's loop (a fifth of its
// instructions, benchmarks/guest_profile.py), as every telemetry byte is summed once for
// each link that sends it.
#pragma once

#include <stdint.h>

#include <array>

namespace hq::mavlink_crc {

// One step of the reflected CRC-16 (polynomial 0x1021 reversed: 0x8408) over one byte, bit
// by bit: what the table holds for each byte value, and what the checks below compare with.
constexpr uint16_t bitwise(uint16_t crc, uint8_t byte) {
    crc ^= byte;
    for (int bit = 0; bit < 8; ++bit) crc = (crc & 1u) ? (crc >> 1) ^ 0x8408u : (crc >> 1);
    return crc;
}

constexpr std::array<uint16_t, 256> make_table() {
    std::array<uint16_t, 256> t{};
    for (unsigned i = 0; i < 256; ++i) t[i] = bitwise(0, static_cast<uint8_t>(i));
    return t;
}

inline constexpr std::array<uint16_t, 256> kTable = make_table();

constexpr uint16_t accumulate(uint16_t crc, uint8_t byte) {
    return static_cast<uint16_t>((crc >> 8) ^ kTable[(crc ^ byte) & 0xFFu]);
}

// The library's own step, as generated: the table must agree with it for every byte and
// every CRC state's low byte (the high byte only shifts), checked at compile time.
constexpr uint16_t library_step(uint16_t crc, uint8_t data) {
    uint8_t tmp = static_cast<uint8_t>(data ^ static_cast<uint8_t>(crc & 0xFF));
    tmp = static_cast<uint8_t>(tmp ^ (tmp << 4));
    return static_cast<uint16_t>((crc >> 8) ^ (tmp << 8) ^ (tmp << 3) ^ (tmp >> 4));
}

constexpr bool agrees_with_library() {
    for (unsigned low = 0; low < 256; ++low)
        for (unsigned byte = 0; byte < 256; ++byte) {
            const uint16_t crc = static_cast<uint16_t>(0xA500u | low);
            if (accumulate(crc, static_cast<uint8_t>(byte)) !=
                library_step(crc, static_cast<uint8_t>(byte)))
                return false;
        }
    return true;
}

constexpr uint16_t checksum(const char* s, uint16_t crc = 0xFFFF) {
    return *s ? checksum(s + 1, accumulate(crc, static_cast<uint8_t>(*s))) : crc;
}

static_assert(agrees_with_library(), "the CRC table disagrees with MAVLink's crc_accumulate");
// CRC-16/MCRF4XX's published check value: the CRC of "123456789" is 0x6F91.
static_assert(checksum("123456789") == 0x6F91, "not CRC-16/MCRF4XX");

}  // namespace hq::mavlink_crc

#define HAVE_CRC_ACCUMULATE 1
static inline void crc_accumulate(uint8_t data, uint16_t* crcAccum) {
    *crcAccum = hq::mavlink_crc::accumulate(*crcAccum, data);
}

#include <heliquad/mavlink.h>
