#include "flight_controller.hpp"

#include <cmath>

#include "attitude.hpp"
#include "boot_report.hpp"

namespace hq {

namespace {

// dt outside [kDtMin, kDtMax] x nominal is clamped (a late or early loop must not make the
// derivative or integral jump).
constexpr float kDtMin = 0.25f, kDtMax = 4.0f;
// Within kDtJitter x nominal of the loop's period, the interval between two steps is the
// period itself: on the board a tick's step starts a few microseconds late when another
// interrupt (USB, UART, RC capture) is being served as the tick comes, and that latency is
// no change of the loop's period; the control law then does not depend on which interrupt
// delayed which tick (nor on the microsecond rounding of a period that is no whole number of
// them). A missed tick (twice the period) is taken as measured.
constexpr float kDtJitter = 0.05f;

float clampf(float x, float lo, float hi) { return x < lo ? lo : (x > hi ? hi : x); }

bool finite3(const Vec3& v) { return std::isfinite(v.x) && std::isfinite(v.y) && std::isfinite(v.z); }

}  // namespace

FlightController::FlightController(const FlightControllerConfig& config, I2cBus& i2c,
                                   Clock& clock, MotorOutputs& motors)
    : config_(config), i2c_(i2c), clock_(clock), motors_(motors),
      imu_(config.imu), filter_(config.attitude_filter), cascade_(Params::defaults().gains),
      allocation_(allocation_geometry(Params::defaults().geometry)),
      supervisor_(Params::defaults().safety, config.loop_rate_hz) {}

InitResult FlightController::init() {
    motors_.disarm();
    BootReport& boot = status_.boot;
    boot.reset = config_.reset_cause;
    int bad_index = -1;
    boot.params = load_params(bad_index, boot.param_result);
    boot.param_index = static_cast<int16_t>(bad_index);
    apply_params(kParamEsc | kParamGeometry, clock_.micros());
    load_program();                  // after the parameters: their bounds check its steps
    imu_init_ = init_imu();
    boot.imu = imu_finding(imu_init_, params_.values().imu_path);
    boot.dmp_step = imu_.dmp_failure();
    publish(clock_.micros());
    return imu_init_;
}

// Initialises the IMU on the path IMU_PATH names (the DMP only when the build has its
// firmware) and tells the Supervisor; a STATUSTEXT when the chip is missing or the DMP
// set-up fell back to the raw path (boot_report.hpp's words).
InitResult FlightController::init_imu() {
    Mpu6050Config imu = config_.imu;
    if (params_.values().imu_path == ImuPath::Raw) {
        imu.dmp_image = imu.dmp_config = imu.dmp_updates = nullptr;
        imu.dmp_image_size = imu.dmp_config_size = imu.dmp_updates_size = 0;
    }
    imu_.configure(imu);
    const InitResult r = imu_.init(i2c_, clock_);
    const ImuFinding found = imu_finding(r, params_.values().imu_path);
    if (announced(found)) notice(imu_notice(found, imu_.dmp_failure()));
    supervisor_.imu_initialised(clock_.micros(), imu_timeout_for(imu_.sample_rate_hz()));
    filter_.reset();
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
    if (std::fabs(dt - nominal) <= kDtJitter * nominal) return nominal;
    const float clamped = clampf(dt, kDtMin * nominal, kDtMax * nominal);
    if (clamped != dt) ++dt_clamped_;
    return clamped;
}

void FlightController::step(const RcInput& rc, LoopInbox& inbox) {
    const uint64_t now = clock_.micros();
    const float dt = clamp_dt(now);
    status_.state.dt_s = dt;
    status_.notice_count = 0;
    status_.excitation_ended = false;
    status_.program_changed = false;
    if (logger_.counters().card != card_said_) {     // logging stopped, or came back
        card_said_ = logger_.counters().card;
        notice(card_notice(card_said_));
    }
    rc_ = rc;
    SupervisorInputs in;
    in.now_us = now;
    in.rc = rc;
    in.imu_sample = read_imu(dt);
    in.attitude = status_.state.attitude;
    in.rate = status_.state.rate;
    float rotor_excitation[kMaxRotors] = {};
    in.rotor_excitation = rotor_excitation;
    answer(inbox, rc, now);
    run_program(rc, now);
    const float excitation = supervisor_.update(in);
    recover_imu(now);
    run_control(rc, excitation, rotor_excitation, dt);
    publish_events();
    publish(now);
    save_params_when_due(now);     // its notice goes out after the telemetry
    logger_.loop(status_, supervisor_.excitation(), config_.loop_rate_hz);
    ++loops_;
}

// The Supervisor's events as notices, and whether an excitation ended in this step.
void FlightController::publish_events() {
    Event e;
    while (status_.notice_count < LoopStatus::kNotices && supervisor_.next_event(e)) {
        notice(static_cast<uint8_t>(e.severity), reason_text(e.reason));
    }
    status_.notices_before_telemetry = status_.notice_count;
    Reason why;
    if (supervisor_.take_excitation_end(why)) {
        status_.excitation_ended = true;
        status_.end_reason = why;
        status_.excitation = excitation_report();
        program_event(program_runner_.step_ended(why, program_));
    }
}

// What the link reports from this step (telemetry reads nothing else of the loop).
void FlightController::publish(uint64_t now_us) {
    const Supervisor& sup = supervisor_;
    LoopStatus& s = status_;
    s.loop_index = loops_;
    s.time_us = now_us;
    s.armed = sup.armed();
    s.mode = sup.mode();
    s.excitation_state = sup.excitation_state();
    s.exc_axis = sup.excitation_config().axis;
    s.exc_injection = sup.excitation_config().injection;
    s.last_reason = sup.last_reason();
    s.imu_stale = sup.imu_stale();
    s.imu_ok = imu_init_ != InitResult::NoDevice && imu_init_ != InitResult::BusError &&
               !sup.imu_stale();
    s.prearm_ok = sup.armed() || sup.arm_check(rc_, now_us) == Reason::None;
    s.sensor_kind = sensor_kind();
    s.supervisor = sup.counters();
    s.imu = imu_.counters();
    s.dt_clamped = dt_clamped_;
    s.rc = rc_;
    s.rc_timeout_us = sup.limits().rc_timeout_us;
    s.params = params_.values();
    s.program = &program_;
    const LogCounters& log = logger_.counters();
    s.log = LogStatus{log.card, log.records, log.dropped, log.bytes_written};
}

void FlightController::set_card_state(CardState s) {
    status_.boot.card = s;
    status_.log.card = s;
    logger_.set_card(s);
}

void FlightController::notice(uint8_t severity, const char* text, int param_index) {
    notice(Notice{severity, text, param_index});
}

void FlightController::notice(const Notice& n) {
    if (status_.notice_count >= LoopStatus::kNotices) return;     // never: sized for a step
    status_.notice[status_.notice_count++] = n;
}

bool FlightController::read_imu(float dt_s) {
    ImuSample s;
    if (!imu_.poll(i2c_, s)) return false;      // no new packet: keep the last estimate
    if (s.has_attitude) {
        status_.state.attitude = to_euler(s.attitude);
    } else {
        // Armed is in flight as far as the filter knows: the low gain and the tilt weight.
        filter_.update(s.gyro_rad_s, s.accel_m_s2, dt_s, supervisor_.armed());
        status_.state.attitude = to_euler(filter_.quaternion());
    }
    status_.state.rate = s.gyro_rad_s;
    status_.state.accel = s.accel_m_s2;
    status_.state.sensor_clipped = static_cast<uint8_t>((s.gyro_clipped ? HQ_SATURATION_GYRO : 0) |
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

// A motor injection's excitation added to the allocation's thrust fractions, each kept within
// 0..1 (a clipped one flags the torque as limited: the rotor did not get all it was asked).
void FlightController::inject_motors(AllocationOutput& out, float excitation,
                                     const float rotor_excitation[]) const {
    const int rotor = injected_rotor(supervisor_.excitation_config().injection);
    if (rotor == kNoRotor) return;
    for (int i = 0; i < allocation_.count(); ++i) {
        const float add = rotor == kAllRotors ? rotor_excitation[i] : (i == rotor ? excitation : 0.0f);
        const float m = out.motor[i] + add;
        out.motor[i] = clampf(m, 0.0f, 1.0f);
        if (out.motor[i] != m) out.torque_limited = out.saturated = true;
    }
}

void FlightController::run_control(const RcInput& rc, float excitation,
                                   const float rotor_excitation[], float dt_s) {
    const Sticks s = sticks(rc, params_.values().sticks);
    const ExcitationConfig& exc = supervisor_.excitation_config();
    CascadeInput in;
    in.mode = supervisor_.mode();
    in.angle_stick = s.angle;
    in.rate_stick = s.rate;
    in.axis = exc.axis;
    in.injection = exc.injection;
    in.excitation = excitation;
    in.attitude = status_.state.attitude;
    in.rate = status_.state.rate;
    in.dt_s = dt_s;
    const CascadeOutput c = cascade_.update(in);
    status_.state.excitation = excitation;
    status_.state.collective = s.throttle;
    status_.state.angle_sp = c.angle_sp;
    status_.state.rate_sp = c.rate_sp;
    status_.state.torque = c.torque;
    AllocationOutput out =
        allocation_.allocate(MixerCommand{s.throttle, c.torque.x, c.torque.y, c.torque.z});
    inject_motors(out, excitation, rotor_excitation);
    status_.state.saturation = static_cast<uint8_t>(
        status_.state.sensor_clipped | (out.torque_limited ? HQ_SATURATION_TORQUE : 0) |
        (out.collective_limited ? HQ_SATURATION_COLLECTIVE : 0));
    bool finite = finite3(c.torque) && finite3(c.rate_sp) && std::isfinite(c.angle_sp.roll) &&
                  std::isfinite(c.angle_sp.pitch);
    for (float m : out.motor) finite = finite && std::isfinite(m);
    if (!finite) supervisor_.fault(Reason::NonFinite);
    if (finite && supervisor_.armed()) {
        for (int i = 0; i < kMaxRotors; ++i) status_.state.motor[i] = out.motor[i];
        motors_.set(status_.state.motor, status_.state.rotor_count);
        return;
    }
    for (float& m : status_.state.motor) m = 0.0f;
    status_.state.excitation = 0.0f;         // nothing reached the vehicle
    motors_.disarm();
    cascade_.reset();                 // nothing integrates while the motors are off
}

}  // namespace hq
