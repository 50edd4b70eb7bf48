// The logs on the card as the MAVLink log protocol sees them (LOG_REQUEST_LIST, _DATA, _ERASE):
// the files LOGS/00000001.BIN ... numbered from 1, oldest first. Contract:
// - Every call touches the card, so it runs in the loop's spare time, never inside a loop
//   step (the step only queues a request; the spare-time service answers it), and never
//   while a log is being written (the protocol is served disarmed only).
// - count() is the number of logs (0 with no card); info() gives the i-th (0-based, oldest
//   first): its number (the file's), size in bytes and the UTC time it was written (0 when
//   the board had no time); false when there is no such log.
// - read() copies up to n bytes of log `id` from `offset` and returns how many it copied: 0 at
//   or past the end, -1 when the log does not exist or the card failed.
// - erase_all() removes every log and resets the numbering; false when the card refused.
#pragma once

#include <cstdint>

namespace hq {

struct LogInfo {
    uint16_t id = 0;            // the log's number (LOGS/<id, 8 digits>.BIN)
    uint32_t size_bytes = 0;
    uint32_t time_utc_s = 0;    // seconds since 1970, 0 when unknown
};

class LogStore {
public:
    virtual uint16_t count() = 0;
    virtual bool info(uint16_t index, LogInfo& out) = 0;
    virtual int32_t read(uint16_t id, uint32_t offset, uint8_t* data, uint32_t n) = 0;
    virtual bool erase_all() = 0;

protected:
    ~LogStore() = default;
};

}  // namespace hq
