// The Teensy 3.5's record storage (hal/param_storage.hpp) in program flash, written through
// the flash module (FTFE): the parameters in the top two 4 KiB sectors (0x7E000-0x7FFFF,
// hq_param_flash_start/_end) and the on-board program in the two below them (0x7C000-0x7DFFF,
// hq_program_flash_start/_end), both reserved by the linker script; each its own magic, so
// neither's sectors ever read as the other's record. docs/teensy35.md, "Parameter storage",
// has the layout and the rules; in short:
//
// - Each sector is a slot: a 16-byte header, then the record (at most kMaxBytes, padded with
//   0xFF to a whole 8-byte phrase):
//       0 magic (its own)  4 sequence   8 record length   12 CRC-32 of sequence, length, record
//   (little-endian words; the CRC is IEEE 802.3's, reflected, as zlib's crc32). A slot is
//   valid when its magic, length and CRC agree.
// - load() returns the valid slot with the highest sequence: Ok. Both sectors blank (every byte
//   0xFF): Empty. Anything else (no valid slot, something written): Corrupt; a valid record
//   longer than `capacity` is Corrupt too (it cannot be delivered).
// - save() writes the slot that does not hold the newest valid record, with the next
//   sequence: erase, check blank, program the record's phrases, then the header's second phrase
//   (length, CRC), then its first (magic, sequence) LAST; then it reads the slot back and
//   compares. A save cut short (reset, power loss) leaves that slot without its magic, so the
//   other slot's record is still the newest valid one: the previous record loads.
// - Each flash command runs with interrupts masked, launched and waited for by a function in
//   RAM (the MK64FX512's program flash is one block: an instruction fetched from it while a
//   command runs is a read collision). save() blocks the caller: an erase takes 15 ms typical
//   (115 ms at most), a phrase 90 us (150 us), so a 1 KiB record about 27 ms (at most 135 ms),
//   interrupts masked for up to one erase at a time; the watchdog (500 ms) is refreshed before
//   each command. The firmware saves only while disarmed (the core's rule).
// - No state: every call reads the flash afresh. Not reentrant (one caller, the main loop).
#pragma once

#include <cstddef>
#include <cstdint>

#include "../../hal/param_storage.hpp"

extern "C" {
// The parameter sectors and the on-board program's, from the linker script (mk64fx512.ld).
extern const uint8_t hq_param_flash_start[];
extern const uint8_t hq_program_flash_start[];
}

namespace hq::teensy {

class FlashParamStorage final : public hq::ParamStorage {
public:
    static constexpr uint32_t kSectorBytes = 4096;
    static constexpr uint32_t kSlots = 2;
    static constexpr uint32_t kHeaderBytes = 16;
    static constexpr uint32_t kPhraseBytes = 8;
    static constexpr uint32_t kParamMagic = 0x31505148u;     // "HQP1" in memory order
    static constexpr uint32_t kProgramMagic = 0x31475148u;   // "HQG1"
    static_assert(kHeaderBytes + kMaxBytes <= kSectorBytes, "a record fits its slot");

    // The parameters' sectors, and the on-board program's (constant: a static one is
    // initialised before start-up runs any code).
    static constexpr FlashParamStorage parameters() {
        return FlashParamStorage(hq_param_flash_start, kParamMagic);
    }
    static constexpr FlashParamStorage program() {
        return FlashParamStorage(hq_program_flash_start, kProgramMagic);
    }

    StoreStatus load(uint8_t* data, size_t capacity, size_t& n) override;
    bool save(const uint8_t* data, size_t n) override;

private:
    constexpr FlashParamStorage(const uint8_t* first_sector, uint32_t magic)
        : first_(first_sector), magic_(magic) {}
    const uint8_t* first_;        // the first of the two sectors
    uint32_t magic_;
};

}  // namespace hq::teensy
