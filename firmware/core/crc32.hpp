// CRC-32 (IEEE 802.3, reflected, polynomial 0xEDB88320), the value zlib's crc32 gives: bit by
// bit, so no table takes flash (about 0.1 ms for 1 KiB on the Teensy). Chained as zlib's is:
// crc32(b, nb, crc32(a, na)) is the CRC of a followed by b. Byte is uint8_t, or volatile
// uint8_t for flash that a flash command may change under the compiler.
#pragma once

#include <cstddef>
#include <cstdint>

namespace hq {

template <class Byte>
uint32_t crc32(const Byte* data, size_t n, uint32_t crc = 0) {
    crc = ~crc;
    for (size_t i = 0; i < n; ++i) {
        crc ^= data[i];
        for (int b = 0; b < 8; ++b) crc = (crc >> 1) ^ (0xEDB88320u & (0u - (crc & 1u)));
    }
    return ~crc;
}

}  // namespace hq
