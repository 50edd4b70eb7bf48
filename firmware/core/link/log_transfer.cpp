// LogTransfer: the log protocol's requests kept in the step, answered from the LogStore in
// spare time (log_transfer.hpp says what is answered how).
#include "log_transfer.hpp"

#include "gcs_link.hpp"
#include "link_util.hpp"

namespace hq {

namespace {

constexpr uint32_t kDataBytes = MAVLINK_MSG_LOG_DATA_FIELD_DATA_LEN;      // 90 a packet
constexpr uint16_t kLastLog = 0xffff;          // LOG_REQUEST_LIST.end: up to the last log

// `text` then `number` in decimal (negative: none), NUL-terminated within kStatusTextLen.
void compose(char out[kStatusTextLen], const char* text, int32_t number) {
    size_t len = 0;
    for (; text[len] != '\0' && len + 1 < kStatusTextLen; ++len) out[len] = text[len];
    if (number >= 0) {
        char digits[10];
        int n = 0;
        uint32_t v = static_cast<uint32_t>(number);
        do {
            digits[n++] = static_cast<char>('0' + v % 10);
            v /= 10;
        } while (v != 0);
        while (n > 0 && len + 1 < kStatusTextLen) out[len++] = digits[--n];
    }
    out[len] = '\0';
}

// The index of log `id` in the store, with its info; false when there is none.
bool find_log(LogStore& store, uint16_t id, LogInfo& out) {
    const uint16_t n = store.count();
    for (uint16_t i = 0; i < n; ++i) {
        if (store.info(i, out) && out.id == id) return true;
    }
    return false;
}

}  // namespace

bool LogTransfer::take(GcsLink& from, const mavlink_message_t& msg) {
    Request r;
    uint8_t system = 0, component = 0;
    switch (msg.msgid) {
        case MAVLINK_MSG_ID_LOG_REQUEST_LIST: {
            mavlink_log_request_list_t m;
            mavlink_msg_log_request_list_decode(&msg, &m);
            r = Request{Job::List, 0, m.start, m.end, 0, 0};
            system = m.target_system, component = m.target_component;
            break;
        }
        case MAVLINK_MSG_ID_LOG_REQUEST_DATA: {
            mavlink_log_request_data_t m;
            mavlink_msg_log_request_data_decode(&msg, &m);
            r = Request{Job::Data, m.id, 0, 0, m.ofs, m.count};
            system = m.target_system, component = m.target_component;
            break;
        }
        case MAVLINK_MSG_ID_LOG_ERASE:
            r.kind = Job::Erase;
            system = mavlink_msg_log_erase_get_target_system(&msg);
            component = mavlink_msg_log_erase_get_target_component(&msg);
            break;
        case MAVLINK_MSG_ID_LOG_REQUEST_END:
            r.kind = Job::End;
            system = mavlink_msg_log_request_end_get_target_system(&msg);
            component = mavlink_msg_log_request_end_get_target_component(&msg);
            break;
        default:
            return false;
    }
    if (!from.for_us(system, component)) return true;
    if (armed_) {
        if (!warned_armed_) refuse_link_ = &from;
        refuse_ = refuse_ || !warned_armed_;
        warned_armed_ = true;
        return true;
    }
    pending_ = r;                                // the newest request wins
    pending_link_ = &from;
    return true;
}

void LogTransfer::set_armed(bool armed) {
    if (armed && !armed_) {                      // arming ends whatever was under way
        job_ = Job::Idle;
        pending_ = Request{};
    }
    if (!armed) warned_armed_ = false;
    armed_ = armed;
}

void LogTransfer::set_link_rate(const GcsLink& link, uint32_t bytes_per_s) {
    rated_link_ = &link;
    rated_bytes_per_s_ = bytes_per_s;
}

void LogTransfer::service(LogStore& store) {
    if (refuse_) {
        link_ = refuse_link_;
        if (send_text(MAV_SEVERITY_ERROR, "logs: disarm to download")) refuse_ = false;
    }
    if (armed_) return;                          // the card is the logger's while armed
    if (pending_.kind != Job::Idle) {
        // Taken and cleared with no store call between: a step nested in a store call (a
        // card busy) may keep a newer request, which the next call starts.
        const Request r = pending_;
        link_ = pending_link_;
        pending_ = Request{};
        start(store, r);
    }
    for (bool more = true; more;) {
        more = job_ == Job::List ? send_entry(store) : job_ == Job::Data && send_data(store);
    }
}

void LogTransfer::start(LogStore& store, const Request& r) {
    job_ = Job::Idle;                            // a new request ends the old transfer
    sent_ = false;
    switch (r.kind) {
        case Job::List: {
            num_logs_ = store.count();
            LogInfo last;
            last_id_ = num_logs_ > 0 && store.info(static_cast<uint16_t>(num_logs_ - 1), last)
                           ? last.id : 0;
            list_index_ = 0;
            list_start_ = r.start;
            list_end_ = r.end == kLastLog || r.end > last_id_ ? last_id_ : r.end;
            job_ = Job::List;
            return;
        }
        case Job::Data: start_data(store, r); return;
        case Job::Erase:
            if (store.erase_all()) send_text(MAV_SEVERITY_INFO, "logs: erased");
            else send_text(MAV_SEVERITY_WARNING, "logs: erase failed");
            return;
        default: return;                         // LOG_REQUEST_END: nothing more
    }
}

void LogTransfer::start_data(LogStore& store, const Request& r) {
    LogInfo info;
    if (!find_log(store, r.id, info)) {
        send_text(MAV_SEVERITY_WARNING, "logs: no log ", r.id);
        return;
    }
    data_id_ = r.id;
    data_ofs_ = r.ofs;
    const uint32_t after = r.ofs >= info.size_bytes ? 0 : info.size_bytes - r.ofs;
    data_left_ = after < r.count ? after : r.count;
    job_ = Job::Data;
}

// The next LOG_ENTRY of a list; false when the budget or the port has no room for it.
bool LogTransfer::send_entry(LogStore& store) {
    mavlink_message_t msg;
    GcsLinkConfig& c = link_->config_;
    if (num_logs_ == 0) {                        // no logs (or no card): one empty entry
        mavlink_msg_log_entry_pack_status(c.system_id, c.component_id, &link_->tx_status_, &msg,
                                          0, 0, 0, 0, 0);
        if (!emit(msg)) return false;
        job_ = Job::Idle;
        return true;
    }
    for (; list_index_ < num_logs_; ++list_index_) {
        LogInfo info;
        const bool listed = store.info(list_index_, info);
        if (job_ != Job::List) return false;    // a step nested in the read armed: ended
        if (!listed || info.id < list_start_ || info.id > list_end_) continue;
        if (!room(packet_bytes(MAVLINK_MSG_ID_LOG_ENTRY))) return false;
        mavlink_msg_log_entry_pack_status(c.system_id, c.component_id, &link_->tx_status_, &msg,
                                          info.id, num_logs_, list_end_, info.time_utc_s,
                                          info.size_bytes);
        if (!emit(msg)) return false;
        ++list_index_;
        sent_ = true;
        return true;
    }
    job_ = Job::Idle;
    if (!sent_) send_text(MAV_SEVERITY_WARNING, "logs: none in the range asked for");
    return false;
}

// The next LOG_DATA; false when the budget or the port has no room (the same bytes are
// read again next time) or the transfer has ended.
bool LogTransfer::send_data(LogStore& store) {
    if (!room(packet_bytes(MAVLINK_MSG_ID_LOG_DATA))) return false;
    uint8_t data[kDataBytes] = {};
    const uint32_t n = data_left_ < kDataBytes ? data_left_ : kDataBytes;
    const int32_t read = n == 0 ? 0 : store.read(data_id_, data_ofs_, data, n);
    if (job_ != Job::Data) return false;        // a step nested in the read armed: ended
    const uint8_t got = static_cast<uint8_t>(read < 0 ? 0 : read);
    GcsLinkConfig& c = link_->config_;
    mavlink_message_t msg;
    mavlink_msg_log_data_pack_status(c.system_id, c.component_id, &link_->tx_status_, &msg,
                                     data_id_, data_ofs_, got, data);
    if (!emit(msg)) return false;
    data_ofs_ += got;
    data_left_ -= got;
    if (read < 0) send_text(MAV_SEVERITY_WARNING, "logs: read failed");
    if (got < kDataBytes || data_left_ == 0) {
        job_ = Job::Idle;
        return false;
    }
    return true;
}

// The log's bytes per second on the link answered: its own rate, or the share of the link.
float LogTransfer::rate_bytes_per_s() const {
    if (link_ == rated_link_ && rated_bytes_per_s_ != 0) {
        return static_cast<float>(rated_bytes_per_s_);
    }
    return kLogLinkShare * static_cast<float>(link_->config_.link_bytes_per_s);
}

// Whether the log's share of the link has `bytes` left, after adding what the time since the
// last call earned (at most kBurstPackets packets' worth saved up).
bool LogTransfer::room(uint32_t bytes) {
    const uint64_t now = link_->loop_time_us_;
    const float cap = static_cast<float>(kBurstPackets * packet_bytes(MAVLINK_MSG_ID_LOG_DATA));
    if (now > filled_us_) {
        allowance_bytes_ += static_cast<float>(now - filled_us_) * 1e-6f * rate_bytes_per_s();
        filled_us_ = now;
    }
    if (allowance_bytes_ > cap) allowance_bytes_ = cap;
    return allowance_bytes_ >= static_cast<float>(bytes);
}

// Sends a packed answer within the budget; when the port has no room nothing is counted
// and its sequence number is taken back, so the receiver sees no gap.
bool LogTransfer::emit(const mavlink_message_t& msg) {
    const uint32_t bytes = mavlink_msg_get_send_buffer_length(&msg);
    if (!room(bytes) || !link_->offer(msg)) {
        link_->tx_status_.current_tx_seq = msg.seq;
        return false;
    }
    allowance_bytes_ -= static_cast<float>(bytes);
    return true;
}

bool LogTransfer::send_text(uint8_t severity, const char* text, int32_t number) {
    char out[kStatusTextLen];
    compose(out, text, number);
    return link_->send_statustext(severity, out);
}

}  // namespace hq
