// Card-image files for the host build (docs/sd-card.md): a file of whole 512-byte blocks,
// formatted FAT32 by FatFs's own f_mkfs, with no partition table (the volume starts at block
// 0, as fsck.fat and mtools read a file). heliquad-fw-host makes one when --sd-image names a
// file that does not exist; `heliquad sd-image` makes one through the bindings.
#pragma once

#include <cstdint>
#include <string>

namespace hq {

// The size of a card image made without one being asked for: 64 MiB, large enough for FAT32
// (at least 65 525 clusters; FatFs gives this size 512-byte clusters) and for minutes of logs,
// small enough to sit in a test's temporary folder (the file is sparse where it is empty).
constexpr uint64_t kDefaultCardImageBytes = 64ull << 20;
// The sizes a card image may have: FAT32's least (65 525 clusters of 512 bytes and the FATs)
// rounded up to 40 MiB, and 32 GiB, an SDHC card's largest.
constexpr uint64_t kMinCardImageBytes = 40ull << 20;
constexpr uint64_t kMaxCardImageBytes = 32ull << 30;

// Makes a card image of `bytes` (a multiple of 512 within the limits) at `path`, replacing
// what is there. Returns an empty string, or why not in one line.
std::string make_card_image(const std::string& path, uint64_t bytes);

}  // namespace hq
