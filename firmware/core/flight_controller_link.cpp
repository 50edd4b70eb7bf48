// The FlightController's telemetry link: commands and parameters in, telemetry out
// (flight_controller.hpp says what is sent when; docs/link-contract.md is the user's view).
#include <cmath>

#include "flight_controller.hpp"

#ifndef HQ_FW_VERSION_MAJOR
#error "the build defines HQ_FW_VERSION_MAJOR, _MINOR and _PATCH (firmware/CMakeLists.txt)"
#endif

namespace hq {

namespace {

// STATUSTEXT.text, NUL-terminated when shorter.
constexpr size_t kStatusTextLen = MAVLINK_MSG_STATUSTEXT_FIELD_TEXT_LEN;
// PARAM_VALUEs sent per loop while a list is being sent: 44 in 22 loops (0.11 s at 200 Hz),
// about 15 kB/s on top of the loop's telemetry.
constexpr int kParamsPerLoop = 2;
// SET_MESSAGE_INTERVAL keeps the streams within this share of the link.
constexpr float kLinkShare = 0.8f;
constexpr uint16_t kUnusedChannel = UINT16_MAX;

// The HQ_MODE values are ArduCopter's numbers for the same two modes (STABILIZE: sticks
// command angles; ACRO: sticks command rates), so a ground station that names a generic
// multirotor's custom modes as ArduCopter's shows them by their usual names.
static_assert(HQ_MODE_ANGLE == 0 && HQ_MODE_RATE == 1, "ArduCopter's STABILIZE and ACRO");

int16_t saturate16(float v) {
    if (!(v == v)) return 0;
    return static_cast<int16_t>(v > 32767.0f ? 32767.0f : (v < -32767.0f ? -32767.0f : v));
}

// A command parameter that carries a whole number (a mode, a message id, an action): the
// number, or kNotWhole for anything else (a fraction, a negative, a NaN, a value past 2^24,
// which a float carries inexactly), so no float is ever converted out of range.
constexpr uint32_t kNotWhole = UINT32_MAX;
uint32_t whole(float v) {
    if (!(v >= 0.0f && v <= 16777216.0f) || v != std::floor(v)) return kNotWhole;
    return static_cast<uint32_t>(v);
}

// The largest encoded length of a message (header, payload, checksum; no signature).
uint32_t packet_bytes(uint32_t msgid) {
    const mavlink_msg_entry_t* e = mavlink_get_msg_entry(msgid);
    return (e ? e->max_msg_len : 255u) + MAVLINK_NUM_NON_PAYLOAD_BYTES;
}

void copy_name(char out[kParamNameLen], const char* name) {
    size_t i = 0;
    for (; i < kParamNameLen && name[i] != '\0'; ++i) out[i] = name[i];
    for (; i < kParamNameLen; ++i) out[i] = '\0';
}

// --- the parameter encoding ----------------------------------------------------------------
// PARAM_VALUE.param_value is a float whatever the type. Integer parameters are sent byte-wise
// (the int32's bytes in the float's, MAV_PROTOCOL_CAPABILITY_PARAM_ENCODE_BYTEWISE): what
// MAVSDK reads for every autopilot but ArduPilot and QGroundControl for every autopilot but
// ArduPilot (its APM plugin alone converts). docs/ground-stations.md says who reads what.
float encode_param_int(float value) {
    const int32_t i = static_cast<int32_t>(value);       // whole and in range (params.cpp)
    float f;
    __builtin_memcpy(&f, &i, sizeof(f));
    return f;
}

#ifdef MAVLINK_MSG_ID_PARAM_ERROR
// MAV_PARAM_ERROR_TYPE_MISMATCH where the common.xml in use has it, else
// VALUE_OUT_OF_RANGE (the value as sent is not one the parameter takes).
template <typename E, typename = void>
struct TypeMismatch {
    static constexpr uint8_t value = E::MAV_PARAM_ERROR_VALUE_OUT_OF_RANGE;
};
template <typename E>
struct TypeMismatch<E, decltype(void(E::MAV_PARAM_ERROR_TYPE_MISMATCH))> {
    static constexpr uint8_t value = E::MAV_PARAM_ERROR_TYPE_MISMATCH;
};

// PARAM_ERROR's code for a refusal (MAV_PARAM_ERROR).
uint8_t param_error(SetResult r) {
    switch (r) {
        case SetResult::Unknown: return MAV_PARAM_ERROR_DOES_NOT_EXIST;
        case SetResult::Armed:
        case SetResult::Excitation: return MAV_PARAM_ERROR_PERMISSION_DENIED;
        case SetResult::Type: return TypeMismatch<MAV_PARAM_ERROR>::value;
        default: return MAV_PARAM_ERROR_VALUE_OUT_OF_RANGE;     // out of range, not whole
    }
}
#endif

}  // namespace

bool FlightController::for_us(uint8_t target_system, uint8_t target_component) const {
    return (target_system == 0 || target_system == config_.system_id) &&
           (target_component == 0 || target_component == config_.component_id);
}

// --- in ------------------------------------------------------------------------------------

void FlightController::handle_commands(const RcInput& rc, uint64_t now_us) {
    uint8_t buf[64];
    size_t n;
    while ((n = telemetry_.read(buf, sizeof(buf))) > 0) {
        for (size_t i = 0; i < n; ++i) {
            mavlink_message_t msg;
            mavlink_status_t status;
            if (mavlink_frame_char_buffer(&rx_msg_, &rx_status_, buf[i], &msg, &status) ==
                MAVLINK_FRAMING_OK) {
                handle_message(msg, rc, now_us);
            }
        }
    }
}

void FlightController::handle_message(const mavlink_message_t& msg, const RcInput& rc,
                                      uint64_t now_us) {
    switch (msg.msgid) {
        case MAVLINK_MSG_ID_HEARTBEAT:
            // Another system's (not our own echoed back by a router): the Supervisor decides
            // whether it is a ground station that counts as the host.
            if (msg.sysid != config_.system_id) {
                supervisor_.heartbeat(msg.sysid, msg.compid, mavlink_msg_heartbeat_get_type(&msg),
                                      now_us);
            }
            return;
        case MAVLINK_MSG_ID_COMMAND_LONG: {
            mavlink_command_long_t c;
            mavlink_msg_command_long_decode(&msg, &c);
            if (!for_us(c.target_system, c.target_component)) return;
            const float p[7] = {c.param1, c.param2, c.param3, c.param4, c.param5, c.param6, c.param7};
            handle_command(msg, c.command, p, rc, now_us);
            return;
        }
        case MAVLINK_MSG_ID_COMMAND_INT: {
            mavlink_command_int_t c;
            mavlink_msg_command_int_decode(&msg, &c);
            if (!for_us(c.target_system, c.target_component)) return;
            const float p[7] = {c.param1, c.param2, c.param3, c.param4, static_cast<float>(c.x),
                                static_cast<float>(c.y), c.z};
            handle_command(msg, c.command, p, rc, now_us);
            return;
        }
        case MAVLINK_MSG_ID_SET_MODE: {
            mavlink_set_mode_t sm;
            mavlink_msg_set_mode_decode(&msg, &sm);
            if (for_us(sm.target_system, 0)) supervisor_.set_mode(sm.custom_mode);
            return;
        }
        case MAVLINK_MSG_ID_HQ_EXCITATION:
            handle_excitation(msg, now_us);
            return;
        case MAVLINK_MSG_ID_PARAM_REQUEST_LIST: {
            mavlink_param_request_list_t r;
            mavlink_msg_param_request_list_decode(&msg, &r);
            if (for_us(r.target_system, r.target_component)) params_pending_ = (1ull << kParamCount) - 1;
            return;
        }
        case MAVLINK_MSG_ID_PARAM_REQUEST_READ:
            handle_param_read(msg);
            return;
        case MAVLINK_MSG_ID_PARAM_SET:
            handle_param_set(msg, now_us);
            return;
        case MAVLINK_MSG_ID_FILE_TRANSFER_PROTOCOL:
            refuse_file_transfer(msg);
            return;
        default:
            return;
    }
}

// Every command addressed to us, or broadcast, is answered with COMMAND_ACK; a command this
// firmware does not know is MAV_RESULT_UNSUPPORTED. result_param2 carries the HQ_REASON of a
// refusal.
void FlightController::handle_command(const mavlink_message_t& msg, uint16_t command,
                                      const float p[7], const RcInput& rc, uint64_t now_us) {
    Reason why = Reason::None;
    const uint8_t result = command_result(command, p, rc, now_us, station_id(msg.sysid, msg.compid), why);
    mavlink_message_t out;
    mavlink_msg_command_ack_pack_status(config_.system_id, config_.component_id, &tx_status_,
                                        &out, command, result, 0, static_cast<int32_t>(why),
                                        msg.sysid, msg.compid);
    send(out);
}

uint8_t FlightController::command_result(uint16_t command, const float p[7], const RcInput& rc,
                                         uint64_t now_us, StationId who, Reason& why) {
    switch (command) {
        case MAV_CMD_COMPONENT_ARM_DISARM:
            if (p[0] > 0.5f) {
                why = supervisor_.arm_command(rc, now_us, who);
                return why == Reason::None ? MAV_RESULT_ACCEPTED : MAV_RESULT_DENIED;
            }
            supervisor_.disarm_command();
            return MAV_RESULT_ACCEPTED;
        case MAV_CMD_DO_SET_MODE:
            // param1 the base mode (custom modes only), param2 the custom mode (HQ_MODE).
            if (whole(p[0]) == kNotWhole || !(whole(p[0]) & MAV_MODE_FLAG_CUSTOM_MODE_ENABLED)) {
                why = Reason::BadMode;
                return MAV_RESULT_DENIED;
            }
            why = supervisor_.set_mode(whole(p[1]));       // kNotWhole is no mode: BAD_MODE
            return why == Reason::None ? MAV_RESULT_ACCEPTED : MAV_RESULT_DENIED;
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
        case MAV_CMD_PREFLIGHT_STORAGE:
            if (supervisor_.armed()) return MAV_RESULT_DENIED;
            return storage_command(whole(p[0]));
        default:
            return MAV_RESULT_UNSUPPORTED;
    }
}

// MAV_CMD_PREFLIGHT_STORAGE's parameter action: read the stored values again, save now, or
// back to the defaults (saved like any change).
uint8_t FlightController::storage_command(uint32_t action) {
    const uint64_t now = clock_.micros();
    if (action == PARAM_READ_PERSISTENT) {
        params_.reset();
        load_params();
    } else if (action == PARAM_WRITE_PERSISTENT) {
        return save_params() ? MAV_RESULT_ACCEPTED : MAV_RESULT_FAILED;
    } else if (action == PARAM_RESET_FACTORY_DEFAULT || action == PARAM_RESET_ALL_DEFAULT) {
        params_.reset();
        params_dirty_ = true;
        params_changed_us_ = now;
    } else {
        return MAV_RESULT_DENIED;
    }
    apply_params(kParamEsc | kParamImu, now);
    params_pending_ = (1ull << kParamCount) - 1;     // every value again, as it now is
    return MAV_RESULT_ACCEPTED;
}

uint8_t FlightController::interval_command(uint32_t msgid, float interval_us) {
    Stream* s = stream(msgid);
    // HEARTBEAT stays at 1 Hz and HQ_SYSID_SAMPLE at the loop rate (the link contract).
    if (s == nullptr || s->default_us == 0 || msgid == MAVLINK_MSG_ID_HEARTBEAT ||
        !std::isfinite(interval_us)) {
        return MAV_RESULT_DENIED;
    }
    uint32_t us;
    if (interval_us < -0.5f) {
        us = 0;                                          // -1: off
    } else if (interval_us < 0.5f) {
        us = s->default_us;                              // 0: the default
    } else {
        const float loop_us = 1e6f / config_.loop_rate_hz;
        us = static_cast<uint32_t>(interval_us < loop_us ? loop_us : (interval_us > 6e7f ? 6e7f : interval_us));
    }
    uint32_t total = stream_bytes_per_s(MAVLINK_MSG_ID_HQ_SYSID_SAMPLE, 1);
    for (const Stream& o : streams_) {
        total += stream_bytes_per_s(o.msgid, &o == s ? us : o.interval_us);
    }
    if (static_cast<float>(total) > kLinkShare * static_cast<float>(config_.link_bytes_per_s)) {
        send_statustext(MAV_SEVERITY_WARNING, "interval refused: more than the link carries");
        return MAV_RESULT_DENIED;
    }
    s->interval_us = us;
    return MAV_RESULT_ACCEPTED;
}

uint32_t FlightController::stream_bytes_per_s(uint32_t msgid, uint32_t interval_us) const {
    if (interval_us == 0) return 0;
    const float loop_us = 1e6f / config_.loop_rate_hz;
    const float us = static_cast<float>(interval_us) < loop_us ? loop_us : static_cast<float>(interval_us);
    return static_cast<uint32_t>(static_cast<float>(packet_bytes(msgid)) * 1e6f / us + 0.5f);
}

uint8_t FlightController::request_message(uint32_t msgid) {
    Stream* s = stream(msgid);
    if (s == nullptr) return MAV_RESULT_DENIED;
    s->requested = true;
    return MAV_RESULT_ACCEPTED;
}

// A multisine's harmonics: the entries before the first zero order. A non-zero order after
// it leaves none, so the request is refused (HQ_REASON_HARMONICS) rather than cut short.
static_assert(sizeof(mavlink_hq_excitation_t::harmonic) / sizeof(uint16_t) == kMaxHarmonics,
              "HQ_EXCITATION carries kMaxHarmonics harmonics");
void FlightController::read_harmonics(const mavlink_hq_excitation_t& ex, ExcitationConfig& cfg) {
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

void FlightController::handle_excitation(const mavlink_message_t& msg, uint64_t now_us) {
    mavlink_hq_excitation_t ex;
    mavlink_msg_hq_excitation_decode(&msg, &ex);
    if (!for_us(ex.target_system, ex.target_component)) return;
    Reason why = Reason::StopCommand;
    if (ex.action == HQ_EXCITATION_STOP) {
        supervisor_.stop_excitation();
        last_exc_accepted_ = true;
    } else if (ex.action == HQ_EXCITATION_FINISH) {
        supervisor_.finish_excitation();             // the answer carries the new length
        last_exc_accepted_ = true;
        why = Reason::None;
    } else if (ex.action == HQ_EXCITATION_START) {
        ExcitationConfig cfg;
        cfg.axis = static_cast<Axis>(ex.axis);              // checked by the Supervisor
        cfg.injection = static_cast<Injection>(ex.injection);
        cfg.freq_hz = ex.freq_hz;
        cfg.amplitude = ex.amplitude;
        cfg.cycles = ex.cycles;
        cfg.fade_cycles = ex.fade_cycles;
        read_harmonics(ex, cfg);
        why = supervisor_.start_excitation(cfg, now_us, station_id(msg.sysid, msg.compid));
        last_exc_accepted_ = why == Reason::None;
    } else {
        // An action this firmware does not know: refused, and nothing else changes (a
        // running excitation goes on; only STOP stops one).
        why = Reason::BadAction;
        supervisor_.refuse_excitation(why);
        last_exc_accepted_ = false;
    }
    send_excitation_status(why);
}

// MAVLink FTP is not served: every request gets a NAK "unknown command", so a ground station
// that tries it first (MAVProxy fetches parameters over FTP when it can) falls back to the
// parameter protocol at once instead of after its timeouts. The payload's header: seq (2),
// session, opcode, size, req_opcode, burst_complete, padding, offset (4), then data.
void FlightController::refuse_file_transfer(const mavlink_message_t& msg) {
    mavlink_file_transfer_protocol_t in;
    mavlink_msg_file_transfer_protocol_decode(&msg, &in);
    if (!for_us(in.target_system, in.target_component)) return;
    uint8_t payload[MAVLINK_MSG_FILE_TRANSFER_PROTOCOL_FIELD_PAYLOAD_LEN] = {};
    const uint16_t seq = static_cast<uint16_t>((in.payload[0] | in.payload[1] << 8) + 1);
    payload[0] = static_cast<uint8_t>(seq);
    payload[1] = static_cast<uint8_t>(seq >> 8);
    payload[2] = in.payload[2];                          // the session asked for
    payload[3] = MAV_FTP_OPCODE_NAK;
    payload[4] = 1;                                      // one byte of data: the error
    payload[5] = in.payload[3];                          // the request's opcode
    payload[12] = MAV_FTP_ERR_UNKNOWNCOMMAND;
    mavlink_message_t out;
    mavlink_msg_file_transfer_protocol_pack_status(config_.system_id, config_.component_id,
                                                   &tx_status_, &out, 0, msg.sysid, msg.compid,
                                                   payload);
    send(out);
}

// --- the parameter protocol ----------------------------------------------------------------

void FlightController::handle_param_read(const mavlink_message_t& msg) {
    mavlink_param_request_read_t r;
    mavlink_msg_param_request_read_decode(&msg, &r);
    if (!for_us(r.target_system, r.target_component)) return;
    const int index = r.param_index >= 0 ? (r.param_index < kParamCount ? r.param_index : -1)
                                         : param_index(r.param_id);
    if (index < 0) {
        send_param_error(msg, r.param_id, r.param_index, SetResult::Unknown);
        send_unknown_param(r.param_id, r.param_index);
        return;
    }
    params_pending_ |= 1ull << index;
}

void FlightController::send_unknown_param(const char* name, int index) {
    char text[kStatusTextLen];
    unknown_param_text(name, index, text, sizeof(text));
    send_statustext(MAV_SEVERITY_WARNING, text);
}

// PARAM_SET is answered with PARAM_VALUE: the new value, or the unchanged one, a STATUSTEXT
// saying why, and PARAM_ERROR to the station that asked (MAVSDK and QGroundControl report
// that as the refusal; MAVProxy and pymavlink read the unchanged value).
void FlightController::handle_param_set(const mavlink_message_t& msg, uint64_t now_us) {
    mavlink_param_set_t ps;
    mavlink_msg_param_set_decode(&msg, &ps);
    if (!for_us(ps.target_system, ps.target_component)) return;
    const int index = param_index(ps.param_id);
    if (index < 0) {
        send_param_error(msg, ps.param_id, -1, SetResult::Unknown);
        send_unknown_param(ps.param_id, -1);
        return;
    }
    const bool as_float = ps.param_type == MAV_PARAM_TYPE_REAL32;
    float value = 0.0f;
    const SetResult r = !decode_param_value(param_info(index), ps.param_value, ps.param_type, value)
                            ? SetResult::Type
                            : params_.set(index, value, supervisor_.armed(),
                                          supervisor_.excitation().active());
    if (as_float) params_as_float_ |= 1ull << index;      // answered in the form it came in
    params_pending_ |= 1ull << index;
    if (r == SetResult::Unchanged) return;               // answered with the value it has
    if (r != SetResult::Ok) {
        send_param_error(msg, ps.param_id, index, r);
        char text[kStatusTextLen];
        set_result_text(r, index, text, sizeof(text));
        send_statustext(MAV_SEVERITY_WARNING, text);
        return;
    }
    apply_params(param_info(index).flags, now_us);
    params_dirty_ = true;
    params_changed_us_ = now_us;
}

void FlightController::send_param_error(const mavlink_message_t& to, const char* name, int index,
                                        SetResult why) {
#ifdef MAVLINK_MSG_ID_PARAM_ERROR
    char id[kParamNameLen];
    copy_name(id, name);
    mavlink_message_t out;
    mavlink_msg_param_error_pack_status(config_.system_id, config_.component_id, &tx_status_, &out,
                                        to.sysid, to.compid, id, static_cast<int16_t>(index),
                                        param_error(why));
    send(out);
#else
    (void)to, (void)name, (void)index, (void)why;       // a common.xml without PARAM_ERROR
#endif
}

bool FlightController::send_param_value(int index) {
    const ParamInfo& info = param_info(index);
    char name[kParamNameLen];
    copy_name(name, info.name);
    const bool integer = (info.flags & kParamInteger) != 0;
    const bool as_float = !integer || (params_as_float_ & (1ull << index)) != 0;
    const float value = as_float ? params_.get(index) : encode_param_int(params_.get(index));
    mavlink_message_t msg;
    mavlink_msg_param_value_pack_status(
        config_.system_id, config_.component_id, &tx_status_, &msg, name, value,
        as_float ? MAV_PARAM_TYPE_REAL32 : MAV_PARAM_TYPE_INT32, kParamCount,
        static_cast<uint16_t>(index));
    return send(msg);
}

void FlightController::send_params() {
    for (int sent = 0; sent < kParamsPerLoop && params_pending_ != 0; ++sent) {
        const int index = __builtin_ctzll(params_pending_);
        if (!send_param_value(index)) return;           // the link is full: next loop
        params_pending_ &= ~(1ull << index);
        params_as_float_ &= ~(1ull << index);
    }
}

// --- out -----------------------------------------------------------------------------------

FlightController::Stream* FlightController::stream(uint32_t msgid) {
    for (Stream& s : streams_) {
        if (s.msgid == msgid) return &s;
    }
    return nullptr;
}

bool FlightController::stream_due(Stream& s, uint64_t now_us) {
    if (s.requested) {
        s.requested = false;
        return true;
    }
    if (s.interval_us == 0 || now_us < s.next_us) return false;
    // On the first one's grid: the next an interval later, or from now if it fell behind.
    const bool on_grid = loops_ > 0 && s.next_us + s.interval_us > now_us;
    s.next_us = (on_grid ? s.next_us : now_us) + s.interval_us;
    return true;
}

bool FlightController::send(const mavlink_message_t& msg) {
    uint8_t buf[MAVLINK_MAX_PACKET_LEN];
    const uint16_t len = mavlink_msg_to_send_buffer(buf, &msg);
    if (telemetry_.write(buf, len) < len) {
        telemetry_dropped_ += len;
        bytes_dropped_ += len;
        return false;
    }
    bytes_sent_ += len;
    return true;
}

void FlightController::send_statustext(uint8_t severity, const char* text) {
    // The packer copies the whole field: give it a zero-padded copy, never the literal itself.
    char padded[kStatusTextLen] = {};
    for (size_t i = 0; i < kStatusTextLen && text[i] != '\0'; ++i) padded[i] = text[i];
    mavlink_message_t msg;
    mavlink_msg_statustext_pack_status(config_.system_id, config_.component_id, &tx_status_, &msg,
                                       severity, padded, 0, 0);
    send(msg);
}

void FlightController::send_events() {
    Event e;
    while (supervisor_.next_event(e)) send_statustext(static_cast<uint8_t>(e.severity), reason_text(e.reason));
    Reason why;
    if (supervisor_.take_excitation_end(why)) send_excitation_status(why);
}

void FlightController::send_excitation_status(Reason reason) {
    const Excitation& ex = supervisor_.excitation();
    const ExcitationConfig& cfg = ex.config();
    mavlink_message_t msg;
    mavlink_msg_hq_excitation_status_pack_status(
        config_.system_id, config_.component_id, &tx_status_, &msg, clock_.micros(),
        last_exc_accepted_ ? 1 : 0, static_cast<uint8_t>(ex.state()), static_cast<uint8_t>(reason),
        static_cast<uint8_t>(cfg.axis), static_cast<uint8_t>(cfg.injection), ex.actual_freq_hz(),
        ex.period_samples(), ex.total_samples(), static_cast<uint8_t>(cfg.signal), ex.fade_samples());
    send(msg);
}

uint8_t FlightController::sensor_kind() const {
    return static_cast<uint8_t>(imu_.mode());       // SensorMode is HQ_SENSOR_KIND
}

void FlightController::send_heartbeat() {
    const Supervisor& sup = supervisor_;
    const bool angle = sup.mode() == FlightMode::Angle;
    const auto base = static_cast<uint8_t>(
        MAV_MODE_FLAG_CUSTOM_MODE_ENABLED | MAV_MODE_FLAG_MANUAL_INPUT_ENABLED |
        (angle ? MAV_MODE_FLAG_STABILIZE_ENABLED : 0) | (sup.armed() ? MAV_MODE_FLAG_SAFETY_ARMED : 0));
    const uint8_t system_status = sup.armed() ? MAV_STATE_ACTIVE
                                  : sup.imu_stale() ? MAV_STATE_CRITICAL : MAV_STATE_STANDBY;
    mavlink_message_t msg;
    mavlink_msg_heartbeat_pack_status(config_.system_id, config_.component_id, &tx_status_, &msg,
                                      MAV_TYPE_QUADROTOR, MAV_AUTOPILOT_GENERIC, base,
                                      static_cast<uint32_t>(sup.mode()), system_status);
    send(msg);
}

void FlightController::send_fw_status(uint64_t now_us) {
    const Supervisor& sup = supervisor_;
    const Mpu6050Counters& c = imu_.counters();
    const SupervisorCounters& f = sup.counters();
    last_load_ = load_.take();
    // The link's drop rate over the last second, for SYS_STATUS.
    const uint32_t total = bytes_sent_ + bytes_dropped_;
    drop_rate_ = static_cast<uint16_t>(total == 0 ? 0 : 10000ull * bytes_dropped_ / total);
    bytes_sent_ = bytes_dropped_ = 0;
    mavlink_message_t msg;
    mavlink_msg_hq_fw_status_pack_status(
        config_.system_id, config_.component_id, &tx_status_, &msg, now_us, loops_, c.packets,
        c.dropped, c.overflows, c.resyncs, c.bad_packets, c.bus_errors, telemetry_dropped_,
        dt_clamped_, f.non_finite, sensor_kind(), sup.armed() ? 1 : 0,
        static_cast<uint8_t>(sup.mode()), static_cast<uint8_t>(sup.excitation_state()),
        static_cast<uint8_t>(sup.last_reason()), f.rc_failsafes, f.host_failsafes, f.imu_stale,
        f.imu_resets, f.imu_reinits, f.arm_refused, f.exc_refused, f.exc_stopped,
        last_load_.median, last_load_.max, last_load_.overruns);
    send(msg);
}

void FlightController::send_sys_status() {
    const Supervisor& sup = supervisor_;
    const uint32_t present = MAV_SYS_STATUS_SENSOR_3D_GYRO | MAV_SYS_STATUS_SENSOR_3D_ACCEL |
                             MAV_SYS_STATUS_SENSOR_ANGULAR_RATE_CONTROL |
                             MAV_SYS_STATUS_SENSOR_ATTITUDE_STABILIZATION |
                             MAV_SYS_STATUS_SENSOR_MOTOR_OUTPUTS | MAV_SYS_STATUS_SENSOR_RC_RECEIVER |
                             MAV_SYS_STATUS_AHRS | MAV_SYS_STATUS_PREARM_CHECK;
    uint32_t enabled = present;
    if (sup.mode() != FlightMode::Angle) enabled &= ~MAV_SYS_STATUS_SENSOR_ATTITUDE_STABILIZATION;
    if (!sup.armed()) enabled &= ~MAV_SYS_STATUS_SENSOR_MOTOR_OUTPUTS;
    uint32_t health = present;
    const bool imu_ok = imu_init_ != InitResult::NoDevice && imu_init_ != InitResult::BusError &&
                        !sup.imu_stale();
    if (!imu_ok) {
        health &= ~(MAV_SYS_STATUS_SENSOR_3D_GYRO | MAV_SYS_STATUS_SENSOR_3D_ACCEL | MAV_SYS_STATUS_AHRS);
    }
    if (rc_.age_us > sup.limits().rc_timeout_us) health &= ~MAV_SYS_STATUS_SENSOR_RC_RECEIVER;
    // Pre-arm: healthy while a command would arm now (or it is armed): MAVSDK's is_armable.
    if (!sup.armed() && sup.arm_check(rc_, clock_.micros()) != Reason::None) {
        health &= ~MAV_SYS_STATUS_PREARM_CHECK;
    }
    // Load: the median loop's share of its period, in 0.1 % (the target's cycle counter).
    uint16_t load = 0;
    if (config_.cpu_hz > 0) {
        const float budget = static_cast<float>(config_.cpu_hz) / config_.loop_rate_hz;
        const float permille = 1000.0f * static_cast<float>(last_load_.median) / budget;
        load = static_cast<uint16_t>(permille > 1000.0f ? 1000.0f : permille);
    }
    const Mpu6050Counters& c = imu_.counters();
    mavlink_message_t msg;
    mavlink_msg_sys_status_pack_status(
        config_.system_id, config_.component_id, &tx_status_, &msg, present, enabled, health, load,
        UINT16_MAX, -1, -1, drop_rate_, static_cast<uint16_t>(rx_status_.packet_rx_drop_count),
        static_cast<uint16_t>(c.bus_errors), static_cast<uint16_t>(c.resyncs),
        static_cast<uint16_t>(c.bad_packets), static_cast<uint16_t>(dt_clamped_), 0, 0, 0);
    send(msg);
}

void FlightController::send_autopilot_version() {
    const uint8_t none[8] = {};
    const uint64_t capabilities = MAV_PROTOCOL_CAPABILITY_PARAM_FLOAT |
                                  MAV_PROTOCOL_CAPABILITY_COMMAND_INT |
                                  MAV_PROTOCOL_CAPABILITY_MAVLINK2 |
                                  MAV_PROTOCOL_CAPABILITY_PARAM_ENCODE_BYTEWISE;
    const uint32_t version = (HQ_FW_VERSION_MAJOR << 24) | (HQ_FW_VERSION_MINOR << 16) |
                             (HQ_FW_VERSION_PATCH << 8) | FIRMWARE_VERSION_TYPE_DEV;
    mavlink_message_t msg;
    mavlink_msg_autopilot_version_pack_status(config_.system_id, config_.component_id,
                                              &tx_status_, &msg, capabilities, version, 0, 0, 0,
                                              none, none, none, 0, 0, config_.uid, config_.uid2);
    send(msg);
}

void FlightController::send_servo_output(uint64_t now_us) {
    // The ESC pulses the motors get: min + f (max - min) armed, the stop pulse disarmed.
    const EscEndpoints& e = params_.values().esc;
    uint16_t us[kMotors];
    for (int i = 0; i < kMotors; ++i) {
        const float span = static_cast<float>(e.max_us[i] - e.min_us[i]);
        us[i] = static_cast<uint16_t>(static_cast<float>(e.min_us[i]) + state_.motor[i] * span + 0.5f);
    }
    mavlink_message_t msg;
    mavlink_msg_servo_output_raw_pack_status(config_.system_id, config_.component_id, &tx_status_,
                                             &msg, static_cast<uint32_t>(now_us), 0, us[0], us[1],
                                             us[2], us[3], us[4], 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0);
    send(msg);
}

void FlightController::send_rc_channels(uint64_t now_us) {
    const uint16_t* ch = rc_.channel_us;
    uint8_t count = 0;
    for (int i = 0; i < kRcChannels; ++i) count = ch[i] != 0 ? static_cast<uint8_t>(i + 1) : count;
    const uint16_t u = kUnusedChannel;
    mavlink_message_t msg;
    mavlink_msg_rc_channels_pack_status(config_.system_id, config_.component_id, &tx_status_, &msg,
                                        static_cast<uint32_t>(now_us / 1000), count, ch[0], ch[1],
                                        ch[2], ch[3], ch[4], ch[5], ch[6], ch[7], u, u, u, u, u,
                                        u, u, u, u, u, UINT8_MAX);
    send(msg);
}

void FlightController::send_scaled_imu(uint64_t now_us) {
    // mG and mrad/s; the magnetometer and temperature are not measured (0).
    constexpr float kMilliG = 1000.0f / kGravity;
    const Vec3& a = state_.accel;
    const Vec3& g = state_.rate;
    mavlink_message_t msg;
    mavlink_msg_scaled_imu_pack_status(config_.system_id, config_.component_id, &tx_status_, &msg,
                                       static_cast<uint32_t>(now_us / 1000), saturate16(a.x * kMilliG),
                                       saturate16(a.y * kMilliG), saturate16(a.z * kMilliG),
                                       saturate16(g.x * 1000.0f), saturate16(g.y * 1000.0f),
                                       saturate16(g.z * 1000.0f), 0, 0, 0, 0);
    send(msg);
}

void FlightController::send_highres_imu(uint64_t now_us) {
    // m/s^2 and rad/s as measured (FRD body axes); nothing else is measured, and
    // fields_updated says so (accelerometer and gyro bits only).
    constexpr uint16_t kAccelGyro = HIGHRES_IMU_UPDATED_XACC | HIGHRES_IMU_UPDATED_YACC |
                                    HIGHRES_IMU_UPDATED_ZACC | HIGHRES_IMU_UPDATED_XGYRO |
                                    HIGHRES_IMU_UPDATED_YGYRO | HIGHRES_IMU_UPDATED_ZGYRO;
    const Vec3& a = state_.accel;
    const Vec3& g = state_.rate;
    mavlink_message_t msg;
    mavlink_msg_highres_imu_pack_status(config_.system_id, config_.component_id, &tx_status_, &msg,
                                        now_us, a.x, a.y, a.z, g.x, g.y, g.z, 0, 0, 0, 0, 0, 0, 0,
                                        kAccelGyro, 0);
    send(msg);
}

void FlightController::send_stream(uint32_t msgid, uint64_t now_us) {
    switch (msgid) {
        case MAVLINK_MSG_ID_HEARTBEAT: send_heartbeat(); return;
        case MAVLINK_MSG_ID_HQ_FW_STATUS: send_fw_status(now_us); return;
        case MAVLINK_MSG_ID_SYS_STATUS: send_sys_status(); return;
        case MAVLINK_MSG_ID_SERVO_OUTPUT_RAW: send_servo_output(now_us); return;
        case MAVLINK_MSG_ID_SCALED_IMU: send_scaled_imu(now_us); return;
        case MAVLINK_MSG_ID_HIGHRES_IMU: send_highres_imu(now_us); return;
        case MAVLINK_MSG_ID_RC_CHANNELS: send_rc_channels(now_us); return;
        case MAVLINK_MSG_ID_AUTOPILOT_VERSION: send_autopilot_version(); return;
        case MAVLINK_MSG_ID_ATTITUDE: {
            mavlink_message_t msg;
            mavlink_msg_attitude_pack_status(config_.system_id, config_.component_id, &tx_status_,
                                             &msg, static_cast<uint32_t>(now_us / 1000),
                                             state_.attitude.roll, state_.attitude.pitch,
                                             state_.attitude.yaw, state_.rate.x, state_.rate.y,
                                             state_.rate.z);
            send(msg);
            return;
        }
        default: return;
    }
}

void FlightController::send_telemetry() {
    // Order matters to the simulator: HQ_SYSID_SAMPLE is the last message of every loop, so
    // a reader that has it has the whole loop's telemetry.
    const uint64_t now = clock_.micros();
    for (Stream& s : streams_) {
        if (stream_due(s, now)) send_stream(s.msgid, now);
    }
    send_params();
    const Supervisor& sup = supervisor_;
    const ExcitationConfig& exc = sup.excitation_config();
    const int a = static_cast<int>(exc.axis);
    const float angle_sp = a < kAngleAxes ? (a == 0 ? state_.angle_sp.roll : state_.angle_sp.pitch)
                                          : 0.0f;
    mavlink_message_t msg;
    mavlink_msg_hq_sysid_sample_pack_status(
        config_.system_id, config_.component_id, &tx_status_, &msg, now, seq_++,
        static_cast<uint8_t>(exc.axis), static_cast<uint8_t>(exc.injection),
        static_cast<uint8_t>(sup.excitation_state()), sup.armed() ? 1 : 0,
        static_cast<uint8_t>(sup.mode()), state_.excitation, angle_sp, state_.rate_sp[a],
        state_.rate[a], state_.attitude[a], state_.torque[a], state_.motor, state_.saturation);
    send(msg);
}

}  // namespace hq
