// GcsLink's messages in (each turned into a loop request or kept for the link's own
// answer), the answers to commands and excitation requests, and the sending of every message
// (gcs_link.hpp says what is sent when; docs/link-contract.md is the user's view).
#include "gcs_link.hpp"

#include <cmath>
#include <type_traits>

#include "link_util.hpp"

namespace hq {

// The core's enums take their values from the dialect (types.hpp, excitation.hpp,
// supervisor.hpp); the arrays the messages carry must match the core's.
static_assert(kMaxRotors == MAVLINK_MSG_HQ_SYSID_SAMPLE_FIELD_MOTOR_LEN &&
              kMaxRotors == MAVLINK_MSG_HQ_ACTUATOR_FRAME_FIELD_MOTOR_LEN, "one motor value per rotor");
static_assert(LoopInbox::kCapacity < 128, "Received::request holds a slot");

GcsLink::GcsLink(const GcsLinkConfig& config, SerialPort& port, LoopInbox& inbox)
    : config_(config), port_(port), inbox_(inbox),
      streams_{{MAVLINK_MSG_ID_HEARTBEAT, 1000000, 1000000, false, 0},
               {MAVLINK_MSG_ID_HQ_FW_STATUS, 1000000, 1000000, false, 0},
               {MAVLINK_MSG_ID_SYS_STATUS, 1000000, 1000000, false, 0},
               {MAVLINK_MSG_ID_ATTITUDE, 1, 1, false, 0},          // every loop
               {MAVLINK_MSG_ID_SERVO_OUTPUT_RAW, 100000, 100000, false, 0},
               {MAVLINK_MSG_ID_SCALED_IMU, 100000, 100000, false, 0},
               // SI units: what MAVSDK's imu() and other clients wait for
               {MAVLINK_MSG_ID_HIGHRES_IMU, 100000, 100000, false, 0},
               {MAVLINK_MSG_ID_RC_CHANNELS, 200000, 200000, false, 0},
               {MAVLINK_MSG_ID_AUTOPILOT_VERSION, 0, 0, false, 0}} {}   // on request only

bool GcsLink::for_us(uint8_t target_system, uint8_t target_component) const {
    return (target_system == 0 || target_system == config_.system_id) &&
           (target_component == 0 || target_component == config_.component_id);
}

// --- in ------------------------------------------------------------------------------------

void GcsLink::receive() {
    received_count_ = 0;
    if (have_held_) {
        have_held_ = false;
        take(rx_msg_);
    }
    for (;;) {
        if (rx_pos_ == rx_len_) {
            rx_len_ = port_.read(rx_buf_, sizeof(rx_buf_));
            rx_pos_ = 0;
            if (rx_len_ == 0) return;
        }
        while (rx_pos_ < rx_len_) {
            // A whole message is taken where the framer built it (rx_msg_), not copied out:
            // the framer writes rx_msg_ again only when it is given the next byte.
            if (mavlink_frame_char_buffer(&rx_msg_, &rx_status_, rx_buf_[rx_pos_++], nullptr,
                                          nullptr) == MAVLINK_FRAMING_OK && !take(rx_msg_)) {
                have_held_ = true;           // no room this loop: it and the rest wait
                return;
            }
        }
    }
}

// Keeps a message that asks the loop something or gets an answer (others are ignored);
// false when this loop has no room left for it.
bool GcsLink::take(const mavlink_message_t& msg) {
    if (received_count_ == LoopInbox::kCapacity) return false;
    if (logs_ != nullptr && logs_->take(*this, msg)) return true;    // kept for the spare time
    if (inbox_.has_excitation &&
        ((msg.msgid == MAVLINK_MSG_ID_HQ_EXCITATION &&
          mavlink_msg_hq_excitation_get_action(&msg) == HQ_EXCITATION_START) ||
         (msg.msgid == MAVLINK_MSG_ID_HQ_PROGRAM &&
          mavlink_msg_hq_program_get_action(&msg) == HQ_PROGRAM_STEP))) {
        return false;                        // one start's (or step's) configuration a loop
    }
    Received& in = received_[received_count_];
    const bool answered = keep(msg, in);
    LoopRequest r;
    const bool asks = ask(msg, in, answered, r);
    if (!answered && !asks) return true;
    in.request = -1;
    if (asks) {
        in.request = static_cast<int8_t>(inbox_.count);
        inbox_.request[inbox_.count++] = r;
    }
    ++received_count_;
    return true;
}

// A command's number and parameters (COMMAND_INT's x, y, z where COMMAND_LONG has param5 to
// param7) into `in`; whether it is addressed to us.
template <typename Command>
bool GcsLink::keep_command(const Command& c, float p5, float p6, float p7, Received& in) const {
    const float p[7] = {c.param1, c.param2, c.param3, c.param4, p5, p6, p7};
    __builtin_memcpy(in.p, p, sizeof(p));
    in.command = c.command;
    return for_us(c.target_system, c.target_component);
}

// A parameter read or set, decoded by `decode`: its name, and its index (a read) or its type
// (a set), into `in`; whether it is addressed to us.
template <typename ParamMessage>
bool GcsLink::keep_param(const mavlink_message_t& msg,
                         void (*decode)(const mavlink_message_t*, ParamMessage*),
                         Received& in) const {
    ParamMessage m;
    decode(&msg, &m);
    __builtin_memcpy(in.param_id, m.param_id, kParamNameLen);
    if constexpr (std::is_same_v<ParamMessage, mavlink_param_set_t>) {
        in.param_type = m.param_type;
    } else {
        in.param_index = m.param_index;
    }
    return for_us(m.target_system, m.target_component);
}

// What the answer to a message needs, for a message addressed to us that gets one.
bool GcsLink::keep(const mavlink_message_t& msg, Received& in) const {
    in.msgid = msg.msgid;
    in.sysid = msg.sysid;
    in.compid = msg.compid;
    switch (msg.msgid) {
        case MAVLINK_MSG_ID_COMMAND_LONG: {
            mavlink_command_long_t c;
            mavlink_msg_command_long_decode(&msg, &c);
            return keep_command(c, c.param5, c.param6, c.param7, in);
        }
        case MAVLINK_MSG_ID_COMMAND_INT: {
            mavlink_command_int_t c;
            mavlink_msg_command_int_decode(&msg, &c);
            return keep_command(c, static_cast<float>(c.x), static_cast<float>(c.y), c.z, in);
        }
        case MAVLINK_MSG_ID_PARAM_REQUEST_LIST: {
            mavlink_param_request_list_t r;
            mavlink_msg_param_request_list_decode(&msg, &r);
            return for_us(r.target_system, r.target_component);
        }
        case MAVLINK_MSG_ID_PARAM_REQUEST_READ:
            return keep_param(msg, mavlink_msg_param_request_read_decode, in);
        case MAVLINK_MSG_ID_PARAM_SET:
            return keep_param(msg, mavlink_msg_param_set_decode, in);
        case MAVLINK_MSG_ID_FILE_TRANSFER_PROTOCOL: {
            mavlink_file_transfer_protocol_t f;
            mavlink_msg_file_transfer_protocol_decode(&msg, &f);
            for (int i = 0; i < 4; ++i) in.ftp[i] = f.payload[i];
            return for_us(f.target_system, f.target_component);
        }
        case MAVLINK_MSG_ID_HQ_PROGRAM:
            return keep_program(msg, in);
        default:
            return false;                    // HQ_EXCITATION: answered when it is a request
    }
}

// What a message asks of the loop, if anything (false: nothing).
bool GcsLink::ask(const mavlink_message_t& msg, const Received& in, bool answered,
                  LoopRequest& r) {
    r.sysid = msg.sysid;
    r.compid = msg.compid;
    r.who = station_id(msg.sysid, msg.compid);
    switch (msg.msgid) {
        case MAVLINK_MSG_ID_HEARTBEAT:
            // Another system's (not our own echoed back by a router): the Supervisor decides
            // whether it is a ground station that counts as the host.
            r.kind = RequestKind::Heartbeat;
            r.mav_type = mavlink_msg_heartbeat_get_type(&msg);
            if (msg.sysid == config_.system_id) return false;
            if (is_ground_station(msg.sysid, r.mav_type)) heard(r.who);
            return true;
        case MAVLINK_MSG_ID_COMMAND_LONG:
        case MAVLINK_MSG_ID_COMMAND_INT: {
            return answered && ask_command(in, r);
        }
        case MAVLINK_MSG_ID_SET_MODE: {
            mavlink_set_mode_t sm;
            mavlink_msg_set_mode_decode(&msg, &sm);
            r.kind = RequestKind::SetMode;
            r.value = sm.custom_mode;
            return for_us(sm.target_system, 0);
        }
        case MAVLINK_MSG_ID_HQ_EXCITATION:
            return ask_excitation(msg, r);
        case MAVLINK_MSG_ID_HQ_PROGRAM:
            return answered && ask_program(msg, r);
        case MAVLINK_MSG_ID_PARAM_SET:
            return ask_param_set(msg, r);
        default:
            return false;
    }
}

bool GcsLink::ask_command(const Received& in, LoopRequest& r) {
    const float* p = in.p;
    switch (in.command) {
        case MAV_CMD_COMPONENT_ARM_DISARM:
            r.kind = p[0] > 0.5f ? RequestKind::Arm : RequestKind::Disarm;
            return true;
        case MAV_CMD_DO_SET_MODE:
            // param1 the base mode (custom modes only), param2 the custom mode (HQ_MODE).
            r.kind = RequestKind::SetMode;
            r.value = whole(p[1]);                  // kNotWhole is no mode: BAD_MODE
            return whole(p[0]) != kNotWhole && (whole(p[0]) & MAV_MODE_FLAG_CUSTOM_MODE_ENABLED);
        case MAV_CMD_PREFLIGHT_STORAGE:
            r.kind = RequestKind::Storage;
            r.value = whole(p[0]);
            return true;
        default:
            return false;
    }
}

bool GcsLink::ask_excitation(const mavlink_message_t& msg, LoopRequest& r) {
    mavlink_hq_excitation_t ex;
    mavlink_msg_hq_excitation_decode(&msg, &ex);
    if (!for_us(ex.target_system, ex.target_component)) return false;
    if (ex.action == HQ_EXCITATION_STOP) {
        r.kind = RequestKind::ExcitationStop;
    } else if (ex.action == HQ_EXCITATION_FINISH) {
        r.kind = RequestKind::ExcitationFinish;
    } else if (ex.action == HQ_EXCITATION_START) {
        r.kind = RequestKind::ExcitationStart;
        inbox_.has_excitation = true;
        read_excitation(ex, inbox_.excitation);
        // a chirp's fields are HQ_EXCITATION's alone (an on-board program has none: a chirp
        // step is refused there by its missing stop frequency)
        inbox_.excitation.freq_stop_hz = ex.freq_stop_hz;
        inbox_.excitation.sweep_s = ex.sweep_s;
    } else {
        r.kind = RequestKind::ExcitationRefuse;
    }
    return true;
}

// The excitation as sent (the Supervisor checks it), and a multisine's harmonics: the
// entries before the first zero order. A non-zero order after
// it leaves none, so the request is refused (HQ_REASON_HARMONICS) rather than cut short.
static_assert(sizeof(mavlink_hq_excitation_t::harmonic) / sizeof(uint16_t) == kMaxHarmonics,
              "HQ_EXCITATION carries kMaxHarmonics harmonics");
template <typename Message>
void GcsLink::read_excitation(const Message& ex, ExcitationConfig& cfg) {
    cfg = ExcitationConfig{};
    cfg.axis = static_cast<Axis>(ex.axis);              // checked by the Supervisor
    cfg.injection = static_cast<Injection>(ex.injection);
    cfg.freq_hz = ex.freq_hz;
    cfg.amplitude = ex.amplitude;
    cfg.cycles = ex.cycles;
    cfg.fade_cycles = ex.fade_cycles;
    cfg.signal = static_cast<Signal>(ex.signal);        // checked by the Supervisor
    if (cfg.signal != Signal::Multisine) return;
    uint8_t count = 0;
    bool gap = false;
    for (int i = 0; i < kMaxHarmonics; ++i) {
        if (ex.harmonic[i] == 0) {
            gap = true;
        } else if (gap) {
            count = 0;
            break;
        } else {
            cfg.harmonic[count++] = Harmonic{ex.harmonic[i], ex.harmonic_amp[i], ex.harmonic_phase[i]};
        }
    }
    cfg.harmonics = count;
}
template void GcsLink::read_excitation(const mavlink_hq_program_t&, ExcitationConfig&);

// --- answers -------------------------------------------------------------------------------

void GcsLink::transmit(const LoopStatus& status) {
    loop_time_us_ = status.time_us;          // the stamp of every message about this loop
    if (logs_ != nullptr) logs_->set_armed(status.armed);
    program_ = status.program;
    for (int i = 0; i < received_count_; ++i) {
        const Received& in = received_[i];
        const LoopAnswer* a = in.request < 0 ? nullptr : &inbox_.answer[in.request];
        if (a != nullptr) send_notices_to(status, a->notices_end);
        reply(in, a);
    }
    received_count_ = 0;
    send_notices_to(status, status.notices_before_telemetry);
    if (status.excitation_ended) send_excitation_status(status.end_reason, status.excitation);
    if (status.program_changed) send_program_status(HQ_PROGRAM_STEP, status.program_report.reason == Reason::None, status.program_report);
    send_boot_report(status.boot);
    send_telemetry(status);
    send_notices_to(status, status.notice_count);
    notices_sent_ = 0;
}

void GcsLink::send_notices(const LoopStatus& status) {
    send_notices_to(status, status.notice_count);
    notices_sent_ = 0;
}

void GcsLink::send_notices_to(const LoopStatus& status, int end) {
    for (; notices_sent_ < end; ++notices_sent_) send_notice(status.notice[notices_sent_]);
}

// A notice's words after prefix (the boot report's "boot: "), within a STATUSTEXT.
bool GcsLink::send_notice(const Notice& n, const char* prefix) {
    char text[kStatusTextLen] = {};
    size_t len = 0;
    for (; prefix[len] != '\0'; ++len) text[len] = prefix[len];
    notice_words(n, text + len, sizeof(text) - len);
    // With a prefix it is the boot report, this link's own words: logged here; the loop's
    // notices the loop logs itself (once, however many links send them).
    return prefix[0] == '\0' ? send_statustext(n.severity, text) : say(n.severity, text);
}

// A ground station's HEARTBEAT: it is heard now; the first from one this link has not heard
// (or has forgotten, for kHeardStations others heard since) asks for the boot report.
void GcsLink::heard(StationId who) {
    ++heartbeats_heard_;
    int oldest = 0;
    for (int i = 0; i < heard_count_; ++i) {
        if (heard_[i].who == who) {
            heard_[i].at = heartbeats_heard_;
            return;
        }
        // Ages, not counts, so that the count's wrap-around changes nothing.
        if (heartbeats_heard_ - heard_[i].at > heartbeats_heard_ - heard_[oldest].at) oldest = i;
    }
    const int slot = heard_count_ < kHeardStations ? heard_count_++ : oldest;
    heard_[slot] = Heard{who, heartbeats_heard_};
    boot_asked_ = true;
}

// The boot report, one finding a loop, in order, from the first to the last; one the link
// could not take is sent in the next loop, so no finding is lost to a full link. A report
// asked for starts when none is under way and a second (of loops) has passed since the last
// began: a flood of new stations or requests costs at most one report a second.
void GcsLink::send_boot_report(const BootReport& boot) {
    if (boot_wait_loops_ > 0) --boot_wait_loops_;
    if (boot_next_ >= kBootFindings && boot_asked_ && boot_wait_loops_ == 0) {
        boot_next_ = 0;
        boot_asked_ = false;
        boot_wait_loops_ = static_cast<uint32_t>(config_.loop_rate_hz + 0.5f);
    }
    if (boot_next_ < kBootFindings && send_notice(boot_finding(boot, boot_next_), "boot: ")) {
        ++boot_next_;
    }
}

void GcsLink::reply(const Received& in, const LoopAnswer* a) {
    switch (in.msgid) {
        case MAVLINK_MSG_ID_COMMAND_LONG:
        case MAVLINK_MSG_ID_COMMAND_INT:
            reply_command(in, a);
            return;
        case MAVLINK_MSG_ID_HQ_EXCITATION:
            last_exc_accepted_ = a->verdict == Verdict::Accepted;
            send_excitation_status(a->reason, a->excitation);
            return;
        case MAVLINK_MSG_ID_PARAM_REQUEST_LIST: params_pending_.set_all(); return;
        case MAVLINK_MSG_ID_PARAM_REQUEST_READ: reply_param_read(in); return;
        case MAVLINK_MSG_ID_PARAM_SET: reply_param_set(in, a); return;
        case MAVLINK_MSG_ID_FILE_TRANSFER_PROTOCOL: refuse_file_transfer(in); return;
        case MAVLINK_MSG_ID_HQ_PROGRAM: reply_program(in, *a); return;
        default: return;                     // a HEARTBEAT or SET_MODE: no answer
    }
}

// Every command addressed to us, or broadcast, is answered with COMMAND_ACK; a command this
// firmware does not know is MAV_RESULT_UNSUPPORTED. result_param2 carries the HQ_REASON of a
// refusal.
void GcsLink::reply_command(const Received& in, const LoopAnswer* a) {
    Reason why = Reason::None;
    const uint8_t result = command_result(in, a, why);
    mavlink_message_t out;
    mavlink_msg_command_ack_pack_status(config_.system_id, config_.component_id, &tx_status_,
                                        &out, in.command, result, 0, static_cast<int32_t>(why),
                                        in.sysid, in.compid);
    send(out);
}

uint8_t GcsLink::command_result(const Received& in, const LoopAnswer* a, Reason& why) {
    const float* p = in.p;
    switch (in.command) {
        case MAV_CMD_COMPONENT_ARM_DISARM:
        case MAV_CMD_DO_SET_MODE:
            if (a == nullptr) {                      // a base mode without custom modes
                why = Reason::BadMode;
                return MAV_RESULT_DENIED;
            }
            why = a->reason;
            return a->verdict == Verdict::Accepted ? MAV_RESULT_ACCEPTED : MAV_RESULT_DENIED;
        case MAV_CMD_PREFLIGHT_STORAGE:
            if (a->verdict == Verdict::Accepted && whole(p[0]) != PARAM_WRITE_PERSISTENT) {
                params_pending_.set_all();           // every value again, as it now is
            }
            return a->verdict == Verdict::Accepted  ? MAV_RESULT_ACCEPTED
                   : a->verdict == Verdict::Failed ? MAV_RESULT_FAILED
                                                   : MAV_RESULT_DENIED;
        case MAV_CMD_SET_MESSAGE_INTERVAL:
            return interval_command(whole(p[0]), p[1]);
        case MAV_CMD_GET_MESSAGE_INTERVAL: {
            const uint32_t msgid = whole(p[0]);
            const Stream* s = stream(msgid);
            mavlink_message_t out;
            const int32_t us = s == nullptr ? 0 : (s->interval_us == 0 ? -1 : static_cast<int32_t>(s->interval_us));
            mavlink_msg_message_interval_pack_status(config_.system_id, config_.component_id,
                                                     &tx_status_, &out, static_cast<uint16_t>(msgid), us);
            send(out);
            return MAV_RESULT_ACCEPTED;
        }
        case MAV_CMD_REQUEST_MESSAGE:
            return request_message(whole(p[0]));
        case MAV_CMD_REQUEST_AUTOPILOT_CAPABILITIES:
            return request_message(MAVLINK_MSG_ID_AUTOPILOT_VERSION);
        default:
            return MAV_RESULT_UNSUPPORTED;
    }
}

// MAVLink FTP is not served: every request gets a NAK "unknown command", so a ground station
// that tries it first (MAVProxy fetches parameters over FTP when it can) falls back to the
// parameter protocol at once instead of after its timeouts. The payload's header: seq (2),
// session, opcode, size, req_opcode, burst_complete, padding, offset (4), then data.
void GcsLink::refuse_file_transfer(const Received& in) {
    uint8_t payload[MAVLINK_MSG_FILE_TRANSFER_PROTOCOL_FIELD_PAYLOAD_LEN] = {};
    const uint16_t seq = static_cast<uint16_t>((in.ftp[0] | in.ftp[1] << 8) + 1);
    payload[0] = static_cast<uint8_t>(seq);
    payload[1] = static_cast<uint8_t>(seq >> 8);
    payload[2] = in.ftp[2];                              // the session asked for
    payload[3] = MAV_FTP_OPCODE_NAK;
    payload[4] = 1;                                      // one byte of data: the error
    payload[5] = in.ftp[3];                              // the request's opcode
    payload[12] = MAV_FTP_ERR_UNKNOWNCOMMAND;
    mavlink_message_t out;
    mavlink_msg_file_transfer_protocol_pack_status(config_.system_id, config_.component_id,
                                                   &tx_status_, &out, 0, in.sysid, in.compid,
                                                   payload);
    send(out);
}

void GcsLink::send_excitation_status(Reason reason, const ExcitationReport& ex) {
    mavlink_message_t msg;
    mavlink_msg_hq_excitation_status_pack_status(
        config_.system_id, config_.component_id, &tx_status_, &msg, loop_time_us_,
        last_exc_accepted_ ? 1 : 0, static_cast<uint8_t>(ex.state), static_cast<uint8_t>(reason),
        static_cast<uint8_t>(ex.axis), static_cast<uint8_t>(ex.injection), ex.actual_freq_hz,
        ex.period_samples, ex.total_samples, static_cast<uint8_t>(ex.signal), ex.fade_samples);
    send(msg);
}

// --- out -----------------------------------------------------------------------------------

bool GcsLink::send(const mavlink_message_t& msg) {
    if (offer(msg)) return true;
    const uint16_t len = mavlink_msg_get_send_buffer_length(&msg);
    telemetry_dropped_ += len;
    bytes_dropped_ += len;
    return false;
}

// The message whole, or nothing (false) when the port has no room; only what went is counted.
bool GcsLink::offer(const mavlink_message_t& msg) {
    uint8_t buf[MAVLINK_MAX_PACKET_LEN];
    const uint16_t len = mavlink_msg_to_send_buffer(buf, &msg);
    if (port_.write(buf, len) < len) return false;
    bytes_sent_ += len;
    bytes_total_ += len;
    return true;
}

bool GcsLink::say(uint8_t severity, const char* text) {
    if (config_.log != nullptr) config_.log->text(text, kStatusTextLen, loop_time_us_);
    return send_statustext(severity, text);
}

bool GcsLink::send_statustext(uint8_t severity, const char* text) {
    // The packer copies the whole field: give it a zero-padded copy, never the literal itself.
    char padded[kStatusTextLen] = {};
    for (size_t i = 0; i < kStatusTextLen && text[i] != '\0'; ++i) padded[i] = text[i];
    mavlink_message_t msg;
    mavlink_msg_statustext_pack_status(config_.system_id, config_.component_id, &tx_status_, &msg,
                                       severity, padded, 0, 0);
    return send(msg);
}

}  // namespace hq
