// A card of 512-byte blocks: the Teensy's built-in microSD socket through the SDHC controller,
// a card-image file on the host build. Contract:
// - Never blocks. A transfer is begun and then polled: begin_read()/begin_write() start one
//   transfer of n consecutive blocks and return Ok (started) or why not (Busy: the previous
//   transfer is not finished; NoCard, WriteProtected, OutOfRange, Failed). poll() says how the
//   transfer begun last stands: Busy while it runs (a write stays Busy while the card holds
//   its busy signal after the data), then Ok, or Failed once and the device is usable again.
//   The buffer handed to begin_*() belongs to the device until poll() stops saying Busy.
// - start() finds the card by its answers (no answer: NoCard) and may be called again after
//   NoCard or Failed (a card inserted later, a reset card); it is the one call allowed to
//   take milliseconds (start-up only, never while armed).
// - block_count() is the card's size in blocks once start() has said Ok, else 0.
// Whoever waits for poll() decides what to do meanwhile (the firmware runs its loop step when
// one is due: a card busy for 250 ms must never make the loop late).
#pragma once

#include <cstdint>

namespace hq {

enum class BlockStatus : uint8_t {
    Ok = 0,
    Busy = 1,
    NoCard = 2,
    WriteProtected = 3,
    OutOfRange = 4,
    Failed = 5,
};

class BlockDevice {
public:
    static constexpr uint32_t kBlockBytes = 512;

    virtual BlockStatus start() = 0;
    virtual uint32_t block_count() const = 0;
    virtual bool write_protected() const = 0;
    virtual BlockStatus begin_read(uint32_t lba, uint8_t* data, uint32_t n) = 0;
    virtual BlockStatus begin_write(uint32_t lba, const uint8_t* data, uint32_t n) = 0;
    virtual BlockStatus poll() = 0;

protected:
    ~BlockDevice() = default;     // not deleted through the interface: no heap on the target
};

}  // namespace hq
