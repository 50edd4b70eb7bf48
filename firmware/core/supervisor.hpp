// The controller's state and its safety rules, with no I/O (docs/safety.md lists every rule
// with its bound and the test that proves it).
//
// Three independent facts, each with one owner here:
//   - armed (and what armed it: the RC switch or a command): whether the motors may spin;
//   - the flight mode, angle or rate (types.hpp): which loops run;
//   - the excitation, idle, fading or running (excitation.hpp).
// The rules that change them:
//   - Arming needs a live RC link, the arm switch (channel 5) high, a throttle signal that is
//     low, and a fresh IMU sample; the switch arms on its low-to-high edge, a command arms
//     with the switch already high. The switch not high always disarms, whatever armed.
//   - The host is a ground station: only a HEARTBEAT of MAV_TYPE_GCS from another system
//     counts (another vehicle's does not), and only from system gcs_sysid when that is set
//     (MAV_GCS_SYSID, 0: any ground station). The loop passes every heartbeat to
//     heartbeat(); the rules are here.
//   - Failsafes, each: motors off, disarmed, an event. RC lost (no valid frame within
//     rc_timeout_us); host lost (armed by command and no host HEARTBEAT within
//     host_timeout_us); IMU stale (no fresh sample within imu_timeout_us); a non-finite
//     value in the loop (reported by the loop with fault()).
//   - An excitation starts only when armed, with a live host, in bounds (amplitude per
//     injection point, frequency band, duration, fade-in), and always with its fade-in. It
//     belongs to the ground station (system and component) that commanded it, whose own
//     heartbeat must be fresh to start it and keeps it alive: another station's does not.
//     It stops at once on disarm, when its station goes quiet, or when its axis's angle or
//     rate passes the abort limits (the same limits the host tool checks as a second line).
//   - An excitation of the on-board program (program.hpp) belongs to no station: the held
//     program switch (channel 7, watched by the program) keeps it alive instead of a
//     heartbeat; every other rule is the same.
//   - The flight mode does not change while an excitation runs: SET_MODE is refused, and an
//     RC mode switch change takes effect when the excitation ends.
//   - A stale IMU is probed and re-initialised while disarmed (imu_recovery_due()).
//
// The loop (FlightController) feeds it commands and one SupervisorInputs per loop, and does
// what it decides; pytest drives it directly through the bindings.
#pragma once

#include <cstdint>

#include "../hal/rc_input.hpp"
#include "rc.hpp"
#include "excitation.hpp"
#include "types.hpp"

