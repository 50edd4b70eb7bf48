#include "param_storage.hpp"

#include "../../core/crc32.hpp"
#include "cpu.hpp"
#include "mk64f12.hpp"
#include "watchdog.hpp"

extern "C" {
// Launches the flash command loaded in FCCOB and waits for it; returns FSTAT at the end.
// It runs from RAM (section .ramfunc, placed in .data and copied there at start-up) and
// touches nothing in flash: its constants are in its own literal pool, in RAM with it, and
// it calls nothing. The caller masks interrupts (every vector and handler is in flash) and
// has loaded FCCOB with CCIF set and ACCERR/FPVIOL clear. long_call: RAM is out of a BL's
// reach from flash.
__attribute__((section(".ramfunc"), noinline, long_call, used)) uint8_t hq_ftfe_run();
}

uint8_t hq_ftfe_run() {
    using hq::mk64::FTFE::FSTAT;
    volatile uint8_t* const fstat = reinterpret_cast<volatile uint8_t*>(uintptr_t{FSTAT::address});
    *fstat = FSTAT::CCIF;                                   // write 1 to CCIF: launch
    while ((*fstat & FSTAT::CCIF) == 0) {
    }
    return *fstat;
}

namespace hq::teensy {

namespace {

using namespace hq::mk64;
using Storage = FlashParamStorage;

constexpr uint8_t kProgramPhrase = 0x07;
constexpr uint8_t kEraseFlashSector = 0x09;

// The flash as the core reads it: volatile, since commands change it under the compiler.
using FlashBytes = const volatile uint8_t*;

FlashBytes slot_bytes(const uint8_t* first, uint32_t slot) {
    return first + slot * Storage::kSectorBytes;
}

uint32_t slot_address(const uint8_t* first, uint32_t slot) {
    return static_cast<uint32_t>(reinterpret_cast<uintptr_t>(first)) + slot * Storage::kSectorBytes;
}

uint32_t get_le32(FlashBytes p) {
    return uint32_t{p[0]} | uint32_t{p[1]} << 8 | uint32_t{p[2]} << 16 | uint32_t{p[3]} << 24;
}

void put_le32(uint8_t* p, uint32_t v) {
    for (int i = 0; i < 4; ++i) p[i] = static_cast<uint8_t>(v >> (8 * i));
}

// The CRC a header carries: of the sequence and length (little-endian) and the record.
uint32_t record_crc(uint32_t sequence, uint32_t length, FlashBytes record) {
    uint8_t head[8];
    put_le32(head, sequence);
    put_le32(head + 4, length);
    return crc32(record, length, crc32(head, sizeof head));
}

enum class SlotState : uint8_t { Blank, Valid, Invalid };

struct Slot {
    SlotState state;
    uint32_t sequence;
    uint32_t length;
};

bool blank(FlashBytes p, size_t n) {
    for (size_t i = 0; i < n; ++i) {
        if (p[i] != 0xFF) return false;
    }
    return true;
}

Slot inspect(const uint8_t* first, uint32_t expected_magic, uint32_t slot) {
    const FlashBytes p = slot_bytes(first, slot);
    const uint32_t magic = get_le32(p), sequence = get_le32(p + 4), length = get_le32(p + 8);
    if (magic == expected_magic && length <= Storage::kMaxBytes &&
        record_crc(sequence, length, p + Storage::kHeaderBytes) == get_le32(p + 12)) {
        return {SlotState::Valid, sequence, length};
    }
    return {blank(p, Storage::kSectorBytes) ? SlotState::Blank : SlotState::Invalid, 0, 0};
}

// The slot holding the newest valid record (the higher sequence; slot 0 on a tie), or -1.
int newest(const Slot (&slots)[Storage::kSlots]) {
    int best = -1;
    for (uint32_t i = 0; i < Storage::kSlots; ++i) {
        if (slots[i].state == SlotState::Valid &&
            (best < 0 || slots[i].sequence > slots[best].sequence)) {
            best = static_cast<int>(i);
        }
    }
    return best;
}

// The FMC caches flash and prefetches from it: after a command, invalidate the cache ways and
// the speculation buffer so the reads that follow see the new bytes.
void invalidate_flash_cache() {
    FMC::PFB0CR::set(FMC::PFB0CR::CINV_WAY(0xF) | FMC::PFB0CR::S_B_INV);
    dsb();
    isb();
}

// One command: FCCOB0 = command, FCCOB1-3 = address, and for Program Phrase its eight bytes,
// byte k (at address + k) in FCCOB 7, 6, 5, 4, B, A, 9, 8 (the FCCOB group is big-endian in
// each longword). True when it completed without ACCERR, FPVIOL, RDCOLERR or MGSTAT0.
bool run_command(uint8_t command, uint32_t address, const uint8_t* phrase) {
    Watchdog::refresh();                     // a command takes at most 115 ms of the 500
    IrqGuard masked;                         // no vector fetch from flash while it runs
    if ((FTFE::FSTAT::read() & FTFE::FSTAT::CCIF) == 0) return false;   // one is running
    FTFE::FSTAT::write(FTFE::FSTAT::ACCERR | FTFE::FSTAT::FPVIOL | FTFE::FSTAT::RDCOLERR);
    FTFE::FCCOB0::write(command);
    FTFE::FCCOB1::write(static_cast<uint8_t>(address >> 16));
    FTFE::FCCOB2::write(static_cast<uint8_t>(address >> 8));
    FTFE::FCCOB3::write(static_cast<uint8_t>(address));
    if (phrase != nullptr) {
        FTFE::FCCOB7::write(phrase[0]);
        FTFE::FCCOB6::write(phrase[1]);
        FTFE::FCCOB5::write(phrase[2]);
        FTFE::FCCOB4::write(phrase[3]);
        FTFE::FCCOBB::write(phrase[4]);
        FTFE::FCCOBA::write(phrase[5]);
        FTFE::FCCOB9::write(phrase[6]);
        FTFE::FCCOB8::write(phrase[7]);
    }
    const uint8_t fstat = hq_ftfe_run();
    return (fstat & (FTFE::FSTAT::ACCERR | FTFE::FSTAT::FPVIOL | FTFE::FSTAT::RDCOLERR |
                     FTFE::FSTAT::MGSTAT0)) == 0;
}

// The record's phrases (the last padded with 0xFF), then the header's second phrase (length,
// CRC), then its first (magic, sequence): the magic is the last thing written.
bool program_slot(uint32_t base, uint32_t magic, uint32_t sequence, const uint8_t* data,
                  size_t n) {
    uint8_t phrase[Storage::kPhraseBytes];
    for (size_t at = 0; at < n; at += Storage::kPhraseBytes) {
        for (size_t k = 0; k < Storage::kPhraseBytes; ++k) {
            phrase[k] = at + k < n ? data[at + k] : 0xFF;
        }
        if (!run_command(kProgramPhrase, base + Storage::kHeaderBytes + at, phrase)) return false;
    }
    put_le32(phrase, static_cast<uint32_t>(n));
    put_le32(phrase + 4, record_crc(sequence, static_cast<uint32_t>(n), data));
    if (!run_command(kProgramPhrase, base + Storage::kPhraseBytes, phrase)) return false;
    put_le32(phrase, magic);
    put_le32(phrase + 4, sequence);
    return run_command(kProgramPhrase, base, phrase);
}

}  // namespace

StoreStatus FlashParamStorage::load(uint8_t* data, size_t capacity, size_t& n) {
    n = 0;
    const Slot slots[kSlots] = {inspect(first_, magic_, 0), inspect(first_, magic_, 1)};
    const int best = newest(slots);
    if (best < 0) {
        return slots[0].state == SlotState::Blank && slots[1].state == SlotState::Blank
                   ? StoreStatus::Empty
                   : StoreStatus::Corrupt;
    }
    const uint32_t length = slots[best].length;
    if (length > capacity || (length > 0 && data == nullptr)) return StoreStatus::Corrupt;
    const FlashBytes record = slot_bytes(first_, static_cast<uint32_t>(best)) + kHeaderBytes;
    for (uint32_t i = 0; i < length; ++i) data[i] = record[i];
    n = length;
    return StoreStatus::Ok;
}

bool FlashParamStorage::save(const uint8_t* data, size_t n) {
    if (n > kMaxBytes || (n > 0 && data == nullptr)) return false;
    const Slot slots[kSlots] = {inspect(first_, magic_, 0), inspect(first_, magic_, 1)};
    const int best = newest(slots);
    const uint32_t target = best == 0 ? 1 : 0;
    const uint32_t sequence = best < 0 ? 1 : slots[best].sequence + 1;
    const uint32_t base = slot_address(first_, target);
    if (!run_command(kEraseFlashSector, base, nullptr)) return false;
    invalidate_flash_cache();
    if (!blank(slot_bytes(first_, target), kSectorBytes)) return false;
    const bool programmed = program_slot(base, magic_, sequence, data, n);
    invalidate_flash_cache();
    if (!programmed) return false;
    const Slot written = inspect(first_, magic_, target);
    if (written.state != SlotState::Valid || written.sequence != sequence || written.length != n) {
        return false;
    }
    const FlashBytes record = slot_bytes(first_, target) + kHeaderBytes;
    for (size_t i = 0; i < n; ++i) {
        if (record[i] != data[i]) return false;
    }
    return true;
}

}  // namespace hq::teensy
