#include "flight_controller.hpp"

#include <cmath>

#include "attitude.hpp"

namespace hq {

// The core's enums take their values from the dialect (types.hpp, excitation.hpp,
// supervisor.hpp); the arrays the messages carry must match the core's.
static_assert(kMotors == MAVLINK_MSG_HQ_SYSID_SAMPLE_FIELD_MOTOR_LEN &&
              kMotors == MAVLINK_MSG_HQ_ACTUATOR_FRAME_FIELD_MOTOR_LEN, "one motor value per rotor");

namespace {

constexpr uint64_t kSlowPeriodUs = 1000000;  // HEARTBEAT, HQ_FW_STATUS: 1 Hz
// dt outside [kDtMin, kDtMax] x nominal is clamped (a late or early loop must not make the
// derivative or integral jump).
constexpr float kDtMin = 0.25f, kDtMax = 4.0f;
// STATUSTEXT.text, NUL-terminated when shorter.
constexpr size_t kStatusTextLen = MAVLINK_MSG_STATUSTEXT_FIELD_TEXT_LEN;

float clampf(float x, float lo, float hi) { return x < lo ? lo : (x > hi ? hi : x); }

// Why the DMP set-up fell back to the raw path (STATUSTEXT, at most 50 characters).
const char* dmp_failure_text(DmpStep step) {
    switch (step) {
        case DmpStep::Tables: return "IMU: DMP tables missing or bad; raw FIFO path";
        case DmpStep::Image: return "IMU: DMP image did not verify; raw FIFO path";
        case DmpStep::Config: return "IMU: DMP config did not verify; raw FIFO path";
        case DmpStep::Registers: return "IMU: DMP set-up bus error; raw FIFO path";
        case DmpStep::Updates: return "IMU: DMP updates did not verify; raw FIFO path";
        case DmpStep::None: break;
    }
    return "IMU: DMP set-up failed; raw FIFO path";
}

bool finite3(const Vec3& v) { return std::isfinite(v.x) && std::isfinite(v.y) && std::isfinite(v.z); }

}  // namespace

FlightController::FlightController(const FlightControllerConfig& config, I2cBus& i2c,
                                   Clock& clock, SerialPort& telemetry, MotorOutputs& motors)
    : config_(config), i2c_(i2c), clock_(clock), telemetry_(telemetry), motors_(motors),
      imu_(config.imu), filter_(config.attitude_filter), cascade_(config.gains), mixer_(config.geometry),
      supervisor_(config.safety, config.loop_rate_hz) {}

InitResult FlightController::init() {
    motors_.disarm();
    const InitResult r = imu_.init(i2c_, clock_);
    if (r == InitResult::OkRawFallback) {
        send_statustext(MAV_SEVERITY_WARNING, dmp_failure_text(imu_.dmp_failure()));
    } else if (r == InitResult::NoDevice || r == InitResult::BusError) {
        send_statustext(MAV_SEVERITY_CRITICAL, "IMU: MPU6050 not found");
    }
    supervisor_.imu_initialised(clock_.micros(), imu_timeout_for(imu_.sample_rate_hz()));
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
    SupervisorInputs in;
    in.now_us = now;
    in.rc = rc;
    in.imu_sample = read_imu(dt);
    in.attitude = state_.attitude;
    in.rate = state_.rate;
    handle_commands(rc, now);
    const float excitation = supervisor_.update(in);
    recover_imu(now);
    run_control(rc, excitation, dt);
    send_events();
    send_telemetry();
    ++loops_;
}

bool FlightController::read_imu(float dt_s) {
    ImuSample s;
    if (!imu_.poll(i2c_, s)) return false;      // no new packet: keep the last estimate
    if (s.has_attitude) {
        state_.attitude = to_euler(s.attitude);
    } else {
        // Armed is in flight as far as the filter knows: the low gain and the tilt weight.
        filter_.update(s.gyro_rad_s, s.accel_m_s2, dt_s, supervisor_.armed());
        state_.attitude = to_euler(filter_.quaternion());
    }
    state_.rate = s.gyro_rad_s;
    state_.sensor_clipped = static_cast<uint8_t>((s.gyro_clipped ? HQ_SATURATION_GYRO : 0) |
                                                 (s.accel_clipped ? HQ_SATURATION_ACCEL : 0));
    return true;
}

void FlightController::recover_imu(uint64_t now_us) {
    if (!supervisor_.imu_recovery_due(now_us)) return;
    const ImuHealth health = imu_.probe(i2c_);
    if (health == ImuHealth::NoAnswer) {
        supervisor_.imu_recovery_result(Reason::ImuNoAnswer, false, now_us);
        return;
    }
    // Disarmed: the motors are off, so the loop may stop for the start-up waits and the
    // whole MotionApps DMP set-up, done again as at boot (about 0.3 s on the board).
    const InitResult r = imu_.init(i2c_, clock_);
    const bool ok = r == InitResult::OkDmp || r == InitResult::OkRaw;
    supervisor_.imu_initialised(now_us, imu_timeout_for(imu_.sample_rate_hz()));   // its path's rate
    supervisor_.imu_recovery_result(
        health == ImuHealth::Unconfigured ? Reason::ImuReset : Reason::ImuStalled, ok, now_us);
    filter_.reset();
}

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
            // The host's, not our own echoed back by a router.
            if (msg.sysid != config_.system_id) supervisor_.host_heartbeat(now_us);
            return;
        case MAVLINK_MSG_ID_COMMAND_LONG:
            handle_command_long(msg, rc, now_us);
            return;
        case MAVLINK_MSG_ID_SET_MODE: {
            mavlink_set_mode_t sm;
            mavlink_msg_set_mode_decode(&msg, &sm);
            if (sm.target_system == config_.system_id) supervisor_.set_mode(sm.custom_mode);
            return;
        }
        case MAVLINK_MSG_ID_HQ_EXCITATION:
            handle_excitation(msg, now_us);
            return;
        default:
            return;
    }
}

