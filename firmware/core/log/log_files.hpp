// The logs on the card as files (docs/sd-card.md): FatFs on a BlockDevice, one log open at a
// time. LogFiles is the card's one user, owned by the spare-time service (spare_time.hpp): it
// is the logger's LogSink (log_sink.hpp) and the log protocol's LogStore (log_store.hpp).
//
// Layout: LOGS/00000001.BIN, LOGS/00000002.BIN, ... (8 decimal digits, numbered from 1) and
// LASTLOG.TXT in the root, the number of the last log begun as decimal text and CR LF (as
// ArduPilot writes it). The next log is one past the larger of LASTLOG.TXT's number and the
// largest number among the files present, so a missing or damaged LASTLOG.TXT, or one left
// behind by a power cut, never makes a log overwrite another.
//
// mount() runs once at start-up (the card's start() may take milliseconds there): the card
// started, its FAT volume mounted, LOGS/ made, the last number found. Its CardState is what
// the reports say; a card that is not Ok takes no log (begin_log() false) and stays as it is
// until the next start-up, except a full card, which an erase makes Ok again. A full or
// write-protected card still lists and reads its logs.
#pragma once

#include <cstdint>

#include "../../hal/block_device.hpp"
#include "../../hal/clock.hpp"
#include "card_disk.hpp"
#include "ff.h"
#include "log_sink.hpp"
#include "log_store.hpp"

namespace hq {

class LogFiles final : public LogSink, public LogStore {
public:
    // The card, the clock the syncs are timed by, and what runs while the card is busy.
    LogFiles(BlockDevice& card, const Clock& clock, CardWait* wait)
        : card_(card), clock_(clock), wait_(wait) {}
    // Closes the open file and lets go of the card (FatFs keeps a pointer to the volume).
    ~LogFiles();
    LogFiles(const LogFiles&) = delete;
    LogFiles& operator=(const LogFiles&) = delete;

    CardState mount();
    // Syncs the open log when its oldest unsynced byte is due (LogSink::kSyncPeriodUs); the
    // spare-time service calls it every time it runs.
    void service();
    // The number of the last log begun (0: none yet).
    uint16_t last_log() const { return last_; }
    bool writing() const { return mode_ == Mode::Writing; }

    // LogSink
    bool begin_log() override;
    uint32_t write(const uint8_t* data, uint32_t n) override;
    void end_log() override;
    CardState state() const override { return state_; }

    // LogStore
    uint16_t count() override;
    bool info(uint16_t index, LogInfo& out) override;
    int32_t read(uint16_t id, uint32_t offset, uint8_t* data, uint32_t n) override;
    bool erase_all() override;

private:
    enum class Mode : uint8_t { Closed, Writing, Reading };

    // The log after `after_id` with the smallest number: false when there is none.
    bool next_log(uint16_t after_id, LogInfo& out);
    uint16_t largest_log();
    uint16_t read_lastlog();
    bool write_lastlog(uint16_t id);
    bool sync();
    void close();
    // A failed FatFs call: the card's state from it (what the card said last), logging stops.
    void fail(FRESULT res);
    CardState state_of(FRESULT res) const;

    BlockDevice& card_;
    const Clock& clock_;
    CardWait* wait_;
    FATFS fs_{};
    FIL file_{};
    Mode mode_ = Mode::Closed;
    bool mounted_ = false;
    CardState state_ = CardState::NoCard;
    uint16_t last_ = 0, reading_id_ = 0;
    bool unsynced_ = false;
    uint64_t unsynced_since_us_ = 0;
    // info(): the listing goes forward one log at a time; the last answer is remembered.
    uint16_t listed_index_ = 0, listed_id_ = 0;
};

}  // namespace hq
