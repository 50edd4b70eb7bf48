// The simulator's logger of the firmware's telemetry link (host/acquire/session.py, _TelemetryLog): reads
// what has arrived, frames the MAVLink 2 packets (CRC checked with the dialect's CRC extras),
// writes every packet to the .tlog stamped with simulated time (plus an offset: the run's
// start on the wall clock), and hands the messages a tool asked for back to Python, which
// decodes them with the host tool's codec.
//
// Stamping: each loop's telemetry ends with its HQ_SYSID_SAMPLE (docs/link-contract.md), so a
// packet gets offset_us plus the time_us of the first HQ_SYSID_SAMPLE at or after it in the
// stream (the offset is the same for every record, so a run repeats apart from it). Packets
// after the last one wait for the next; at the end of a session drain() logs them with the
// last loop's time, so nothing the firmware sent is lost.
#pragma once

#include <cstdint>
#include <vector>

#include <hq_mavlink.hpp>

namespace hqsim {

struct TappedMessage {
    uint32_t msgid = 0;
    std::vector<uint8_t> payload;      // as received (MAVLink 2 trims trailing zeros)
};

class TelemetryTap {
public:
    // tel_fd: the telemetry pty (non-blocking); tlog_fd: the .tlog file, new and empty, open
    // for writing; offset_us: added to every stamp (us since 1970 of the run's start).
    TelemetryTap(int tel_fd, int tlog_fd, std::vector<uint32_t> wanted, uint64_t offset_us = 0);

    // Everything that has arrived, logged; the wanted messages among it. Never blocks.
    std::vector<TappedMessage> read();
    // read(), then the packets still waiting for their loop's sample (a loop cut short: the
    // firmware died, or the session ended) logged with the last loop's time (0 before the
    // first). For the end of a session.
    std::vector<TappedMessage> drain();
    // The last loop's simulated time (without the offset); -1 before the first sample.
    int64_t last_time_us() const { return last_time_us_; }
    uint64_t offset_us() const { return offset_us_; }
    uint64_t packets() const { return packets_; }
    // A write to the .tlog failed (then nothing more is logged; the file ends with the last
    // whole record that reached it); write_errno() says why (ENOSPC, EFBIG: no room).
    bool write_failed() const { return write_failed_; }
    int write_errno() const { return write_errno_; }

private:
    void accept(uint32_t msgid, const uint8_t* packet, size_t total,
                std::vector<TappedMessage>* out);
    void flush_log();
    void stamp_pending(uint64_t loop_us);   // the loop's simulated time; the offset is added

    int tel_fd_, tlog_fd_;
    std::vector<uint32_t> wanted_;
    uint64_t offset_us_;
    std::vector<uint8_t> rx_;          // bytes read, not yet framed
    std::vector<uint8_t> pending_;     // packets whose loop is not known yet
    std::vector<size_t> pending_lengths_;
    std::vector<uint8_t> log_;         // stamped packets not yet written
    std::vector<size_t> log_ends_;     // where each record in log_ ends
    uint64_t written_ = 0;             // bytes in the .tlog: whole records only
    int64_t last_time_us_ = -1;
    uint64_t packets_ = 0;
    bool write_failed_ = false;
    int write_errno_ = 0;
};

}  // namespace hqsim
