// A LogStore in RAM for the host build (never in the Teensy image): the .BIN files of a
// folder, read once at start (heliquad-fw-host --log-store-ram DIR), served by the MAVLink
// log protocol until the card-backed store takes its place. A file named as the card names
// its logs (8 digits, 00000001.BIN) keeps that number; the others are numbered after the
// highest, in name order. Its time is the file's modification time. erase_all() forgets them
// all (the folder is never changed).
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "../../core/log/log_store.hpp"

namespace hq {

class RamLogStore final : public LogStore {
public:
    // The .BIN files of `folder` (upper or lower case), oldest number first; an empty string
    // and sets `error` when the folder or a file cannot be read.
    bool load(const std::string& folder, std::string& error);

    uint16_t count() override { return static_cast<uint16_t>(logs_.size()); }
    bool info(uint16_t index, LogInfo& out) override;
    int32_t read(uint16_t id, uint32_t offset, uint8_t* data, uint32_t n) override;
    bool erase_all() override;

private:
    struct Log {
        LogInfo info;
        std::vector<uint8_t> bytes;
    };
    std::vector<Log> logs_;
};

}  // namespace hq