void FlightController::handle_command_long(const mavlink_message_t& msg, const RcInput& rc,
                                           uint64_t now_us) {
    mavlink_command_long_t cmd;
    mavlink_msg_command_long_decode(&msg, &cmd);
    if (cmd.target_system != config_.system_id) return;
    uint8_t result = MAV_RESULT_UNSUPPORTED;
    Reason why = Reason::None;
    if (cmd.command == MAV_CMD_COMPONENT_ARM_DISARM) {
        if (cmd.param1 > 0.5f) {
            why = supervisor_.arm_command(rc, now_us);
            result = why == Reason::None ? MAV_RESULT_ACCEPTED : MAV_RESULT_DENIED;
        } else {
            supervisor_.host_heartbeat(now_us);
            supervisor_.disarm_command();
            result = MAV_RESULT_ACCEPTED;
        }
    }
    mavlink_message_t out;
    mavlink_msg_command_ack_pack_status(config_.system_id, config_.component_id, &tx_status_,
                                        &out, cmd.command, result, 0, static_cast<int32_t>(why),
                                        msg.sysid, msg.compid);
    send(out);
}

void FlightController::handle_excitation(const mavlink_message_t& msg, uint64_t now_us) {
    mavlink_hq_excitation_t ex;
    mavlink_msg_hq_excitation_decode(&msg, &ex);
    if (ex.target_system != config_.system_id) return;
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
        why = supervisor_.start_excitation(cfg, now_us);
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

void FlightController::run_control(const RcInput& rc, float excitation, float dt_s) {
    const Sticks s = sticks(rc, config_.sticks);
    const ExcitationConfig& exc = supervisor_.excitation_config();
    CascadeInput in;
    in.mode = supervisor_.mode();
    in.angle_stick = s.angle;
    in.rate_stick = s.rate;
    in.axis = exc.axis;
    in.injection = exc.injection;
    in.excitation = excitation;
    in.attitude = state_.attitude;
    in.rate = state_.rate;
    in.dt_s = dt_s;
    const CascadeOutput c = cascade_.update(in);
    state_.excitation = excitation;
    state_.collective = s.throttle;
    state_.angle_sp = c.angle_sp;
    state_.rate_sp = c.rate_sp;
    state_.torque = c.torque;
    const MixerOutput out = mixer_.mix(MixerCommand{s.throttle, c.torque.x, c.torque.y, c.torque.z});
    state_.saturation = static_cast<uint8_t>(
        state_.sensor_clipped | (out.torque_limited ? HQ_SATURATION_TORQUE : 0) |
        (out.collective_limited ? HQ_SATURATION_COLLECTIVE : 0));
    bool finite = finite3(c.torque) && finite3(c.rate_sp) && std::isfinite(c.angle_sp.roll) &&
                  std::isfinite(c.angle_sp.pitch);
    for (float m : out.motor) finite = finite && std::isfinite(m);
    if (!finite) supervisor_.fault(Reason::NonFinite);
    if (finite && supervisor_.armed()) {
        for (int i = 0; i < kMotors; ++i) state_.motor[i] = out.motor[i];
        motors_.set(state_.motor);
        return;
    }
    for (float& m : state_.motor) m = 0.0f;
    state_.excitation = 0.0f;         // nothing reached the vehicle
    motors_.disarm();
    cascade_.reset();                 // nothing integrates while the motors are off
}

void FlightController::send(const mavlink_message_t& msg) {
    uint8_t buf[MAVLINK_MAX_PACKET_LEN];
    const uint16_t len = mavlink_msg_to_send_buffer(buf, &msg);
    if (telemetry_.write(buf, len) < len) telemetry_dropped_ += len;
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
        ex.period_samples(), ex.total_samples());
    send(msg);
}

