// Host backend of the HAL block device (hal/block_device.hpp): a card-image file, the card's
// blocks one after another from byte 0 (docs/sd-card.md), with the faults a test sets.
//
// Transfers happen at once in begin_*(); the card's busy time after a write is lockstep time
// (the Clock given, set by the simulator's frames), so a busy card costs the same loop steps in
// every run. Faults (CardFaults, all off by default):
// - no_card: start() says NoCard, every transfer NoCard;
// - write_protected: the switch is on: writes say WriteProtected;
// - writable_blocks N (0: off): writes to a block at or past N say OutOfRange (a full card);
// - failing_writes: every write says Failed, nothing written;
// - busy_after_write_us: poll() says Busy for this long after each write's data;
// - busy_every_us / busy_for_us: poll() also says Busy for busy_for_us once every busy_every_us
//   (the card's own housekeeping), measured from start();
// - power_cut_after_writes N (0: off): after N blocks were written the power is gone: the file
//   keeps exactly those blocks, every later transfer says NoCard.
#pragma once

#include <cstdint>
#include <cstdio>
#include <string>

#include "../../hal/block_device.hpp"
#include "../../hal/clock.hpp"

namespace hq {

struct CardFaults {
    bool no_card = false;
    bool write_protected = false;
    uint32_t writable_blocks = 0;
    bool failing_writes = false;
    uint64_t busy_after_write_us = 0;
    uint64_t busy_every_us = 0, busy_for_us = 0;
    uint32_t power_cut_after_writes = 0;
};

// Sets the fault `name` (a CardFaults member's name) to `value` (1/0 for the flags); false for
// an unknown name. The one reading of fault names: heliquad-fw-host's --sd-faults and the
// bindings.
bool set_card_fault(CardFaults& faults, const std::string& name, uint64_t value);

class FileBlockDevice final : public BlockDevice {
public:
    // A card whose blocks are the file at `path` (its size rounded down to whole blocks).
    FileBlockDevice(std::string path, const Clock& clock) : path_(std::move(path)), clock_(clock) {}
    ~FileBlockDevice();
    FileBlockDevice(const FileBlockDevice&) = delete;
    FileBlockDevice& operator=(const FileBlockDevice&) = delete;

    void set_faults(const CardFaults& faults) { faults_ = faults; }
    const CardFaults& faults() const { return faults_; }
    // Ends the card's busy time now and for good (the busy faults off): the host build lets
    // a waiting FatFs call finish this way when it must exit.
    void release() {
        faults_.busy_after_write_us = faults_.busy_every_us = faults_.busy_for_us = 0;
        busy_until_us_ = 0;
    }
    // Blocks written to the file since start() (what a power cut counts).
    uint32_t blocks_written() const { return blocks_written_; }

    BlockStatus start() override;
    uint32_t block_count() const override { return blocks_; }
    bool write_protected() const override { return faults_.write_protected; }
    BlockStatus begin_read(uint32_t lba, uint8_t* data, uint32_t n) override;
    BlockStatus begin_write(uint32_t lba, const uint8_t* data, uint32_t n) override;
    BlockStatus poll() override;

private:
    bool busy() const;
    BlockStatus finish(BlockStatus s);

    std::string path_;
    const Clock& clock_;
    CardFaults faults_;
    std::FILE* file_ = nullptr;
    uint32_t blocks_ = 0, blocks_written_ = 0;
    uint64_t started_us_ = 0, busy_until_us_ = 0;
    BlockStatus result_ = BlockStatus::Ok;
    bool powered_ = true;
};

}  // namespace hq