namespace hq {

// Why something was refused, stopped, disarmed or reported: HQ_REASON, whose descriptions
// say each in words (the dialect is the one definition of the values).
enum class Reason : uint8_t {
    None = HQ_REASON_NONE,
    Finished = HQ_REASON_FINISHED,
    StopCommand = HQ_REASON_STOP_COMMAND,
    Disarmed = HQ_REASON_DISARMED,
    NoHost = HQ_REASON_NO_HOST,
    Busy = HQ_REASON_BUSY,
    AxisInjection = HQ_REASON_AXIS_INJECTION,
    InjectionMode = HQ_REASON_INJECTION_MODE,
    Amplitude = HQ_REASON_AMPLITUDE,
    Frequency = HQ_REASON_FREQUENCY,
    Cycles = HQ_REASON_CYCLES,
    Fade = HQ_REASON_FADE,
    Duration = HQ_REASON_DURATION,
    AngleLimit = HQ_REASON_ANGLE_LIMIT,
    RateLimit = HQ_REASON_RATE_LIMIT,
    RcLost = HQ_REASON_RC_LOST,
    HostLost = HQ_REASON_HOST_LOST,
    ImuStale = HQ_REASON_IMU_STALE,
    NonFinite = HQ_REASON_NON_FINITE,
    RcSwitch = HQ_REASON_RC_SWITCH,
    DisarmCommand = HQ_REASON_DISARM_COMMAND,
    NoRc = HQ_REASON_NO_RC,
    ArmSwitchLow = HQ_REASON_ARM_SWITCH_LOW,
    NoThrottle = HQ_REASON_NO_THROTTLE,
    ThrottleHigh = HQ_REASON_THROTTLE_HIGH,
    ImuNotReady = HQ_REASON_IMU_NOT_READY,
    ModeLocked = HQ_REASON_MODE_LOCKED,
    ImuReset = HQ_REASON_IMU_RESET,
    ImuNoAnswer = HQ_REASON_IMU_NO_ANSWER,
    ImuStalled = HQ_REASON_IMU_STALLED,
    ImuRecovered = HQ_REASON_IMU_RECOVERED,
    ImuInitFailed = HQ_REASON_IMU_INIT_FAILED,
    BadMode = HQ_REASON_BAD_MODE,
    BadAction = HQ_REASON_BAD_ACTION,
    Harmonics = HQ_REASON_HARMONICS,
    Peak = HQ_REASON_PEAK,
    Armed = HQ_REASON_ARMED,
    ProgramRunning = HQ_REASON_PROGRAM_RUNNING,
    ProgramSwitch = HQ_REASON_PROGRAM_SWITCH,
    ProgramOrder = HQ_REASON_PROGRAM_ORDER,
    Geometry = HQ_REASON_GEOMETRY,
    NoProgram = HQ_REASON_NO_PROGRAM,
};
constexpr uint8_t kReasonCount = HQ_REASON_ENUM_END;

// The reason in words, for STATUSTEXT: at most 49 characters, never null.
const char* reason_text(Reason reason);

// The MAV_SEVERITY values the firmware uses.
enum class Severity : uint8_t {
    Critical = MAV_SEVERITY_CRITICAL,
    Warning = MAV_SEVERITY_WARNING,
    Notice = MAV_SEVERITY_NOTICE,
    Info = MAV_SEVERITY_INFO,
};

struct Event {
    Reason reason = Reason::None;
    Severity severity = Severity::Info;
};

enum class ArmSource : uint8_t { None = 0, RcSwitch = 1, Command = 2 };

// Every bound a rule uses, with its reason. Defaults are the flight values.
struct SafetyLimits {
    // A receiver that lost its transmitter holds its last pulses or stops; half a second
    // without a valid frame is about 25 lost frames of a 50 Hz PWM receiver.
    uint32_t rc_timeout_us = 500000;
    // The host sends HEARTBEAT at 1 Hz or faster; 1.5 s tolerates one late heartbeat.
    uint32_t host_timeout_us = 1500000;
    // No fresh IMU sample for this long: the rate loop is flying blind. Set from the IMU's
    // rate with imu_timeout_for(); 25 ms is five samples at 200 Hz.
    uint32_t imu_timeout_us = 25000;
    // How often a stale IMU is probed and re-initialised while disarmed (the DMP set-up
    // blocks the loop for about 0.3 s on the board).
    uint32_t imu_retry_us = 1000000;
    // Abort limits of an excitation (80 deg, 400 deg/s): the rigs' safe swing and the
    // gyro's comfortable range (it saturates at 2000 deg/s).
    float abort_angle_rad = 1.3962634f;
    float abort_rate_rad_s = 6.9813170f;
    // Largest amplitude per injection point (Injection order: angle, rate, mixer):
    // 45 deg of angle setpoint, with margin to the 80 deg abort limit for overshoot;
    // 200 deg/s of rate setpoint, half the abort rate (a resonant response may double it);
    // 1.0 of normalised torque, the axis's whole authority (beyond it the mixer clips).
    float max_amplitude[kInjectionBounds] = {0.78539816f, 3.4906585f, 1.0f, 0.2f};
    // Lowest frequency: a 20 s period, a third of the lowest band edge identified (yaw,
    // 0.15 Hz). Highest: a quarter of the loop rate (at least four samples per period).
    float min_freq_hz = 0.05f;
    float max_freq_fraction = 0.25f;
    // Longest excitation, fades included: 5 minutes, about a flight battery on the rig.
    float max_duration_s = 300.0f;
    // Every excitation fades in (and out) over at least this many cycles.
    uint16_t min_fade_cycles = 1;
    // The arm and mode switches' positions and the throttle that is low enough to arm.
    RcThresholds rc{};
    // The one ground station's system id that counts as the host (MAV_GCS_SYSID, as
    // ArduPilot names it); 0: any ground station.
    uint8_t gcs_sysid = 0;
};

// A ground station on the link: (system id << 8) | component id. kAnyStation is the
// identity of a caller that does not say who it is (the bindings' default): system 0 is
// the broadcast address, never a sender.
using StationId = uint16_t;
constexpr StationId kAnyStation = 0;
constexpr StationId station_id(uint8_t sysid, uint8_t compid) {
    return static_cast<StationId>(sysid << 8 | compid);
}
// Whether a HEARTBEAT is a ground station's: MAV_TYPE_GCS, from a real system (not 0). The
// Supervisor's host and the link's boot report (link/gcs_link.hpp) both go by it.
constexpr bool is_ground_station(uint8_t sysid, uint8_t mav_type) {
    return mav_type == MAV_TYPE_GCS && sysid != 0;
}

// The IMU timeout for a sensor delivering rate_hz samples: five samples, at most 50 ms.
uint32_t imu_timeout_for(float rate_hz);

// One loop's facts.
struct SupervisorInputs {
    uint64_t now_us = 0;
    RcInput rc{};
    bool imu_sample = false;   // a fresh IMU sample arrived in this loop
    Euler attitude{};          // measured, rad
    Vec3 rate{};               // measured, rad/s
    // Where an Injection::Motors excitation puts each rotor's part (kMaxRotors values; the
    // rotor count's are written, the rest left): nullptr, the sum only.
    float* rotor_excitation = nullptr;
};

struct SupervisorCounters {
    uint32_t rc_failsafes = 0;
    uint32_t host_failsafes = 0;
    uint32_t imu_stale = 0;
    uint32_t imu_resets = 0;
    uint32_t imu_reinits = 0;
    uint32_t non_finite = 0;
    uint32_t arm_refused = 0;
    uint32_t exc_refused = 0;
    uint32_t exc_stopped = 0;   // by the firmware itself: limits, host lost, disarm
    uint32_t events_dropped = 0;
};

class Supervisor {
public:
    static constexpr int kEventQueue = 8;   // events waiting for the link (next_event)

