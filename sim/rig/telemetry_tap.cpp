#include "rig/telemetry_tap.hpp"

#include <unistd.h>

#include <algorithm>
#include <cerrno>

namespace hqsim {
namespace {

// The MAVLink library's own constants. The tap frames for itself rather than with the library's
// parser (mavlink_frame_char_buffer, which the firmware and the sim link use) because that
// parser swallows the packet after a damaged header while it waits for the bogus length:
// this framer scans on from the next start byte, as sim/base/framing.py does, and loses nothing.
constexpr uint8_t kStx2 = MAVLINK_STX;
constexpr size_t kHeader = MAVLINK_NUM_HEADER_BYTES;
constexpr size_t kCrc = MAVLINK_NUM_CHECKSUM_BYTES;
constexpr size_t kSignature = MAVLINK_SIGNATURE_BLOCK_LEN;

}  // namespace

TelemetryTap::TelemetryTap(int tel_fd, int tlog_fd, std::vector<uint32_t> wanted,
                           uint64_t offset_us)
    : tel_fd_(tel_fd), tlog_fd_(tlog_fd), wanted_(std::move(wanted)), offset_us_(offset_us) {}

std::vector<TappedMessage> TelemetryTap::read() {
    std::vector<TappedMessage> out;
    uint8_t buf[16384];
    for (;;) {
        const ssize_t n = ::read(tel_fd_, buf, sizeof buf);
        if (n <= 0) break;                        // EAGAIN: all read
        rx_.insert(rx_.end(), buf, buf + n);
    }
    size_t pos = 0;
    // Frames whole, CRC-checked packets. Anything else is skipped a byte at a time until the
    // next valid start, as host/mavframe.py's Framer does, so the stream resynchronises.
    while (pos < rx_.size()) {
        const auto start = std::find(rx_.begin() + static_cast<long>(pos), rx_.end(), kStx2);
        pos = static_cast<size_t>(start - rx_.begin());
        if (rx_.size() - pos < kHeader) break;
        const uint8_t* p = rx_.data() + pos;
        const size_t len = p[1];
        const size_t total = kHeader + len + kCrc + ((p[2] & MAVLINK_IFLAG_SIGNED) ? kSignature : 0);
        if (rx_.size() - pos < total) break;
        const uint32_t msgid = p[7] | (p[8] << 8) | (static_cast<uint32_t>(p[9]) << 16);
        const mavlink_msg_entry_t* entry = mavlink_get_msg_entry(msgid);
        uint16_t crc = crc_calculate(p + 1, static_cast<uint16_t>(kHeader - 1 + len));
        if (entry) crc_accumulate(entry->crc_extra, &crc);
        if (!entry || crc != (p[kHeader + len] | (p[kHeader + len + 1] << 8))) {
            ++pos;                                // not a packet: resync
            continue;
        }
        accept(msgid, p, total, &out);
        pos += total;
    }
    rx_.erase(rx_.begin(), rx_.begin() + static_cast<long>(pos));
    flush_log();
    return out;
}

void TelemetryTap::accept(uint32_t msgid, const uint8_t* packet, size_t total,
                          std::vector<TappedMessage>* out) {
    pending_.insert(pending_.end(), packet, packet + total);
    pending_lengths_.push_back(total);
    ++packets_;
    const uint8_t* payload = packet + kHeader;
    const size_t len = packet[1];
    if (std::find(wanted_.begin(), wanted_.end(), msgid) != wanted_.end()) {
        out->push_back({msgid, std::vector<uint8_t>(payload, payload + len)});
    }
    if (msgid != MAVLINK_MSG_ID_HQ_SYSID_SAMPLE) return;
    // The loop is known: stamp everything pending with its time (8 bytes, big-endian).
    // time_us is the payload's first field (uint64, little-endian; MAVLink 2 may have
    // trimmed trailing zero bytes, which read as zero).
    uint64_t t = 0;
    for (size_t b = 0; b < 8 && b < len; ++b) t |= static_cast<uint64_t>(payload[b]) << (8 * b);
    stamp_pending(t);
    last_time_us_ = static_cast<int64_t>(t);
}

std::vector<TappedMessage> TelemetryTap::drain() {
    std::vector<TappedMessage> out = read();
    if (!pending_lengths_.empty()) {
        stamp_pending(last_time_us_ < 0 ? 0 : static_cast<uint64_t>(last_time_us_));
        flush_log();
    }
    return out;
}

void TelemetryTap::stamp_pending(uint64_t loop_us) {
    const uint64_t t = loop_us + offset_us_;
    size_t at = 0;
    for (const size_t plen : pending_lengths_) {
        for (int b = 7; b >= 0; --b) log_.push_back(static_cast<uint8_t>(t >> (8 * b)));
        log_.insert(log_.end(), pending_.begin() + static_cast<long>(at),
                    pending_.begin() + static_cast<long>(at + plen));
        log_ends_.push_back(log_.size());
        at += plen;
    }
    pending_.clear();
    pending_lengths_.clear();
}

void TelemetryTap::flush_log() {
    size_t done = 0;
    while (!write_failed_ && done < log_.size()) {
        const ssize_t w = ::write(tlog_fd_, log_.data() + done, log_.size() - done);
        if (w < 0 && errno == EINTR) continue;
        if (w <= 0) {
            // No room (or another error): keep the whole records that reached the file, cut
            // a record left half written, and log nothing more.
            write_errno_ = w < 0 ? errno : ENOSPC;
            write_failed_ = true;
            const auto whole = std::upper_bound(log_ends_.begin(), log_ends_.end(), done);
            const size_t kept = whole == log_ends_.begin() ? 0 : *(whole - 1);
            if (::ftruncate(tlog_fd_, static_cast<off_t>(written_ + kept)) == 0) done = kept;
            break;
        }
        done += static_cast<size_t>(w);
    }
    written_ += done;
    log_.clear();
    log_ends_.clear();
}

}  // namespace hqsim
