// LogTransfer: the MAVLink log protocol (LOG_REQUEST_LIST -> LOG_ENTRY, LOG_REQUEST_DATA ->
// LOG_DATA, LOG_ERASE, LOG_REQUEST_END) over a GcsLink, against the logs of a LogStore
// (core/log/log_store.hpp), served as ArduPilot serves it (docs/ground-stations.md).
//
// One per board, shared by its links (each GcsLink::serve_logs() it): one transfer at a time,
// answered on the link that asked. Two halves, because every LogStore call touches the card
// and the step never may:
// - take() runs inside a link's receive (the step's side): it only keeps the request, the
//   newest replacing any older one from either link (a new request ends the old).
// - service() runs in the loop's spare time (the target's main calls it, never the step): it
//   reads the store and sends the answers on the link, as far as the log's share of the
//   link's budget (kLogLinkShare of GcsLinkConfig::link_bytes_per_s, or the rate
//   set_link_rate() gave that link; in bursts of at most kBurstPackets) and the port's room
//   allow; a packet the port cannot take waits for the next call, never dropped.
// Answers: a list is one LOG_ENTRY per log in [start, end] (end 0xffff: the last), or one
// LOG_ENTRY with num_logs 0 when there are none; data is LOG_DATA packets of up to 90 bytes
// until the count asked for or the log's end, and one LOG_DATA with count 0 for a request at
// or past the end; a log that does not exist ends the transfer with the STATUSTEXT "logs: no
// log N"; a store that fails mid-read ends it with a LOG_DATA of count 0 (end of data, as
// ArduPilot reports it) and "logs: read failed"; an erase says "logs: erased" or "logs:
// erase failed". Served disarmed only: while armed every request is refused with one
// STATUSTEXT "logs: disarm to download" (once per arming, as ArduPilot warns) and arming
// ends a transfer under way.
#pragma once

#include <cstdint>

#include "../log/log_store.hpp"

#include <hq_mavlink.hpp>

namespace hq {

class GcsLink;

class LogTransfer {
public:
    // Of the link's bytes per second, the share log answers may take: telemetry's default
    // streams take about a quarter of UART0 at 921600 baud (25 kB/s of 92 kB/s), so half
    // leaves the HEARTBEAT and every stream their room.
    static constexpr float kLogLinkShare = 0.5f;
    // The most LOG_DATA packets one service() call sends (what a USB link's budget saves up
    // while the loop is busy is not spent at once).
    static constexpr uint32_t kBurstPackets = 8;

    // A link's side (no card): a LOG_* message `from` received; false for any other message.
    bool take(GcsLink& from, const mavlink_message_t& msg);
    // The target's: the log's bytes per second on `link` (one link; 0: the default share),
    // for a link that moves more than its link_bytes_per_s while the loop waits (a USB port,
    // whose transmit buffer empties between the loop's ticks).
    void set_link_rate(const GcsLink& link, uint32_t bytes_per_s);
    // The link's side: whether the vehicle is armed now (from each loop's status).
    void set_armed(bool armed);
    // Spare time: the answers, from `store`.
    void service(LogStore& store);
    bool busy() const { return job_ != Job::Idle || pending_.kind != Job::Idle; }

private:
    enum class Job : uint8_t { Idle, List, Data, Erase, End };
    struct Request {
        Job kind = Job::Idle;
        uint16_t id = 0, start = 0, end = 0;
        uint32_t ofs = 0, count = 0;
    };
    void start(LogStore& store, const Request& r);
    void start_data(LogStore& store, const Request& r);
    bool send_entry(LogStore& store);
    bool send_data(LogStore& store);
    bool room(uint32_t bytes);
    float rate_bytes_per_s() const;
    bool emit(const mavlink_message_t& msg);
    bool send_text(uint8_t severity, const char* text, int32_t number = -1);

    GcsLink* link_ = nullptr;        // the link the transfer under way answers on
    Request pending_{};              // taken in the step, started by the next service()
    GcsLink* pending_link_ = nullptr;   // the link it came on
    GcsLink* refuse_link_ = nullptr;    // the link an armed request came on
    bool armed_ = false;
    bool warned_armed_ = false;      // "disarm to download" said since this arming
    bool refuse_ = false;            // a request came while armed: say so once
    // The job under way: a list (the next index of the store's logs to look at, the ids
    // asked for, how many logs, the last id) or data (the log, where, how much is left).
    Job job_ = Job::Idle;
    uint16_t list_index_ = 0, list_start_ = 0, list_end_ = 0, num_logs_ = 0, last_id_ = 0;
    uint16_t data_id_ = 0;
    uint32_t data_ofs_ = 0, data_left_ = 0;
    bool sent_ = false;              // a LOG_ENTRY of this list sent
    // The budget: bytes the log may still send, and the loop time it was last filled up to.
    float allowance_bytes_ = 0.0f;
    uint64_t filled_us_ = 0;
    // The link with a rate of its own (set_link_rate), and that rate.
    const GcsLink* rated_link_ = nullptr;
    uint32_t rated_bytes_per_s_ = 0;
};

}  // namespace hq