    Supervisor(const SafetyLimits& limits, float loop_rate_hz);

    // --- commands (the telemetry link); each answer is Reason::None when accepted ----------
    // A HEARTBEAT from another system: counts as the host's when it is a ground station's
    // (mav_type MAV_TYPE_GCS) and, with gcs_sysid set, from that system. True if it counted.
    bool heartbeat(uint8_t sysid, uint8_t compid, uint8_t mav_type, uint64_t now_us);
    // A ground station's sign of life (heartbeat() once it decided it counts).
    void host_heartbeat(uint64_t now_us, StationId who = kAnyStation);
    // Arms when `who` is a ground station whose own heartbeat is fresh (NoHost otherwise)
    // and the checks pass. A command is no sign of life: only a HEARTBEAT keeps a station.
    Reason arm_command(const RcInput& rc, uint64_t now_us, StationId who = kAnyStation);
    void disarm_command();
    Reason set_mode(uint32_t custom_mode);
    // The excitation belongs to `who`: its heartbeat keeps it alive.
    Reason start_excitation(const ExcitationConfig& config, uint64_t now_us,
                            StationId who = kAnyStation);
    // An on-board program's step (program.hpp): the same checks as start_excitation() but
    // no station's heartbeat; the held program switch keeps it alive (end_program_step()).
    Reason start_program_step(const ExcitationConfig& config, uint64_t now_us);
    // Ends a running program step with `why` (announced, reported as an excitation end).
    void end_program_step(Reason why);
    bool program_owns_excitation() const { return excitation_.active() && exc_by_program_; }
    // The checks of a request's own numbers, whatever the state (armed, host, mode): axis and
    // injection, amplitude, band, harmonics, cycles, fade and duration within the limits.
    Reason check_excitation_bounds(const ExcitationConfig& config) const;
    // A chirp's sweep and fades against the duration cap (check_excitation_bounds' last).
    Reason check_chirp_duration(const ExcitationConfig& config) const;
    // Counts and announces a refused excitation request (for a refusal decided outside the
    // Supervisor's checks, such as an unknown HQ_EXCITATION action).
    void refuse_excitation(Reason why);
    // Stops a running excitation (StopCommand); false if none was running.
    bool stop_excitation();
    // Ends a running excitation in order (Excitation::finish; it ends as Finished); false if
    // none was running.
    bool finish_excitation() { return excitation_.finish(); }

    // --- once per loop, before the control laws -----------------------------------------------
    // Applies the RC switches, the failsafes and the excitation's limits; returns the
    // excitation's value for this loop (0 when idle).
    float update(const SupervisorInputs& in);
    // A fault the loop found itself (a non-finite value): motors off, disarmed.
    void fault(Reason why);

    // --- IMU recovery ---------------------------------------------------------------------
    // The chip was initialised at now_us (the boot init): the first retry waits from here.
    // timeout_us replaces limits().imu_timeout_us (imu_timeout_for() of the chip's rate).
    void imu_initialised(uint64_t now_us, uint32_t timeout_us);
    // True when the loop should probe the chip and re-initialise it: disarmed, no fresh
    // sample, and imu_retry_us since the last attempt.
    bool imu_recovery_due(uint64_t now_us) const;
    // What the probe found (ImuReset, ImuStalled or ImuNoAnswer) and whether the
    // re-initialisation that followed worked (false when none was tried).
    void imu_recovery_result(Reason found, bool reinitialised, uint64_t now_us);

