#include "flight_controller.hpp"

#include <cmath>

#include "attitude.hpp"

namespace hq {

// The core's enums take their values from the dialect (types.hpp, excitation.hpp,
// supervisor.hpp); the arrays the messages carry must match the core's.
static_assert(kMotors == MAVLINK_MSG_HQ_SYSID_SAMPLE_FIELD_MOTOR_LEN &&
              kMotors == MAVLINK_MSG_HQ_ACTUATOR_FRAME_FIELD_MOTOR_LEN, "one motor value per rotor");

namespace {

// Parameters are saved once they have not changed for this long (a ground station's
// "param load" sends dozens in a row: one save, not dozens of flash erases).
constexpr uint64_t kSaveQuietUs = 500000;
// dt outside [kDtMin, kDtMax] x nominal is clamped (a late or early loop must not make the
// derivative or integral jump).
constexpr float kDtMin = 0.25f, kDtMax = 4.0f;

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
      imu_(config.imu), filter_(config.attitude_filter), cascade_(config.tunables.gains),
      mixer_(config.geometry), supervisor_(config.tunables.safety, config.loop_rate_hz),
      params_(config.tunables),
      streams_{{MAVLINK_MSG_ID_HEARTBEAT, 1000000, 1000000, 0, false},
               {MAVLINK_MSG_ID_HQ_FW_STATUS, 1000000, 1000000, 0, false},
               {MAVLINK_MSG_ID_SYS_STATUS, 1000000, 1000000, 0, false},
               {MAVLINK_MSG_ID_ATTITUDE, 1, 1, 0, false},          // every loop
               {MAVLINK_MSG_ID_SERVO_OUTPUT_RAW, 100000, 100000, 0, false},
               {MAVLINK_MSG_ID_SCALED_IMU, 100000, 100000, 0, false},
               // SI units: what MAVSDK's imu() and other clients wait for
               {MAVLINK_MSG_ID_HIGHRES_IMU, 100000, 100000, 0, false},
               {MAVLINK_MSG_ID_RC_CHANNELS, 200000, 200000, 0, false},
               {MAVLINK_MSG_ID_AUTOPILOT_VERSION, 0, 0, 0, false}} {}   // on request only

InitResult FlightController::init() {
    motors_.disarm();
    load_params();
    apply_params(kParamEsc, clock_.micros());
    imu_init_ = init_imu();
    return imu_init_;
}

// Initialises the IMU on the path IMU_PATH names (the DMP only when the build has its
// firmware) and tells the Supervisor; a STATUSTEXT when the chip is missing or the DMP
// set-up fell back to the raw path.
InitResult FlightController::init_imu() {
    Mpu6050Config imu = config_.imu;
    if (params_.values().imu_path == ImuPath::Raw) {
        imu.dmp_image = imu.dmp_config = imu.dmp_updates = nullptr;
        imu.dmp_image_size = imu.dmp_config_size = imu.dmp_updates_size = 0;
    }
    imu_.configure(imu);
    const InitResult r = imu_.init(i2c_, clock_);
    if (r == InitResult::OkRawFallback) {
        send_statustext(MAV_SEVERITY_WARNING, dmp_failure_text(imu_.dmp_failure()));
    } else if (r == InitResult::NoDevice || r == InitResult::BusError) {
        send_statustext(MAV_SEVERITY_CRITICAL, "IMU: MPU6050 not found");
    }
    supervisor_.imu_initialised(clock_.micros(), imu_timeout_for(imu_.sample_rate_hz()));
    filter_.reset();
    return r;
}

void FlightController::load_params() {
    if (config_.storage == nullptr) return;              // defaults, nothing to say
    uint8_t record[ParamStorage::kMaxBytes];
    size_t n = 0;
    const StoreStatus st = config_.storage->load(record, sizeof(record), n);
    LoadReport r;
    if (st == StoreStatus::Ok) r = params_.decode(record, n);
    if (st == StoreStatus::Corrupt || r.status == LoadReport::Status::Corrupt) {
        send_statustext(MAV_SEVERITY_WARNING, "params: store corrupt; defaults loaded");
    } else if (r.status == LoadReport::Status::Empty) {
        send_statustext(MAV_SEVERITY_INFO, "params: none stored; defaults");
    } else if (r.out_of_range > 0) {
        char text[MAVLINK_MSG_STATUSTEXT_FIELD_TEXT_LEN];
        set_result_text(SetResult::Range, r.first_bad, text, sizeof(text));
        send_statustext(MAV_SEVERITY_WARNING, text);     // that one stays at its default
    }
}

// The parameters' values into the parts that fly with them. The gains and bounds take
// effect at once (the PID keeps its integral term, so a gain change is bumpless); the ESC
// endpoints and the IMU's path only when `changed` says so, and only while disarmed (the
// protocol refuses them while armed).
void FlightController::apply_params(uint8_t changed, uint64_t now_us) {
    const Tunables& t = params_.values();
    cascade_.set_gains(t.gains);
    supervisor_.set_limits(t.safety);
    if (supervisor_.armed()) return;
    if (changed & kParamEsc) motors_.set_endpoints(t.esc);
    if (changed & kParamImu) {
        imu_init_ = init_imu();
        supervisor_.imu_initialised(now_us, imu_timeout_for(imu_.sample_rate_hz()));
    }
}

void FlightController::save_params_when_due(uint64_t now_us) {
    if (params_dirty_ && !supervisor_.armed() && now_us - params_changed_us_ >= kSaveQuietUs) {
        save_params();
    }
}

// Only while disarmed: on flash this blocks for tens of milliseconds.
bool FlightController::save_params() {
    params_dirty_ = false;
    if (config_.storage == nullptr) {
        send_statustext(MAV_SEVERITY_INFO, "params: no storage; kept until restart");
        return false;
    }
    uint8_t record[Params::kRecordBytes];
    const size_t n = params_.encode(record, sizeof(record));
    const bool ok = config_.storage->save(record, n);
    send_statustext(ok ? MAV_SEVERITY_INFO : MAV_SEVERITY_CRITICAL,
                    ok ? "params: saved" : "params: save failed; not stored");
    return ok;
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
    rc_ = rc;
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
    save_params_when_due(now);
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
    state_.accel = s.accel_m_s2;
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
    imu_init_ = imu_.init(i2c_, clock_);
    const bool ok = imu_init_ == InitResult::OkDmp || imu_init_ == InitResult::OkRaw;
    supervisor_.imu_initialised(now_us, imu_timeout_for(imu_.sample_rate_hz()));   // its path's rate
    supervisor_.imu_recovery_result(
        health == ImuHealth::Unconfigured ? Reason::ImuReset : Reason::ImuStalled, ok, now_us);
    filter_.reset();
}

void FlightController::run_control(const RcInput& rc, float excitation, float dt_s) {
    const Sticks s = sticks(rc, params_.values().sticks);
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

}  // namespace hq
