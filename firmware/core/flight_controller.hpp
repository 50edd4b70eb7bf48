// FlightController: the loop. One iteration reads the IMU through the HAL, computes and
// clamps dt, answers the requests a ground station made (LoopInbox, loop_exchange.hpp),
// hands the loop's facts to the Supervisor (which owns the state and every safety rule, see
// supervisor.hpp and docs/safety.md), runs the cascade with the excitation the Supervisor
// gives, checks for non-finite values, writes the motors only when the Supervisor says they
// may spin, re-initialises a stale IMU when the Supervisor asks, keeps the parameters it
// flies (loaded, applied, saved), publishes what it did (LoopStatus) and queues it for the
// on-board log (log/logger.hpp: armed only, into a RAM ring; the card is never touched here).
//
// It has no MAVLink of its own: the ground-station link (link/gcs_link.hpp) turns messages
// into requests before the step and the published state into telemetry after it.
#pragma once

#include <cstdint>

#include "../hal/clock.hpp"
#include "../hal/i2c.hpp"
#include "../hal/motors.hpp"
#include "../hal/param_storage.hpp"
#include "../hal/rc_input.hpp"
#include "controllers.hpp"
#include "excitation.hpp"
#include "log/logger.hpp"
#include "loop_exchange.hpp"
#include "allocation.hpp"
#include "mpu6050.hpp"
#include "params.hpp"
#include "program.hpp"
#include "rc.hpp"
#include "supervisor.hpp"

namespace hq {

// The control loop's rate unless configured otherwise, and the most the host build runs
// (its --loop-hz), Hz.
constexpr float kLoopRateHz = 200.0f;
constexpr float kMaxLoopRateHz = 2000.0f;

struct FlightControllerConfig {
    float loop_rate_hz = kLoopRateHz;
    Mpu6050Config imu{};
    AttitudeFilterConfig attitude_filter{};   // the raw path's ComplementaryFilter
    // Where the parameters persist (nullptr: defaults at every start, nothing saved).
    ParamStorage* storage = nullptr;
    // Where the on-board program persists (program.hpp; nullptr: kept until restart).
    ParamStorage* program_storage = nullptr;
    // Why the chip last reset, for the boot report: the target reads it from the HAL
    // (hal/reset_cause.hpp) before init().
    ResetCause reset_cause = ResetCause::PowerOn;
};

class FlightController {
public:
    FlightController(const FlightControllerConfig& config, I2cBus& i2c, Clock& clock,
                     MotorOutputs& motors);

    // Loads the parameters and starts the IMU; status() has what it said, and what start-up
    // found (LoopStatus::boot).
    InitResult init();
    // One loop iteration at the clock's current time with the latest RC input, answering
    // `inbox`'s requests in order (their answers in inbox.answer[]); status() has the result.
    void step(const RcInput& rc, LoopInbox& inbox);

    const LoopStatus& status() const { return status_; }
    const Supervisor& supervisor() const { return supervisor_; }
    bool armed() const { return supervisor_.armed(); }
    FlightMode mode() const { return supervisor_.mode(); }
    const LoopState& state() const { return status_.state; }
    const Mpu6050& imu() const { return imu_; }
    const Params& params() const { return params_; }
    // The FIFO data the MPU6050 is configured for (HQ_SENSOR_KIND).
    uint8_t sensor_kind() const { return static_cast<uint8_t>(imu_.mode()); }
    uint32_t loops() const { return loops_; }
    // The DataFlash log (log/logger.hpp): the step queues its records; the spare-time service
    // (never the step) drains them into `sink`.
    void log_service(LogSink& sink) { logger_.service(sink, params_); }
    // The SD card's state at start-up (after init(), before the first step): the boot
    // report's finding; a card that cannot log is said in the first step, and every later
    // change of the card's state once, in the step after the spare-time service saw it.
    void set_card_state(CardState s);
    const Logger& logger() const { return logger_; }
    Logger& logger() { return logger_; }     // for the links' own STATUSTEXTs (GcsLinkConfig::log)

private:
    // flight_controller.cpp: the loop
    bool read_imu(float dt_s);
    void recover_imu(uint64_t now_us);
    InitResult init_imu();
    void run_control(const RcInput& rc, float excitation, const float rotor_excitation[],
                     float dt_s);
    void inject_motors(AllocationOutput& out, float excitation,
                       const float rotor_excitation[]) const;
    float clamp_dt(uint64_t now_us);
    void publish(uint64_t now_us);
    void publish_events();
    void notice(uint8_t severity, const char* text, int param_index = -1);
    void notice(const Notice& n);
    // flight_controller_requests.cpp: the requests and the parameters they change
    void answer(LoopInbox& inbox, const RcInput& rc, uint64_t now_us);
    LoopAnswer answer_one(const LoopRequest& r, const ExcitationConfig& start, const RcInput& rc,
                          uint64_t now_us);
    LoopAnswer answer_bootloader();
    LoopAnswer answer_excitation(const LoopRequest& r, const ExcitationConfig& start,
                                 uint64_t now_us);
    LoopAnswer answer_param_set(const LoopRequest& r, uint64_t now_us);
    Verdict storage_action(uint32_t action, uint64_t now_us);
    ExcitationReport excitation_report() const;
    ParamsFinding load_params(int& bad_index, SetResult& bad_result);
    void configure_allocation();
    void apply_params(uint8_t changed, uint64_t now_us);
    void save_params_when_due(uint64_t now_us);
    bool save_params();
    // flight_controller_program.cpp: the on-board program
    void load_program();
    LoopAnswer answer_program(const LoopRequest& r, const ExcitationConfig& step);
    LoopAnswer set_program_step(const LoopRequest& r, const ExcitationConfig& step);
    bool save_program(const Program& program);
    void run_program(const RcInput& rc, uint64_t now_us);
    void program_event(const ProgramEvent& e);
    ProgramReport program_report() const;

    FlightControllerConfig config_;
    I2cBus& i2c_;
    Clock& clock_;
    MotorOutputs& motors_;
    Mpu6050 imu_;
    ComplementaryFilter filter_;
    Cascade cascade_;
    Allocation allocation_;   // from the geometry parameters (configure_allocation())
    Supervisor supervisor_;
    Params params_;
    Logger logger_;

    LoopStatus status_{};
    RcInput rc_{};                           // this loop's RC input
    bool have_time_ = false;
    uint64_t last_us_ = 0;
    uint32_t loops_ = 0;
    uint32_t dt_clamped_ = 0;
    CardState card_said_ = CardState::Ok;      // the card's state the last notice said
    InitResult imu_init_ = InitResult::NoDevice;
    bool params_dirty_ = false;              // changed since the last save
    uint64_t params_changed_us_ = 0;
    Program program_{};                      // the stored program
    ProgramBuilder program_in_{};            // a new one, arriving step by step
    ProgramRunner program_runner_{};
};

}  // namespace hq
