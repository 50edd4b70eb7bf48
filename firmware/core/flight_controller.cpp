#include "flight_controller.hpp"

#include <cmath>

#include "attitude.hpp"

namespace hq {

namespace {

constexpr uint16_t kRcCenter = 1500, kRcMin = 1000, kRcHalfSpan = 500;
constexpr uint16_t kRcArmHigh = 1700;        // channel 5 above this: arm requested
constexpr uint16_t kRcThrottleLow = 1100;    // throttle below this counts as low for arming
constexpr uint16_t kRcModeRate = 1700;       // channel 6 above this: rate mode
constexpr int kChRoll = 0, kChPitch = 1, kChThrottle = 2, kChYaw = 3, kChArm = 4, kChMode = 5;
constexpr uint64_t kSlowPeriodUs = 1000000;  // HEARTBEAT, HQ_FW_STATUS: 1 Hz
// dt outside [kDtMin, kDtMax] x nominal is clamped (a late or early loop must not make the
// derivative or integral jump).
constexpr float kDtMin = 0.25f, kDtMax = 4.0f;

float clampf(float x, float lo, float hi) { return x < lo ? lo : (x > hi ? hi : x); }

// -1..1 from a stick channel; 0 when the channel has no signal.
float stick(const RcInput& rc, int ch) {
    const uint16_t us = rc.channel_us[ch];
    if (us == 0) return 0.0f;
    return clampf((static_cast<float>(us) - kRcCenter) / kRcHalfSpan, -1.0f, 1.0f);
}

float throttle(const RcInput& rc) {
    const uint16_t us = rc.channel_us[kChThrottle];
    if (us == 0) return 0.0f;
    return clampf((static_cast<float>(us) - kRcMin) / (2.0f * kRcHalfSpan), 0.0f, 1.0f);
}

bool finite3(const Vec3& v) { return std::isfinite(v.x) && std::isfinite(v.y) && std::isfinite(v.z); }

}  // namespace

FlightController::FlightController(const FlightControllerConfig& config, I2cBus& i2c,
                                   Clock& clock, SerialPort& telemetry, MotorOutputs& motors)
    : config_(config), i2c_(i2c), clock_(clock), telemetry_(telemetry), motors_(motors),
      imu_(config.imu), attitude_ctl_(config.gains), rate_ctl_(config.gains),
      mixer_(config.geometry) {}

InitResult FlightController::init() {
    motors_.disarm();
    const InitResult r = imu_.init(i2c_, clock_);
    if (r == InitResult::OkRawFallback) {
        send_statustext(MAV_SEVERITY_WARNING, "IMU: DMP image did not verify; raw FIFO path");
    } else if (r == InitResult::NoDevice || r == InitResult::BusError) {
        send_statustext(MAV_SEVERITY_CRITICAL, "IMU: MPU6050 not found");
    }
    return r;
}

float FlightController::clamp_dt(uint64_t now_us) {
    const float nominal = 1.0f / config_.loop_rate_hz;
    if (!have_time_) {
        have_time_ = true;
        last_us_ = now_us;
        return nominal;
    }
    const float dt = static_cast<float>(now_us - last_us_) * 1e-6f;
    last_us_ = now_us;
    const float clamped = clampf(dt, kDtMin * nominal, kDtMax * nominal);
    if (clamped != dt) ++dt_clamped_;
    return clamped;
}

void FlightController::step(const RcInput& rc) {
    const uint64_t now = clock_.micros();
    const float dt = clamp_dt(now);
    state_.dt_s = dt;
    read_imu(dt);
    handle_commands(rc);
    check_failsafes(rc);
    run_control(rc, dt);
    send_telemetry();
    ++loops_;
}

void FlightController::read_imu(float dt_s) {
    ImuSample s;
    if (!imu_.poll(i2c_, s)) return;            // no new packet: keep the last estimate
    if (s.has_attitude) {
        state_.attitude = to_euler(s.attitude);
    } else {
        filter_.update(s.gyro_rad_s, s.accel_m_s2, dt_s);
        state_.attitude = to_euler(filter_.quaternion());
    }
    state_.rate = s.gyro_rad_s;
}

void FlightController::handle_commands(const RcInput& rc) {
    uint8_t buf[64];
    size_t n;
    while ((n = telemetry_.read(buf, sizeof(buf))) > 0) {
        for (size_t i = 0; i < n; ++i) {
            mavlink_message_t msg;
            mavlink_status_t status;
            if (mavlink_frame_char_buffer(&rx_msg_, &rx_status_, buf[i], &msg, &status) ==
                MAVLINK_FRAMING_OK) {
                handle_message(msg, rc);
            }
        }
    }
    handle_rc_arming(rc);
}

void FlightController::handle_message(const mavlink_message_t& msg, const RcInput& rc) {
    mavlink_message_t out;
    switch (msg.msgid) {
        case MAVLINK_MSG_ID_HEARTBEAT:
            last_host_heartbeat_us_ = clock_.micros();
            return;
        case MAVLINK_MSG_ID_COMMAND_LONG: {
            mavlink_command_long_t cmd;
            mavlink_msg_command_long_decode(&msg, &cmd);
            if (cmd.target_system != config_.system_id) return;
            uint8_t result = MAV_RESULT_UNSUPPORTED;
            if (cmd.command == MAV_CMD_COMPONENT_ARM_DISARM) {
                last_host_heartbeat_us_ = clock_.micros();
                if (cmd.param1 > 0.5f) {
                    result = try_arm(rc, true) ? MAV_RESULT_ACCEPTED : MAV_RESULT_DENIED;
                } else {
                    disarm("disarmed by command");
                    result = MAV_RESULT_ACCEPTED;
                }
            }
            mavlink_msg_command_ack_pack_status(config_.system_id, config_.component_id, &tx_status_,
                                                &out, cmd.command, result, 0, 0, msg.sysid,
                                                msg.compid);
            send(out);
            return;
        }
        case MAVLINK_MSG_ID_SET_MODE: {
            mavlink_set_mode_t sm;
            mavlink_msg_set_mode_decode(&msg, &sm);
            if (sm.target_system != config_.system_id) return;
            if (sm.custom_mode == static_cast<uint32_t>(Mode::Angle) ||
                sm.custom_mode == static_cast<uint32_t>(Mode::Rate)) {
                flight_mode_ = static_cast<Mode>(sm.custom_mode);
                if (armed()) mode_ = flight_mode_;
            }
            return;
        }
        case MAVLINK_MSG_ID_HQ_EXCITATION: {
            mavlink_hq_excitation_t ex;
            mavlink_msg_hq_excitation_decode(&msg, &ex);
            if (ex.target_system != config_.system_id) return;
            bool accepted = false;
            if (ex.action == HQ_EXCITATION_STOP) {
                excitation_.stop();
                accepted = true;
            } else if (ex.axis <= static_cast<uint8_t>(Axis::Yaw) &&
                       ex.injection <= static_cast<uint8_t>(Injection::Mixer) &&
                       !(ex.axis == static_cast<uint8_t>(Axis::Yaw) &&
                         ex.injection == static_cast<uint8_t>(Injection::Angle))) {
                ExcitationConfig cfg;
                cfg.axis = static_cast<Axis>(ex.axis);
                cfg.injection = static_cast<Injection>(ex.injection);
                cfg.freq_hz = ex.freq_hz;
                cfg.amplitude = ex.amplitude;
                cfg.cycles = ex.cycles;
                cfg.fade_cycles = ex.fade_cycles;
                accepted = excitation_.start(cfg, config_.loop_rate_hz);
                if (accepted) {
                    exc_axis_ = cfg.axis;
                    exc_injection_ = cfg.injection;
                }
            }
            send_excitation_status(accepted);
            return;
        }
        default:
            return;
    }
}

void FlightController::handle_rc_arming(const RcInput& rc) {
    const bool high = rc.channel_us[kChArm] > kRcArmHigh;
    if (high && !rc_arm_switch_was_high_ && !armed()) try_arm(rc, false);
    if (!high && rc_arm_switch_was_high_ && armed() && !armed_by_command_) disarm("RC disarm");
    rc_arm_switch_was_high_ = high;
    if (rc.channel_us[kChMode] != 0) {
        flight_mode_ = rc.channel_us[kChMode] > kRcModeRate ? Mode::Rate : Mode::Angle;
        if (armed()) mode_ = flight_mode_;
    }
}

bool FlightController::try_arm(const RcInput& rc, bool by_command) {
    if (armed()) return true;
    if (rc.channel_us[kChThrottle] >= kRcThrottleLow && rc.channel_us[kChThrottle] != 0) {
        send_statustext(MAV_SEVERITY_WARNING, "arming refused: throttle not low");
        return false;
    }
    if (imu_.mode() == SensorMode::None) {
        send_statustext(MAV_SEVERITY_WARNING, "arming refused: no IMU");
        return false;
    }
    attitude_ctl_.reset();
    rate_ctl_.reset();
    armed_by_command_ = by_command;
    mode_ = flight_mode_;
    return true;
}

void FlightController::disarm(const char* reason) {
    if (armed()) send_statustext(MAV_SEVERITY_NOTICE, reason);
    mode_ = Mode::Disarmed;
    armed_by_command_ = false;
    excitation_.stop();
    motors_.disarm();
}

void FlightController::check_failsafes(const RcInput& rc) {
    if (!armed()) return;
    if (rc.age_us > config_.rc_timeout_us) {
        disarm("failsafe: RC lost, motors off");
    } else if (armed_by_command_ &&
               clock_.micros() - last_host_heartbeat_us_ > config_.link_timeout_us) {
        disarm("failsafe: host link lost, motors off");
    }
}

void FlightController::run_control(const RcInput& rc, float dt_s) {
    const int a = static_cast<int>(exc_axis_);
    const float exc = excitation_.next();
    state_.excitation = exc;
    const Mode flight = mode_ == Mode::Disarmed ? flight_mode_ : mode_;

    Euler angle_sp{stick(rc, kChRoll) * config_.max_stick_angle_rad,
                   stick(rc, kChPitch) * config_.max_stick_angle_rad, state_.attitude.yaw};
    Vec3 rate_sp{stick(rc, kChRoll) * config_.max_stick_rate_rad_s,
                 stick(rc, kChPitch) * config_.max_stick_rate_rad_s,
                 stick(rc, kChYaw) * config_.max_yaw_rate_rad_s};
    if (exc_injection_ == Injection::Angle && a < 2) {
        (a == 0 ? angle_sp.roll : angle_sp.pitch) += exc;
    }
    angle_sp.roll = clampf(angle_sp.roll, -config_.max_angle_rad, config_.max_angle_rad);
    angle_sp.pitch = clampf(angle_sp.pitch, -config_.max_angle_rad, config_.max_angle_rad);
    if (flight == Mode::Angle || flight == Mode::Sysid) {
        const Vec3 outer = attitude_ctl_.update(angle_sp, state_.attitude, dt_s);
        rate_sp.x = outer.x;
        rate_sp.y = outer.y;
    }
    if (exc_injection_ == Injection::Rate) rate_sp[a] += exc;
    Vec3 torque = rate_ctl_.update(rate_sp, state_.rate, dt_s);
    if (exc_injection_ == Injection::Mixer) torque[a] += exc;

    state_.collective = throttle(rc);
    const MixerOutput out =
        mixer_.mix(MixerCommand{state_.collective, torque.x, torque.y, torque.z});
    bool finite = finite3(torque) && finite3(rate_sp) && std::isfinite(angle_sp.roll) &&
                  std::isfinite(angle_sp.pitch);
    for (float m : out.motor) finite = finite && std::isfinite(m);
    state_.angle_sp = angle_sp;
    state_.rate_sp = rate_sp;
    state_.torque = torque;
    if (!finite) {
        ++nan_events_;
        attitude_ctl_.reset();
        rate_ctl_.reset();
        for (float& m : state_.motor) m = 0.0f;
        if (armed()) send_statustext(MAV_SEVERITY_CRITICAL, "non-finite value in control");
        disarm("motors cut: non-finite value");
        return;
    }
    if (armed()) {
        if (excitation_.active()) mode_ = Mode::Sysid;
        else if (mode_ == Mode::Sysid) mode_ = flight_mode_;
        for (int i = 0; i < kMotors; ++i) state_.motor[i] = out.motor[i];
        motors_.set(state_.motor);
    } else {
        for (float& m : state_.motor) m = 0.0f;
        motors_.disarm();
        attitude_ctl_.reset();         // nothing integrates while the motors are off
        rate_ctl_.reset();
    }
}

void FlightController::send(const mavlink_message_t& msg) {
    uint8_t buf[MAVLINK_MAX_PACKET_LEN];
    const uint16_t len = mavlink_msg_to_send_buffer(buf, &msg);
    if (telemetry_.write(buf, len) < len) telemetry_dropped_ += len;
}

void FlightController::send_statustext(uint8_t severity, const char* text) {
    mavlink_message_t msg;
    mavlink_msg_statustext_pack_status(config_.system_id, config_.component_id, &tx_status_, &msg,
                                       severity, text, 0, 0);
    send(msg);
}

void FlightController::send_excitation_status(bool accepted) {
    mavlink_message_t msg;
    mavlink_msg_hq_excitation_status_pack_status(
        config_.system_id, config_.component_id, &tx_status_, &msg, clock_.micros(),
        accepted ? 1 : 0, excitation_.active() ? 1 : 0, static_cast<uint8_t>(exc_axis_),
        static_cast<uint8_t>(exc_injection_), excitation_.actual_freq_hz(),
        excitation_.period_samples(), excitation_.total_samples());
    send(msg);
}

void FlightController::send_telemetry() {
    // Order matters to the simulator: HQ_SYSID_SAMPLE is the last message of every loop, so
    // a reader that has it has the whole loop's telemetry.
    const uint64_t now = clock_.micros();
    const int a = static_cast<int>(exc_axis_);
    mavlink_message_t msg;
    if (loops_ == 0 || now - last_slow_us_ >= kSlowPeriodUs) {
        last_slow_us_ = now;
        const uint8_t base = static_cast<uint8_t>(MAV_MODE_FLAG_CUSTOM_MODE_ENABLED |
                                                  (armed() ? MAV_MODE_FLAG_SAFETY_ARMED : 0));
        mavlink_msg_heartbeat_pack_status(config_.system_id, config_.component_id, &tx_status_,
                                          &msg, MAV_TYPE_QUADROTOR, MAV_AUTOPILOT_GENERIC, base,
                                          static_cast<uint32_t>(mode_),
                                          armed() ? MAV_STATE_ACTIVE : MAV_STATE_STANDBY);
        send(msg);
        const Mpu6050Counters& c = imu_.counters();
        const uint8_t kind = imu_.mode() == SensorMode::Dmp ? HQ_SENSOR_DMP
                             : imu_.mode() == SensorMode::Raw ? HQ_SENSOR_RAW : HQ_SENSOR_NONE;
        mavlink_msg_hq_fw_status_pack_status(config_.system_id, config_.component_id, &tx_status_,
                                             &msg, now, loops_, c.packets, c.dropped, c.overflows,
                                             c.resyncs, c.bad_packets, c.bus_errors,
                                             telemetry_dropped_, dt_clamped_, nan_events_, kind);
        send(msg);
    }
    const bool active = excitation_.active();
    if (active != exc_was_active_) send_excitation_status(true);
    exc_was_active_ = active;
    mavlink_msg_attitude_pack_status(config_.system_id, config_.component_id, &tx_status_, &msg,
                                     static_cast<uint32_t>(now / 1000), state_.attitude.roll,
                                     state_.attitude.pitch, state_.attitude.yaw, state_.rate.x,
                                     state_.rate.y, state_.rate.z);
    send(msg);
    const uint8_t exc_state = excitation_.measuring() ? 2 : (excitation_.active() ? 1 : 0);
    const float angle_sp = a == 0 ? state_.angle_sp.roll : (a == 1 ? state_.angle_sp.pitch : 0.0f);
    mavlink_msg_hq_sysid_sample_pack_status(
        config_.system_id, config_.component_id, &tx_status_, &msg, now, seq_++,
        static_cast<uint8_t>(exc_axis_), static_cast<uint8_t>(exc_injection_), exc_state,
        state_.excitation, angle_sp, state_.rate_sp[a], state_.rate[a], state_.attitude[a],
        state_.torque[a], state_.motor);
    send(msg);
}

}  // namespace hq
