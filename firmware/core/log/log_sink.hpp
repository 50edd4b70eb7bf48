// Where the logger's bytes go: one log file at a time on the card (LogFiles, log_files.hpp,
// implements it; a test may implement it in RAM). The logger calls it from the loop's spare
// time only, never inside a loop step. Contract:
// - begin_log() opens the next log (LOGS/<n, 8 digits>.BIN, n one past the last) and records
//   its number in LASTLOG.TXT; false when the card cannot take a log (state() says why).
//   A log already open is ended first.
// - write(data, n) appends up to n bytes to the open log at the card's own speed and returns
//   how many it took: n, or fewer when the card filled up or failed (state() says which), 0
//   with no log open. The bytes are on the card (synced) at most kSyncPeriodUs after they were
//   taken, and at end_log().
// - While write() (or begin_log(), end_log()) waits for the card, the wait hook runs
//   (card_disk.hpp): the loop's step may run nested inside the call. The step never calls the
//   sink, and the bytes at `data` must stay as they are until write() returns (a RAM ring
//   frees them only after it returned).
// - end_log() syncs and closes the open log; nothing when none is open.
// - state() is the card's state for the boot report, STATUSTEXT and HQ_FW_STATUS.
#pragma once

#include <cstdint>

#include <hq_mavlink.hpp>      // HQ_CARD_STATE: the numbers HQ_FW_STATUS reports

namespace hq {

// The card as the reports name it. Ok: logs can be written. NoCard: no card answered at
// start-up. WriteProtected: the card's switch (or the card) refuses writes. Full: no room for
// another byte (a log may still be open and readable). Failed: the card or its file system
// failed (not FAT, a transfer error); logging stops until the next start-up.
enum class CardState : uint8_t {
    Ok = HQ_CARD_OK,
    NoCard = HQ_CARD_NO_CARD,
    WriteProtected = HQ_CARD_WRITE_PROTECTED,
    Full = HQ_CARD_FULL,
    Failed = HQ_CARD_FAILED,
};

// The state in the words the reports use: "ok", "no card", "write-protected", "full", "failed".
constexpr const char* card_state_name(CardState s) {
    switch (s) {
        case CardState::Ok: return "ok";
        case CardState::NoCard: return "no card";
        case CardState::WriteProtected: return "write-protected";
        case CardState::Full: return "full";
        default: return "failed";
    }
}

class LogSink {
public:
    // The longest a taken byte waits before it is synced to the card, us.
    static constexpr uint64_t kSyncPeriodUs = 1'000'000;

    virtual bool begin_log() = 0;
    virtual uint32_t write(const uint8_t* data, uint32_t n) = 0;
    virtual void end_log() = 0;
    virtual CardState state() const = 0;

protected:
    ~LogSink() = default;     // not deleted through the interface: no heap on the target
};

}  // namespace hq