uint8_t FlightController::sensor_kind() const {
    return static_cast<uint8_t>(imu_.mode());       // SensorMode is HQ_SENSOR_KIND
}

void FlightController::send_telemetry() {
    // Order matters to the simulator: HQ_SYSID_SAMPLE is the last message of every loop, so
    // a reader that has it has the whole loop's telemetry.
    const uint64_t now = clock_.micros();
    const Supervisor& sup = supervisor_;
    const uint8_t armed = sup.armed() ? 1 : 0;
    const auto mode = static_cast<uint8_t>(sup.mode());
    const auto exc_state = static_cast<uint8_t>(sup.excitation_state());
    mavlink_message_t msg;
    if (loops_ == 0 || now - last_slow_us_ >= kSlowPeriodUs) {
        last_slow_us_ = now;
        const auto base = static_cast<uint8_t>(MAV_MODE_FLAG_CUSTOM_MODE_ENABLED |
                                               (armed ? MAV_MODE_FLAG_SAFETY_ARMED : 0));
        const uint8_t system_status = armed ? MAV_STATE_ACTIVE
                                      : sup.imu_stale() ? MAV_STATE_CRITICAL : MAV_STATE_STANDBY;
        mavlink_msg_heartbeat_pack_status(config_.system_id, config_.component_id, &tx_status_,
                                          &msg, MAV_TYPE_QUADROTOR, MAV_AUTOPILOT_GENERIC, base,
                                          mode, system_status);
        send(msg);
        const Mpu6050Counters& c = imu_.counters();
        const SupervisorCounters& f = sup.counters();
        const LoopLoad::Report load = load_.take();
        mavlink_msg_hq_fw_status_pack_status(
            config_.system_id, config_.component_id, &tx_status_, &msg, now, loops_, c.packets,
            c.dropped, c.overflows, c.resyncs, c.bad_packets, c.bus_errors, telemetry_dropped_,
            dt_clamped_, f.non_finite, sensor_kind(), armed, mode, exc_state,
            static_cast<uint8_t>(sup.last_reason()), f.rc_failsafes, f.host_failsafes, f.imu_stale,
            f.imu_resets, f.imu_reinits, f.arm_refused, f.exc_refused, f.exc_stopped, load.median,
            load.max, load.overruns);
        send(msg);
    }
    mavlink_msg_attitude_pack_status(config_.system_id, config_.component_id, &tx_status_, &msg,
                                     static_cast<uint32_t>(now / 1000), state_.attitude.roll,
                                     state_.attitude.pitch, state_.attitude.yaw, state_.rate.x,
                                     state_.rate.y, state_.rate.z);
    send(msg);
    const ExcitationConfig& exc = sup.excitation_config();
    const int a = static_cast<int>(exc.axis);
    const float angle_sp = a < kAngleAxes ? (a == 0 ? state_.angle_sp.roll : state_.angle_sp.pitch)
                                          : 0.0f;
    mavlink_msg_hq_sysid_sample_pack_status(
        config_.system_id, config_.component_id, &tx_status_, &msg, now, seq_++,
        static_cast<uint8_t>(exc.axis), static_cast<uint8_t>(exc.injection), exc_state, armed,
        mode, state_.excitation, angle_sp, state_.rate_sp[a], state_.rate[a], state_.attitude[a],
        state_.torque[a], state_.motor, state_.saturation);
    send(msg);
}

}  // namespace hq
