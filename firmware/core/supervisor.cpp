#include "supervisor.hpp"

#include <cmath>

#include "rc.hpp"

namespace hq {

namespace {

// The IMU is stale after this many missing samples...
constexpr float kImuTimeoutSamples = 5.0f;
// ...but never later than this: at 50 ms a rate loop with the paper's gains has lost its
// phase margin to the missing feedback.
constexpr uint32_t kImuTimeoutMaxUs = 50000;

}  // namespace

const char* reason_text(Reason reason) {
    // A switch, not a table of pointers: no relocations (the core has no .data), and the
    // compiler checks that every reason has its text.
    switch (reason) {
        case Reason::None: return "ok";
        case Reason::Finished: return "excitation finished";
        case Reason::StopCommand: return "excitation stopped by command";
        case Reason::Disarmed: return "excitation refused: disarmed";
        case Reason::NoHost: return "refused: no heartbeat from this ground station";
        case Reason::Busy: return "excitation refused: one is already running";
        case Reason::AxisInjection: return "excitation refused: bad axis or injection";
        case Reason::InjectionMode: return "excitation refused: needs angle mode";
        case Reason::Amplitude: return "excitation refused: amplitude out of bounds";
        case Reason::Frequency: return "excitation refused: frequency out of band";
        case Reason::Cycles: return "excitation refused: no measured cycles";
        case Reason::Fade: return "excitation refused: fade-in too short";
        case Reason::Duration: return "excitation refused: longer than the cap";
        case Reason::AngleLimit: return "excitation stopped: angle limit";
        case Reason::RateLimit: return "excitation stopped: rate limit";
        case Reason::RcLost: return "failsafe: RC lost, motors off";
        case Reason::HostLost: return "host heartbeat lost";
        case Reason::ImuStale: return "failsafe: IMU stale, motors off";
        case Reason::NonFinite: return "failsafe: non-finite value, motors off";
        case Reason::RcSwitch: return "disarmed by RC switch";
        case Reason::DisarmCommand: return "disarmed by command";
        case Reason::NoRc: return "arming refused: no RC link";
        case Reason::ArmSwitchLow: return "arming refused: arm switch low";
        case Reason::NoThrottle: return "arming refused: no throttle signal";
        case Reason::ThrottleHigh: return "arming refused: throttle not low";
        case Reason::ImuNotReady: return "arming refused: IMU not ready";
        case Reason::ModeLocked: return "mode change refused: excitation running";
        case Reason::ImuReset: return "IMU lost its configuration; re-initialising";
        case Reason::ImuNoAnswer: return "IMU does not answer";
        case Reason::ImuStalled: return "IMU delivers no samples; re-initialising";
        case Reason::ImuRecovered: return "IMU recovered";
        case Reason::ImuInitFailed: return "IMU re-initialisation failed";
        case Reason::BadMode: return "mode refused: unknown mode";
        case Reason::BadAction: return "excitation refused: unknown action";
        case Reason::Harmonics: return "excitation refused: bad signal or harmonics";
        case Reason::Peak: return "excitation stopped: signal passed its peak";
        case Reason::Armed: return "refused: armed (disarm first)";
        case Reason::ProgramRunning: return "refused: the on-board program runs";
        case Reason::ProgramSwitch: return "program stopped: channel 7 released";
        case Reason::ProgramOrder: return "program refused: steps out of order";
        case Reason::NoProgram: return "program refused: none stored";
        case Reason::Geometry: return "arming refused: vehicle geometry refused";
    }
    return "unknown reason";
}

uint32_t imu_timeout_for(float rate_hz) {
    if (!(rate_hz > 0.0f)) return kImuTimeoutMaxUs;
    const float us = kImuTimeoutSamples * 1e6f / rate_hz;
    return us >= static_cast<float>(kImuTimeoutMaxUs) ? kImuTimeoutMaxUs
                                                       : static_cast<uint32_t>(us);
}

Supervisor::Supervisor(const SafetyLimits& limits, float loop_rate_hz)
    : limits_(limits), loop_rate_hz_(loop_rate_hz) {}

// --- events ---------------------------------------------------------------------------------

void Supervisor::emit(Reason reason, Severity severity) {
    if (severity <= Severity::Warning) last_reason_ = reason;
    if (event_count_ == kEventQueue) {          // full: the oldest is lost, and counted
        event_head_ = (event_head_ + 1) % kEventQueue;
        --event_count_;
        ++counters_.events_dropped;
    }
    events_[(event_head_ + event_count_) % kEventQueue] = Event{reason, severity};
    ++event_count_;
}

bool Supervisor::next_event(Event& out) {
    if (event_count_ == 0) return false;
    out = events_[event_head_];
    event_head_ = (event_head_ + 1) % kEventQueue;
    --event_count_;
    return true;
}

bool Supervisor::take_excitation_end(Reason& why) {
    if (!exc_end_pending_) return false;
    exc_end_pending_ = false;
    why = exc_end_reason_;
    return true;
}

// --- arming ---------------------------------------------------------------------------------

int Supervisor::station_slot(StationId who) const {
    for (int i = 0; i < kStations; ++i) {
        if (stations_[i].seen && stations_[i].id == who) return i;
    }
    return -1;
}

bool Supervisor::station_allowed(StationId who) const {
    return limits_.gcs_sysid == 0 || (who >> 8) == limits_.gcs_sysid;
}

bool Supervisor::station_alive(StationId who, uint64_t now_us) const {
    const int i = station_slot(who);
    return i >= 0 && station_allowed(who) && now_us - stations_[i].last_us <= limits_.host_timeout_us;
}

bool Supervisor::host_alive(uint64_t now_us) const {
    for (const Station& s : stations_) {
        if (s.seen && station_alive(s.id, now_us)) return true;
    }
    return false;
}

uint64_t Supervisor::last_host_heartbeat_us() const {
    uint64_t last = 0;
    for (const Station& s : stations_) last = s.seen && s.last_us > last ? s.last_us : last;
    return last;
}

bool Supervisor::imu_fresh(uint64_t now_us) const {
    return imu_seen_ && now_us - last_imu_us_ <= limits_.imu_timeout_us;
}

bool Supervisor::heartbeat(uint8_t sysid, uint8_t compid, uint8_t mav_type, uint64_t now_us) {
    if (!is_ground_station(sysid, mav_type)) return false;     // a vehicle, a camera ...
    if (limits_.gcs_sysid != 0 && sysid != limits_.gcs_sysid) return false;
    host_heartbeat(now_us, station_id(sysid, compid));
    return true;
}

void Supervisor::host_heartbeat(uint64_t now_us, StationId who) {
    if (!station_allowed(who)) return;       // MAV_GCS_SYSID excludes it
    int slot = station_slot(who);
    if (slot < 0) slot = free_slot();
    stations_[slot] = Station{true, who, now_us};
}

int Supervisor::free_slot() const {
    // A new station takes a free slot, else the one heard from longest ago, but never the
    // slot of the station whose excitation runs: a fifth station does not stop it.
    const bool owned = excitation_.active();
    int slot = -1;
    for (int i = 0; i < kStations; ++i) {
        if (!stations_[i].seen) return i;
        if (owned && stations_[i].id == exc_owner_) continue;
        if (slot < 0 || stations_[i].last_us < stations_[slot].last_us) slot = i;
    }
    return slot;                             // kStations > 1: one slot is never the owner's
}

Reason Supervisor::check_arm(const RcInput& rc, uint64_t now_us) const {
    if (rc.age_us > limits_.rc_timeout_us) return Reason::NoRc;
    if (!switch_high(rc, rc::kArm, limits_.rc)) return Reason::ArmSwitchLow;
    if (!has_signal(rc, rc::kThrottle)) return Reason::NoThrottle;
    if (rc.channel_us[rc::kThrottle] >= limits_.rc.throttle_low_us) return Reason::ThrottleHigh;
    if (!imu_fresh(now_us)) return Reason::ImuNotReady;
    if (!geometry_ok_) return Reason::Geometry;
    return Reason::None;
}

Reason Supervisor::arm_check(const RcInput& rc, uint64_t now_us) const {
    return host_alive(now_us) ? check_arm(rc, now_us) : Reason::NoHost;
}

void Supervisor::arm(ArmSource source) {
    armed_ = true;
    arm_source_ = source;
}

void Supervisor::refuse_arm(Reason why) {
    ++counters_.arm_refused;
    emit(why, Severity::Warning);
}

void Supervisor::disarm(Reason why) {
    if (!armed_) return;
    armed_ = false;
    arm_source_ = ArmSource::None;
    const bool failsafe = why == Reason::RcLost || why == Reason::HostLost ||
                          why == Reason::ImuStale || why == Reason::NonFinite;
    emit(why, failsafe ? Severity::Critical : Severity::Notice);
    // The excitation ends with the disarm's own reason, already announced.
    if (excitation_.active()) end_excitation(why, false);
}

Reason Supervisor::arm_command(const RcInput& rc, uint64_t now_us, StationId who) {
    // Only a ground station whose own HEARTBEAT is fresh (and that MAV_GCS_SYSID allows)
    // may arm: the host-lost failsafe then watches it. A command is no heartbeat: it keeps
    // no station alive.
    const bool host = station_alive(who, now_us);
    if (armed_ && host) return Reason::None;
    const Reason r = host ? check_arm(rc, now_us) : Reason::NoHost;
    if (r != Reason::None) {
        refuse_arm(r);
        return r;
    }
    arm(ArmSource::Command);
    return Reason::None;
}

void Supervisor::disarm_command() { disarm(Reason::DisarmCommand); }

void Supervisor::fault(Reason why) {
    if (why == Reason::NonFinite) ++counters_.non_finite;
    // Disarmed, the motors are already off: counted, not announced every loop it persists.
    disarm(why);
}

// --- modes ----------------------------------------------------------------------------------

Reason Supervisor::set_mode(uint32_t custom_mode) {
    Reason r = Reason::None;
    if (custom_mode != static_cast<uint32_t>(FlightMode::Angle) &&
        custom_mode != static_cast<uint32_t>(FlightMode::Rate)) {
        r = Reason::BadMode;
    } else if (excitation_.active()) {
        r = Reason::ModeLocked;
    }
    if (r != Reason::None) {
        emit(r, Severity::Warning);
        return r;
    }
    mode_ = static_cast<FlightMode>(custom_mode);
    return Reason::None;
}

void Supervisor::apply_mode_switch(const RcInput& rc) {
    // The switch acts when it moves (and when it first shows a position), so SET_MODE is not
    // overridden by a switch that stays put; a move during an excitation waits for its end.
    if (has_signal(rc, rc::kMode)) {
        const FlightMode pos = switch_high(rc, rc::kMode, limits_.rc) ? FlightMode::Rate : FlightMode::Angle;
        if (!mode_switch_known_ || pos != mode_switch_) {
            mode_switch_known_ = true;
            mode_switch_ = pos;
            mode_switch_pending_ = true;
        }
    }
    if (!mode_switch_pending_) return;
    if (!excitation_.active()) {
        mode_ = mode_switch_;
        mode_switch_pending_ = false;
        mode_lock_reported_ = false;
    } else if (!mode_lock_reported_ && mode_switch_ != mode_) {
        mode_lock_reported_ = true;
        emit(Reason::ModeLocked, Severity::Warning);
    }
}

// --- the loop -------------------------------------------------------------------------------

void Supervisor::apply_rc(const RcInput& rc, uint64_t now_us) {
    if (rc.age_us > limits_.rc_timeout_us) {
        // The arm switch's position is forgotten: when the link comes back, only a new
        // low-to-high move arms, never a switch that was moved (or left high) meanwhile.
        arm_switch_ = SwitchPos::Unknown;
        if (armed_) {
            ++counters_.rc_failsafes;
            disarm(Reason::RcLost);
        }
        return;
    }
    const bool high = switch_high(rc, rc::kArm, limits_.rc);
    if (armed_ && !high) {
        disarm(Reason::RcSwitch);
    } else if (!armed_ && high && arm_switch_ == SwitchPos::Low) {
        // Only a low-to-high edge the pilot made arms: a switch found high at boot does not,
        // nor one whose pulse dropped out (no signal, or mid-travel, is not "low").
        const Reason r = check_arm(rc, now_us);
        if (r == Reason::None) arm(ArmSource::RcSwitch);
        else refuse_arm(r);
    }
    arm_switch_ = high ? SwitchPos::High
                : switch_low(rc, rc::kArm, limits_.rc) ? SwitchPos::Low : SwitchPos::Unknown;
    apply_mode_switch(rc);
}

void Supervisor::check_host(uint64_t now_us) {
    if (armed_ && arm_source_ == ArmSource::Command && !host_alive(now_us)) {
        ++counters_.host_failsafes;
        disarm(Reason::HostLost);
    }
}

void Supervisor::check_imu(const SupervisorInputs& in) {
    if (in.imu_sample) {
        last_imu_us_ = in.now_us;
        imu_seen_ = true;
        if (imu_stale_) {
            imu_stale_ = false;
            last_imu_finding_ = Reason::None;
            emit(Reason::ImuRecovered, Severity::Info);
        }
        return;
    }
    if (imu_seen_ && !imu_stale_ && !imu_fresh(in.now_us)) {
        imu_stale_ = true;
        ++counters_.imu_stale;
        if (armed_) disarm(Reason::ImuStale);
    }
}

float Supervisor::update(const SupervisorInputs& in) {
    check_imu(in);
    apply_rc(in.rc, in.now_us);
    check_host(in.now_us);
    return run_excitation(in);
}

// --- the excitation -------------------------------------------------------------------------

Reason Supervisor::check_excitation(const ExcitationConfig& c, uint64_t now_us,
                                    StationId who, bool program) const {
    if (!armed_) return Reason::Disarmed;
    if (!program && !station_alive(who, now_us)) return Reason::NoHost;     // its own heartbeat
    if (excitation_.active()) return Reason::Busy;
    // A bad axis or injection first, then the mode, then the numbers (as they always were).
    const Reason bounds = check_excitation_bounds(c);
    if (bounds == Reason::AxisInjection) return bounds;
    if (c.injection == Injection::Angle && mode_ != FlightMode::Angle) {
        return Reason::InjectionMode;
    }
    return bounds;
}

Reason Supervisor::check_excitation_bounds(const ExcitationConfig& c) const {
    const auto axis = static_cast<uint8_t>(c.axis);
    const auto injection = static_cast<uint8_t>(c.injection);
    const int rotor = injected_rotor(c.injection);
    if (axis >= kAxes || injection >= kInjections ||
        (c.axis == Axis::Yaw && c.injection == Injection::Angle) || rotor >= rotors_) {
        return Reason::AxisInjection;
    }
    // Every rotor its own lines: a multisine with at least one harmonic per rotor.
    if (rotor == kAllRotors && !(c.signal == Signal::Multisine && c.harmonics >= rotors_)) {
        return Reason::Harmonics;
    }
    if (!(std::isfinite(c.amplitude) && c.amplitude > 0.0f &&
          c.amplitude <= limits_.max_amplitude[amplitude_bound(c.injection)])) {
        return Reason::Amplitude;
    }
    if (!(std::isfinite(c.freq_hz) && c.freq_hz > 0.0f)) return Reason::Frequency;
    // The period actually used is an integer number of loops (excitation.hpp).
    const float period = std::round(loop_rate_hz_ / c.freq_hz);
    if (!(period >= 1.0f && period <= static_cast<float>(Excitation::kMaxPeriodSamples))) {
        return Reason::Frequency;
    }
    if (!harmonics_valid(c, static_cast<uint32_t>(period))) return Reason::Harmonics;
    if (is_chirp(c.signal) &&
        !(std::isfinite(c.freq_stop_hz) && c.freq_stop_hz > 0.0f && c.freq_stop_hz != c.freq_hz)) {
        return Reason::Frequency;
    }
    // Every excited frequency (a sine's one; a multisine's lowest and highest harmonic; a
    // chirp's two ends) is inside the band.
    if (!(lowest_freq_hz(c) >= limits_.min_freq_hz &&
          highest_freq_hz(c) <= limits_.max_freq_fraction * loop_rate_hz_)) {
        return Reason::Frequency;
    }
    if (c.cycles == 0 || (is_chirp(c.signal) && c.cycles != 1)) return Reason::Cycles;
    if (c.fade_cycles < limits_.min_fade_cycles) return Reason::Fade;
    if (is_chirp(c.signal)) return check_chirp_duration(c);
    const float fade = static_cast<float>(fade_samples_for(c, static_cast<uint32_t>(period)));
    const float period_s = period / loop_rate_hz_;
    const float cycles = static_cast<float>(c.cycles) + 2.0f * fade / period;
    if (!(cycles * period_s <= limits_.max_duration_s)) return Reason::Duration;
    return Reason::None;
}

// A chirp's length: its sweep (finite, positive, a whole number of samples at least) and
// its two fades, of whole cycles of its lower end, within the duration cap.
Reason Supervisor::check_chirp_duration(const ExcitationConfig& c) const {
    const uint64_t sweep = sweep_samples_for(c, loop_rate_hz_);
    if (!(std::isfinite(c.sweep_s) && c.sweep_s > 0.0f) || sweep == 0) return Reason::Duration;
    // The generator's own sample counts (excitation.cpp), compared whole in double.
    const uint64_t total = sweep + 2u * chirp_fade_samples_for(c, loop_rate_hz_);
    if (!(static_cast<double>(total) <=
          static_cast<double>(limits_.max_duration_s) * static_cast<double>(loop_rate_hz_))) {
        return Reason::Duration;
    }
    return Reason::None;
}

Reason Supervisor::start_excitation(const ExcitationConfig& config, uint64_t now_us,
                                    StationId who) {
    return begin_excitation(config, now_us, who, false);
}

Reason Supervisor::start_program_step(const ExcitationConfig& config, uint64_t now_us) {
    return begin_excitation(config, now_us, kAnyStation, true);
}

Reason Supervisor::begin_excitation(const ExcitationConfig& config, uint64_t now_us,
                                    StationId who, bool program) {
    Reason r = check_excitation(config, now_us, who, program);
    if (r == Reason::None && !excitation_.start(config, loop_rate_hz_)) r = Reason::Frequency;
    if (r == Reason::None) {
        exc_owner_ = who;
        exc_by_program_ = program;
    }
    if (r != Reason::None) refuse_excitation(r);
    return r;
}

void Supervisor::end_program_step(Reason why) {
    if (program_owns_excitation()) end_excitation(why);
}

void Supervisor::refuse_excitation(Reason why) {
    ++counters_.exc_refused;
    emit(why, Severity::Warning);
}

bool Supervisor::stop_excitation() {
    if (!excitation_.active()) return false;
    excitation_.stop();
    return true;
}

void Supervisor::end_excitation(Reason why, bool announce) {
    excitation_.stop();
    exc_end_pending_ = true;
    exc_end_reason_ = why;
    if (why != Reason::Finished) ++counters_.exc_stopped;
    if (announce) emit(why, why == Reason::Finished ? Severity::Info : Severity::Warning);
}

Reason Supervisor::excitation_limit(const SupervisorInputs& in) const {
    const ExcitationConfig& c = excitation_.config();
    const int a = static_cast<int>(c.axis);
    // A host's excitation lives by its owner's heartbeat; a program's by its switch.
    if (!exc_by_program_ && !station_alive(exc_owner_, in.now_us)) return Reason::HostLost;
    // The yaw rig's heading is free: only roll and pitch have an angle limit. A measurement
    // that is not a number is beyond every limit (the comparisons are written so).
    if (a < kAngleAxes && !(std::fabs(in.attitude[a]) <= limits_.abort_angle_rad)) {
        return Reason::AngleLimit;
    }
    if (!(std::fabs(in.rate[a]) <= limits_.abort_rate_rad_s)) return Reason::RateLimit;
    return Reason::None;
}

float Supervisor::run_excitation(const SupervisorInputs& in) {
    if (excitation_.active()) {
        const Reason stop = armed_ ? excitation_limit(in) : Reason::Disarmed;
        if (stop != Reason::None) end_excitation(stop);
    }
    exc_state_ = excitation_.state();
    if (!excitation_.active()) return 0.0f;
    const bool split = injected_rotor(excitation_.config().injection) == kAllRotors &&
                       in.rotor_excitation != nullptr;
    const float value = excitation_.next(in.rotor_excitation, split ? rotors_ : 0);
    if (!excitation_.active()) {
        end_excitation(excitation_.peak_exceeded() ? Reason::Peak : Reason::Finished);
    }
    return value;
}

// --- IMU recovery ---------------------------------------------------------------------------

void Supervisor::set_limits(const SafetyLimits& limits) {
    const uint32_t imu_timeout_us = limits_.imu_timeout_us;
    limits_ = limits;
    limits_.imu_timeout_us = imu_timeout_us;
    // A station MAV_GCS_SYSID now excludes is forgotten: it is no host any more.
    for (Station& s : stations_) {
        if (s.seen && !station_allowed(s.id)) s = Station{};
    }
}

void Supervisor::imu_initialised(uint64_t now_us, uint32_t timeout_us) {
    last_imu_attempt_us_ = now_us;
    limits_.imu_timeout_us = timeout_us;
}

bool Supervisor::imu_recovery_due(uint64_t now_us) const {
    // A clock that went backwards (against the HAL's contract) delays the retry, never
    // repeats it every loop.
    return !armed_ && !imu_fresh(now_us) && now_us >= last_imu_attempt_us_ &&
           now_us - last_imu_attempt_us_ >= limits_.imu_retry_us;
}

void Supervisor::imu_recovery_result(Reason found, bool reinitialised, uint64_t now_us) {
    last_imu_attempt_us_ = now_us;
    if (found == Reason::ImuReset) ++counters_.imu_resets;
    if (reinitialised) ++counters_.imu_reinits;
    // A chip that stays silent is probed every retry; say so once, not every second.
    if (found != last_imu_finding_) {
        emit(found, found == Reason::ImuNoAnswer ? Severity::Critical : Severity::Warning);
    }
    last_imu_finding_ = found;
    if (found != Reason::ImuNoAnswer && !reinitialised) emit(Reason::ImuInitFailed, Severity::Critical);
}

}  // namespace hq