    // --- state ----------------------------------------------------------------------------
    bool armed() const { return armed_; }
    ArmSource arm_source() const { return arm_source_; }
    FlightMode mode() const { return mode_; }
    // State of this loop's excitation sample (set by update()).
    ExcitationState excitation_state() const { return exc_state_; }
    const Excitation& excitation() const { return excitation_; }
    const ExcitationConfig& excitation_config() const { return excitation_.config(); }
    bool imu_fresh(uint64_t now_us) const;
    // What an arm command from a live ground station would be answered now (Reason::None:
    // it would arm; NoHost when no ground station is alive).
    Reason arm_check(const RcInput& rc, uint64_t now_us) const;
    bool imu_stale() const { return imu_stale_; }
    uint64_t last_host_heartbeat_us() const;
    // The station the running (or last) excitation belongs to.
    StationId excitation_owner() const { return exc_owner_; }
    Reason last_reason() const { return last_reason_; }
    const SupervisorCounters& counters() const { return counters_; }
    const SafetyLimits& limits() const { return limits_; }
    // New bounds (the parameters changed); the IMU timeout stays the one the chip's rate set.
    // A station a new gcs_sysid excludes is forgotten.
    void set_limits(const SafetyLimits& limits);
    // Whether the geometry parameters gave an allocation (arming is refused while not), and
    // its rotor count (a motor injection names one of them).
    void set_geometry(bool ok, int rotors) {
        geometry_ok_ = ok;
        rotors_ = rotors;
    }

    // --- what the loop reports -------------------------------------------------------------
    // The oldest event not yet taken (STATUSTEXT); false when there is none.
    bool next_event(Event& out);
    // True once after an excitation ended by itself or was stopped by a rule (not by a stop
    // command, which is answered directly), with why (HQ_EXCITATION_STATUS).
    bool take_excitation_end(Reason& why);

private:
    Reason check_arm(const RcInput& rc, uint64_t now_us) const;
    void arm(ArmSource source);
    void disarm(Reason why);
    void refuse_arm(Reason why);
    void apply_rc(const RcInput& rc, uint64_t now_us);
    void apply_mode_switch(const RcInput& rc);
    void check_host(uint64_t now_us);
    void check_imu(const SupervisorInputs& in);
    float run_excitation(const SupervisorInputs& in);
    Reason excitation_limit(const SupervisorInputs& in) const;
    Reason check_excitation(const ExcitationConfig& config, uint64_t now_us,
                            StationId who, bool program) const;
    Reason begin_excitation(const ExcitationConfig& config, uint64_t now_us, StationId who,
                            bool program);
    void end_excitation(Reason why, bool announce = true);
    bool host_alive(uint64_t now_us) const;
    bool station_alive(StationId who, uint64_t now_us) const;
    bool station_allowed(StationId who) const;
    int station_slot(StationId who) const;
    int free_slot() const;
    void emit(Reason reason, Severity severity);

    enum class SwitchPos : uint8_t { Unknown, Low, High };

    SafetyLimits limits_;
    float loop_rate_hz_;
    Excitation excitation_;
    bool armed_ = false;
    ArmSource arm_source_ = ArmSource::None;
    FlightMode mode_ = FlightMode::Angle;
    ExcitationState exc_state_ = ExcitationState::Idle;
    SwitchPos arm_switch_ = SwitchPos::Unknown;
    bool mode_switch_known_ = false, mode_switch_pending_ = false, mode_lock_reported_ = false;
    FlightMode mode_switch_ = FlightMode::Angle;
    // The ground stations heard from, most recent heartbeat each (a new one takes the slot
    // heard from longest ago, never the running excitation's owner's): enough for a GCS, a
    // companion and a spare.
    static constexpr int kStations = 4;
    struct Station {
        bool seen = false;
        StationId id = 0;
        uint64_t last_us = 0;
    };
    Station stations_[kStations];
    StationId exc_owner_ = kAnyStation;
    bool exc_by_program_ = false;            // the running excitation is a program's step
    bool imu_seen_ = false, imu_stale_ = false;
    uint64_t last_imu_us_ = 0, last_imu_attempt_us_ = 0;
    Reason last_imu_finding_ = Reason::None;
    Reason last_reason_ = Reason::None;
    bool geometry_ok_ = true;
    int rotors_ = 5;
    bool exc_end_pending_ = false;
    Reason exc_end_reason_ = Reason::None;
    SupervisorCounters counters_{};
    Event events_[kEventQueue];
    int event_head_ = 0, event_count_ = 0;
};

}  // namespace hq
