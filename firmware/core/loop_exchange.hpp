// What the loop (FlightController) and the ground-station link (link/gcs_link.hpp) exchange,
// as plain structs and nothing else: requests in (LoopInbox: what a ground station asked of
// the loop, in the order it arrived), each answered by the loop (LoopAnswer: accepted or
// refused, and why), and the loop's state out (LoopStatus: what it publishes every cycle,
// with the notices it raised for STATUSTEXT). Neither side calls the other.
#pragma once

#include <cstddef>
#include <cstdint>

#include "../hal/reset_cause.hpp"
#include "excitation.hpp"
#include "log/log_sink.hpp"
#include "mixer.hpp"
#include "mpu6050.hpp"
#include "params.hpp"
#include "program.hpp"
#include "rc.hpp"
#include "supervisor.hpp"
#include "types.hpp"

namespace hq {

enum class RequestKind : uint8_t {
    Heartbeat,          // another system's HEARTBEAT: the Supervisor decides if it counts
    Arm,
    Disarm,
    SetMode,            // `value` the custom mode (HQ_MODE)
    ExcitationStart,    // LoopInbox::excitation the request
    ExcitationStop,
    ExcitationFinish,
    ExcitationRefuse,   // an HQ_EXCITATION action the firmware does not know (BAD_ACTION)
    ParamSet,           // `param_index`, `param_value` (decoded; `param_type_ok` false: refused)
    Storage,            // `value` the MAV_CMD_PREFLIGHT_STORAGE parameter action
    Bootloader,         // the target asks to restart into its bootloader (never while armed)
    ProgramStep,        // LoopInbox::excitation the step; `value` its index, `param_index` the count
    ProgramClear,
    ProgramRead,        // `value` the step asked for
};

struct LoopRequest {             // the one-byte members together: 20 bytes, not 24
    RequestKind kind = RequestKind::Heartbeat;
    bool param_type_ok = false;            // ParamSet
    StationId who = kAnyStation;           // the station that asked
    uint8_t sysid = 0, compid = 0, mav_type = 0;   // Heartbeat
    uint32_t value = 0;
    int param_index = -1;
    float param_value = 0.0f;
};

enum class Verdict : uint8_t { Accepted, Refused, Failed };

// The excitation as a request or its end left it (HQ_EXCITATION_STATUS).
struct ExcitationReport {
    ExcitationState state = ExcitationState::Idle;
    Axis axis = Axis::Roll;
    Injection injection = Injection::Mixer;
    Signal signal = Signal::Sine;
    float actual_freq_hz = 0.0f;
    uint32_t period_samples = 0, total_samples = 0, fade_samples = 0;
};

struct LoopAnswer {
    Verdict verdict = Verdict::Accepted;
    Reason reason = Reason::None;
    SetResult set = SetResult::Ok;         // ParamSet
    uint8_t notices_end = 0;               // LoopStatus::notice[] up to here raised by now
    ExcitationReport excitation{};         // the Excitation* kinds
    ProgramReport program{};               // the Program* kinds
};

// One loop's requests, filled by the links before the step and answered in the step; whoever
// runs the loop clears it before the links fill it (one inbox serves every link of the
// board). At most one ExcitationStart a loop (its configuration is large); a second waits for
// the next.
struct LoopInbox {
    static constexpr int kCapacity = 24;
    LoopRequest request[kCapacity];
    LoopAnswer answer[kCapacity];
    uint8_t count = 0;
    bool has_excitation = false;
    ExcitationConfig excitation{};
    void clear() {
        count = 0;
        has_excitation = false;
    }
};

struct LoopState {               // what the last loop computed, for telemetry and tests
    Euler attitude{};
    Vec3 rate{};
    Euler angle_sp{};
    Vec3 rate_sp{};
    Vec3 torque{};               // normalised mixer torque commands, after injection
    float collective = 0.0f;
    float excitation = 0.0f;
    float motor[kMaxRotors] = {};  // thrust fractions, rotor order; 0 past rotor_count
    Vec3 accel{};                // m/s^2, the last IMU sample's
    float dt_s = 0.0f;
    uint8_t sensor_clipped = 0;  // HQ_SATURATION_GYRO / _ACCEL bits of the last IMU sample
    uint8_t saturation = 0;      // HQ_SATURATION bits of this loop (mixer and sensor)
    uint8_t rotor_count = kMotors;  // the rotors the loop flies: motor[0..rotor_count)
};

// Something the loop says in words (a STATUSTEXT): a Supervisor event, an IMU or a parameter
// store message. `text` is a constant string, or nullptr for a stored value refused (its words
// are set_result_text(param_result, param_index): what a set of that value would be told).
struct Notice {
    uint8_t severity = 0;                  // MAV_SEVERITY
    const char* text = nullptr;
    int param_index = -1;
    SetResult param_result = SetResult::Range;
};

// A notice's words into out (at most capacity bytes, zero-padded when shorter): its text, or
// the refusal of its parameter's stored value. The words of its STATUSTEXT and of its log MSG.
inline void notice_words(const Notice& n, char* out, size_t capacity) {
    if (n.text == nullptr) {
        set_result_text(n.param_result, n.param_index, out, capacity);
        return;
    }
    size_t i = 0;
    for (; i < capacity && n.text[i] != '\0'; ++i) out[i] = n.text[i];
    for (; i < capacity; ++i) out[i] = '\0';
}

// What start-up found (boot_report.hpp turns it into STATUSTEXTs): why the chip reset, where
// the parameters came from, and the IMU's path. Set once by init(); a later re-read of the
// store or re-initialisation of the IMU does not change it.
enum class ParamsFinding : uint8_t {
    NoStorage,     // no storage configured: the defaults
    Loaded,        // every stored value taken
    Empty,         // nothing stored: the defaults
    Corrupt,       // the store failed its checks: the defaults
    OutOfRange,    // loaded, but a stored value was refused (param_index: the first)
};
enum class ImuFinding : uint8_t {
    Dmp,           // found, on the DMP path
    RawByParam,    // found, on the raw path because IMU_PATH says so
    RawNoImage,    // found, on the raw path because the build has no DMP firmware
    RawFallback,   // found, on the raw path because the DMP set-up failed (dmp_step: where)
    Missing,       // not found (no answer, a wrong WHO_AM_I, a bus error)
};
struct BootReport {
    ResetCause reset = ResetCause::PowerOn;
    ParamsFinding params = ParamsFinding::NoStorage;
    int16_t param_index = -1;
    SetResult param_result = SetResult::Range;     // why param_index's value was refused
    ImuFinding imu = ImuFinding::Missing;
    DmpStep dmp_step = DmpStep::None;
    CardState card = CardState::NoCard;      // the SD card at start-up (set_card_state())
};

// The on-board log as HQ_FW_STATUS reports it: the card's state now and the logger's counts
// since boot (core/log/logger.hpp).
struct LogStatus {
    CardState card = CardState::NoCard;
    uint32_t records = 0;        // records queued in the RAM ring
    uint32_t dropped = 0;        // records dropped: the ring was full (a slow or busy card)
    uint32_t bytes = 0;          // bytes the card took
};

// What the loop publishes: after init(), and after every step.
struct LoopStatus {
    LoopState state{};
    uint32_t loop_index = 0;               // the step's number from 0 (HQ_FW_STATUS.loops)
    // The step's time, read as it starts (before the IMU read): the stamp of every message
    // about this loop on every link, however late a link sends it.
    uint64_t time_us = 0;
    bool armed = false;
    FlightMode mode = FlightMode::Angle;
    ExcitationState excitation_state = ExcitationState::Idle;   // this loop's sample
    Axis exc_axis = Axis::Roll;
    Injection exc_injection = Injection::Mixer;
    Reason last_reason = Reason::None;
    bool imu_stale = false;
    bool imu_ok = false;                   // found, initialised and not stale
    bool prearm_ok = false;                // an arm command would arm now (or armed)
    uint8_t sensor_kind = 0;               // HQ_SENSOR_KIND
    SupervisorCounters supervisor{};
    Mpu6050Counters imu{};
    uint32_t dt_clamped = 0;
    RcInput rc{};                          // this loop's RC input
    uint32_t rc_timeout_us = 0;
    Tunables params{};                     // the values the loop flies
    bool excitation_ended = false;         // this step: HQ_EXCITATION_STATUS with end_reason
    Reason end_reason = Reason::None;
    ExcitationReport excitation{};
    // The on-board program: the one stored (HQ_PROGRAM READ's answers), and whether this step
    // started or ended a step of it (HQ_PROGRAM_STATUS with program_report).
    const Program* program = nullptr;
    bool program_changed = false;
    ProgramReport program_report{};
    // A request's notices (LoopAnswer::notices_end), then up to notices_before_telemetry
    // the Supervisor's events, then the ones raised after the telemetry (the store's).
    static constexpr int kNotices = 2 * LoopInbox::kCapacity + Supervisor::kEventQueue + 4;
    Notice notice[kNotices];
    uint8_t notice_count = 0;
    uint8_t notices_before_telemetry = 0;
    BootReport boot{};                     // what start-up found (init())
    LogStatus log{};                       // the on-board log and its card
    // A Bootloader request was accepted (disarmed): the target enters its bootloader once
    // this loop's messages are out. Never set while armed.
    bool bootloader = false;
};

// HQ_SYSID_SAMPLE's values of the excitation's axis in a loop: the telemetry's sample and the
// log's HQSD (logger.hpp) are the same numbers. Yaw has no angle loop: its angle_sp is 0.
struct SysidSample {
    float angle_sp = 0.0f, rate_sp = 0.0f, rate = 0.0f, angle = 0.0f, axis_cmd = 0.0f;
};
inline SysidSample sysid_sample(const LoopStatus& st) {
    const LoopState& x = st.state;
    const int a = static_cast<int>(st.exc_axis);
    SysidSample s;
    s.angle_sp = a < kAngleAxes ? (a == 0 ? x.angle_sp.roll : x.angle_sp.pitch) : 0.0f;
    s.rate_sp = x.rate_sp[a];
    s.rate = x.rate[a];
    s.angle = x.attitude[a];
    s.axis_cmd = x.torque[a];
    return s;
}

}  // namespace hq
