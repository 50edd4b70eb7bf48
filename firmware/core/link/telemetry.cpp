// GcsLink's telemetry: the streams (their rates, SET_MESSAGE_INTERVAL and
// MAV_CMD_REQUEST_MESSAGE) and every streamed message, packed from the loop's published state
// (gcs_link.hpp says what is sent when).
#include <cmath>

#include "gcs_link.hpp"
#include "link_util.hpp"

#ifndef HQ_FW_VERSION_MAJOR
#error "the build defines HQ_FW_VERSION_MAJOR, _MINOR and _PATCH (firmware/CMakeLists.txt)"
#endif

namespace hq {

namespace {

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

}  // namespace

uint8_t GcsLink::interval_command(uint32_t msgid, float interval_us) {
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
    // A change that adds nothing is always taken: on a slow radio link the contract's streams
    // alone may need more than the share, and a station must still be able to slow the rest.
    const bool adds = stream_bytes_per_s(msgid, us) > stream_bytes_per_s(msgid, s->interval_us);
    const float budget = kLinkShare * static_cast<float>(config_.link_bytes_per_s);
    if (adds && static_cast<float>(total) > budget) {
        say(MAV_SEVERITY_WARNING, "interval refused: more than the link carries");
        return MAV_RESULT_DENIED;
    }
    s->interval_us = us;
    return MAV_RESULT_ACCEPTED;
}

uint32_t GcsLink::stream_bytes_per_s(uint32_t msgid, uint32_t interval_us) const {
    if (interval_us == 0) return 0;
    const float loop_us = 1e6f / config_.loop_rate_hz;
    const float us = static_cast<float>(interval_us) < loop_us ? loop_us : static_cast<float>(interval_us);
    return static_cast<uint32_t>(static_cast<float>(packet_bytes(msgid)) * 1e6f / us + 0.5f);
}

// A message of the stream table once in the next loop; STATUSTEXT: the boot report again
// (after the one under way, if any: send_boot_report).
uint8_t GcsLink::request_message(uint32_t msgid) {
    if (msgid == MAVLINK_MSG_ID_STATUSTEXT) {
        boot_asked_ = true;
        return MAV_RESULT_ACCEPTED;
    }
    Stream* s = stream(msgid);
    if (s == nullptr) return MAV_RESULT_DENIED;
    s->requested = true;
    return MAV_RESULT_ACCEPTED;
}

GcsLink::Stream* GcsLink::stream(uint32_t msgid) {
    for (Stream& s : streams_) {
        if (s.msgid == msgid) return &s;
    }
    return nullptr;
}

bool GcsLink::stream_due(Stream& s, uint32_t loop_index, uint64_t now_us) {
    if (s.requested) {
        s.requested = false;
        return true;
    }
    if (s.interval_us == 0 || now_us < s.next_us) return false;
    // On the first one's grid: the next an interval later, or from now if it fell behind.
    const bool on_grid = loop_index > 0 && s.next_us + s.interval_us > now_us;
    s.next_us = (on_grid ? s.next_us : now_us) + s.interval_us;
    return true;
}

void GcsLink::send_heartbeat(const LoopStatus& st) {
    const bool angle = st.mode == FlightMode::Angle;
    const auto base = static_cast<uint8_t>(
        MAV_MODE_FLAG_CUSTOM_MODE_ENABLED | MAV_MODE_FLAG_MANUAL_INPUT_ENABLED |
        (angle ? MAV_MODE_FLAG_STABILIZE_ENABLED : 0) | (st.armed ? MAV_MODE_FLAG_SAFETY_ARMED : 0));
    const uint8_t system_status = st.armed ? MAV_STATE_ACTIVE
                                  : st.imu_stale ? MAV_STATE_CRITICAL : MAV_STATE_STANDBY;
    mavlink_message_t msg;
    mavlink_msg_heartbeat_pack_status(config_.system_id, config_.component_id, &tx_status_, &msg,
                                      MAV_TYPE_QUADROTOR, MAV_AUTOPILOT_GENERIC, base,
                                      static_cast<uint32_t>(st.mode), system_status);
    send(msg);
}

void GcsLink::send_fw_status(const LoopStatus& st, uint64_t now_us) {
    const Mpu6050Counters& c = st.imu;
    const SupervisorCounters& f = st.supervisor;
    last_load_ = load_.take();
    // The link's drop rate over the last second, for SYS_STATUS.
    const uint32_t total = bytes_sent_ + bytes_dropped_;
    drop_rate_ = static_cast<uint16_t>(total == 0 ? 0 : 10000ull * bytes_dropped_ / total);
    bytes_sent_ = bytes_dropped_ = 0;
    // Since boot, per link (HQ_LINK): this one's and its pair's.
    static_assert(MAVLINK_MSG_HQ_FW_STATUS_FIELD_LINK_BYTES_LEN == 2, "two links: USB, UART0");
    uint32_t link_bytes[2] = {}, link_dropped[2] = {};
    link_bytes[config_.link_id & 1] = bytes_total_;
    link_dropped[config_.link_id & 1] = telemetry_dropped_;
    if (peer_ != nullptr) {
        link_bytes[peer_->config_.link_id & 1] = peer_->bytes_total_;
        link_dropped[peer_->config_.link_id & 1] = peer_->telemetry_dropped_;
    }
    mavlink_message_t msg;
    mavlink_msg_hq_fw_status_pack_status(
        config_.system_id, config_.component_id, &tx_status_, &msg, now_us, st.loop_index, c.packets,
        c.dropped, c.overflows, c.resyncs, c.bad_packets, c.bus_errors, telemetry_dropped_,
        st.dt_clamped, f.non_finite, st.sensor_kind, st.armed ? 1 : 0,
        static_cast<uint8_t>(st.mode), static_cast<uint8_t>(st.excitation_state),
        static_cast<uint8_t>(st.last_reason), f.rc_failsafes, f.host_failsafes, f.imu_stale,
        f.imu_resets, f.imu_reinits, f.arm_refused, f.exc_refused, f.exc_stopped,
        last_load_.median, last_load_.max, last_load_.overruns, config_.link_id, link_bytes,
        link_dropped, static_cast<uint8_t>(st.log.card), st.log.records, st.log.dropped,
        st.log.bytes);
    send(msg);
}

void GcsLink::send_sys_status(const LoopStatus& st) {
    const uint32_t present = MAV_SYS_STATUS_SENSOR_3D_GYRO | MAV_SYS_STATUS_SENSOR_3D_ACCEL |
                             MAV_SYS_STATUS_SENSOR_ANGULAR_RATE_CONTROL |
                             MAV_SYS_STATUS_SENSOR_ATTITUDE_STABILIZATION |
                             MAV_SYS_STATUS_SENSOR_MOTOR_OUTPUTS | MAV_SYS_STATUS_SENSOR_RC_RECEIVER |
                             MAV_SYS_STATUS_AHRS | MAV_SYS_STATUS_PREARM_CHECK;
    uint32_t enabled = present;
    if (st.mode != FlightMode::Angle) enabled &= ~MAV_SYS_STATUS_SENSOR_ATTITUDE_STABILIZATION;
    if (!st.armed) enabled &= ~MAV_SYS_STATUS_SENSOR_MOTOR_OUTPUTS;
    uint32_t health = present;
    if (!st.imu_ok) {
        health &= ~(MAV_SYS_STATUS_SENSOR_3D_GYRO | MAV_SYS_STATUS_SENSOR_3D_ACCEL | MAV_SYS_STATUS_AHRS);
    }
    if (st.rc.age_us > st.rc_timeout_us) health &= ~MAV_SYS_STATUS_SENSOR_RC_RECEIVER;
    // Pre-arm: healthy while a command would arm now (or it is armed): MAVSDK's is_armable.
    if (!st.prearm_ok) {
        health &= ~MAV_SYS_STATUS_PREARM_CHECK;
    }
    // Load: the median loop's share of its period, in 0.1 % (the target's cycle counter).
    uint16_t load = 0;
    if (config_.cpu_hz > 0) {
        const float budget = static_cast<float>(config_.cpu_hz) / config_.loop_rate_hz;
        const float permille = 1000.0f * static_cast<float>(last_load_.median) / budget;
        load = static_cast<uint16_t>(permille > 1000.0f ? 1000.0f : permille);
    }
    const Mpu6050Counters& c = st.imu;
    mavlink_message_t msg;
    mavlink_msg_sys_status_pack_status(
        config_.system_id, config_.component_id, &tx_status_, &msg, present, enabled, health, load,
        UINT16_MAX, -1, -1, drop_rate_, static_cast<uint16_t>(rx_status_.packet_rx_drop_count),
        static_cast<uint16_t>(c.bus_errors), static_cast<uint16_t>(c.resyncs),
        static_cast<uint16_t>(c.bad_packets), static_cast<uint16_t>(st.dt_clamped), 0, 0, 0);
    send(msg);
}

void GcsLink::send_autopilot_version() {
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

void GcsLink::send_servo_output(const LoopStatus& st, uint64_t now_us) {
    // The ESC pulses the motors get: min + f (max - min) armed, the stop pulse disarmed and
    // past the rotor count (whose thrust fractions are 0).
    const EscEndpoints& e = st.params.esc;
    uint16_t us[kMaxRotors];
    for (int i = 0; i < kMaxRotors; ++i) {
        const float span = static_cast<float>(e.max_us[i] - e.min_us[i]);
        us[i] = static_cast<uint16_t>(static_cast<float>(e.min_us[i]) + st.state.motor[i] * span + 0.5f);
    }
    mavlink_message_t msg;
    mavlink_msg_servo_output_raw_pack_status(config_.system_id, config_.component_id, &tx_status_,
                                             &msg, static_cast<uint32_t>(now_us), 0, us[0], us[1],
                                             us[2], us[3], us[4], us[5], us[6], us[7], 0, 0, 0, 0,
                                             0, 0, 0, 0);
    send(msg);
}

void GcsLink::send_rc_channels(const LoopStatus& st, uint64_t now_us) {
    const uint16_t* ch = st.rc.channel_us;
    uint8_t count = 0;
    for (int i = 0; i < kRcChannels; ++i) count = ch[i] != 0 ? static_cast<uint8_t>(i + 1) : count;
    const uint16_t u = kUnusedChannel;
    mavlink_message_t msg;
    mavlink_msg_rc_channels_pack_status(config_.system_id, config_.component_id, &tx_status_, &msg,
                                        boot_ms(now_us), count, ch[0], ch[1],
                                        ch[2], ch[3], ch[4], ch[5], ch[6], ch[7], u, u, u, u, u,
                                        u, u, u, u, u, UINT8_MAX);
    send(msg);
}

void GcsLink::send_scaled_imu(const LoopStatus& st, uint64_t now_us) {
    // mG and mrad/s; the magnetometer and temperature are not measured (0).
    constexpr float kMilliG = 1000.0f / kGravity;
    const Vec3& a = st.state.accel;
    const Vec3& g = st.state.rate;
    mavlink_message_t msg;
    mavlink_msg_scaled_imu_pack_status(config_.system_id, config_.component_id, &tx_status_, &msg,
                                       boot_ms(now_us), saturate16(a.x * kMilliG),
                                       saturate16(a.y * kMilliG), saturate16(a.z * kMilliG),
                                       saturate16(g.x * 1000.0f), saturate16(g.y * 1000.0f),
                                       saturate16(g.z * 1000.0f), 0, 0, 0, 0);
    send(msg);
}

void GcsLink::send_highres_imu(const LoopStatus& st, uint64_t now_us) {
    // m/s^2 and rad/s as measured (FRD body axes); nothing else is measured, and
    // fields_updated says so (accelerometer and gyro bits only).
    constexpr uint16_t kAccelGyro = HIGHRES_IMU_UPDATED_XACC | HIGHRES_IMU_UPDATED_YACC |
                                    HIGHRES_IMU_UPDATED_ZACC | HIGHRES_IMU_UPDATED_XGYRO |
                                    HIGHRES_IMU_UPDATED_YGYRO | HIGHRES_IMU_UPDATED_ZGYRO;
    const Vec3& a = st.state.accel;
    const Vec3& g = st.state.rate;
    mavlink_message_t msg;
    mavlink_msg_highres_imu_pack_status(config_.system_id, config_.component_id, &tx_status_, &msg,
                                        now_us, a.x, a.y, a.z, g.x, g.y, g.z, 0, 0, 0, 0, 0, 0, 0,
                                        kAccelGyro, 0);
    send(msg);
}

void GcsLink::send_attitude(const LoopStatus& st, uint64_t now_us) {
    const LoopState& x = st.state;
    mavlink_message_t msg;
    mavlink_msg_attitude_pack_status(config_.system_id, config_.component_id, &tx_status_, &msg,
                                     boot_ms(now_us), x.attitude.roll,
                                     x.attitude.pitch, x.attitude.yaw, x.rate.x, x.rate.y, x.rate.z);
    send(msg);
}

void GcsLink::send_stream(uint32_t msgid, const LoopStatus& st, uint64_t now_us) {
    switch (msgid) {
        case MAVLINK_MSG_ID_HEARTBEAT: send_heartbeat(st); return;
        case MAVLINK_MSG_ID_HQ_FW_STATUS: send_fw_status(st, now_us); return;
        case MAVLINK_MSG_ID_SYS_STATUS: send_sys_status(st); return;
        case MAVLINK_MSG_ID_SERVO_OUTPUT_RAW: send_servo_output(st, now_us); return;
        case MAVLINK_MSG_ID_SCALED_IMU: send_scaled_imu(st, now_us); return;
        case MAVLINK_MSG_ID_HIGHRES_IMU: send_highres_imu(st, now_us); return;
        case MAVLINK_MSG_ID_RC_CHANNELS: send_rc_channels(st, now_us); return;
        case MAVLINK_MSG_ID_AUTOPILOT_VERSION: send_autopilot_version(); return;
        case MAVLINK_MSG_ID_ATTITUDE: send_attitude(st, now_us); return;
        default: return;
    }
}

void GcsLink::send_telemetry(const LoopStatus& st) {
    // Order matters to the simulator: HQ_SYSID_SAMPLE is the last message of every loop, so
    // a reader that has it has the whole loop's telemetry.
    const uint64_t now = st.time_us;      // the loop's, not this link's moment of sending
    for (Stream& s : streams_) {
        if (stream_due(s, st.loop_index, now)) send_stream(s.msgid, st, now);
    }
    send_params(st.params);
    send_sysid_sample(st, now);
}

void GcsLink::send_sysid_sample(const LoopStatus& st, uint64_t now_us) {
    const LoopState& x = st.state;
    const SysidSample s = sysid_sample(st);
    mavlink_message_t msg;
    mavlink_msg_hq_sysid_sample_pack_status(
        config_.system_id, config_.component_id, &tx_status_, &msg, now_us, seq_++,
        static_cast<uint8_t>(st.exc_axis), static_cast<uint8_t>(st.exc_injection),
        static_cast<uint8_t>(st.excitation_state), st.armed ? 1 : 0,
        static_cast<uint8_t>(st.mode), x.excitation, s.angle_sp, s.rate_sp, s.rate, s.angle,
        s.axis_cmd, x.saturation, x.rotor_count, x.motor);
    send(msg);
}

}  // namespace hq
