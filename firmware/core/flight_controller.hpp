// FlightController: the one place that does a loop iteration's I/O. It reads the IMU through
// the HAL, computes and clamps dt, hands the commands that arrived on the telemetry link and
// the loop's facts to the Supervisor (which owns the state and every safety rule, see
// supervisor.hpp and docs/safety.md), runs the cascade with the excitation the Supervisor
// gives, checks for non-finite values, writes the motors only when the Supervisor says they
// may spin, re-initialises a stale IMU when the Supervisor asks, and sends telemetry.
//
// Telemetry every loop: ATTITUDE and HQ_SYSID_SAMPLE (always the loop's last message);
// HEARTBEAT and HQ_FW_STATUS once a second; HQ_EXCITATION_STATUS in answer to every
// HQ_EXCITATION and when an excitation ends; STATUSTEXT for every Supervisor event;
// COMMAND_ACK for COMMAND_LONG.
// A message that does not fit the link is dropped whole and counted, never blocking the loop.
#pragma once

#include <cstdint>

#include "../hal/clock.hpp"
#include "../hal/i2c.hpp"
#include "../hal/motors.hpp"
#include "../hal/param_storage.hpp"
#include "../hal/rc_input.hpp"
#include "../hal/serial.hpp"
#include "controllers.hpp"
#include "excitation.hpp"
#include "loop_load.hpp"
#include "mixer.hpp"
#include "mpu6050.hpp"
#include "rc.hpp"
#include "supervisor.hpp"

#include <heliquad/mavlink.h>

namespace hq {

struct FlightControllerConfig {
    float loop_rate_hz = 200.0f;
    CascadeGains gains = CascadeGains::paper_defaults();
    MixerGeometry geometry{};
    Mpu6050Config imu{};
    AttitudeFilterConfig attitude_filter{};   // the raw path's ComplementaryFilter
    uint8_t system_id = 1;
    uint8_t component_id = MAV_COMP_ID_AUTOPILOT1;
    // The rules' bounds. imu_timeout_us is replaced at init() by imu_timeout_for() of the
    // IMU's configured rate.
    SafetyLimits safety{};
    StickLimits sticks{};
    // Where the parameters persist (nullptr: defaults at every start, nothing saved).
    ParamStorage* storage = nullptr;
};

struct LoopState {               // what the last loop computed, for telemetry and tests
    Euler attitude{};
    Vec3 rate{};
    Euler angle_sp{};
    Vec3 rate_sp{};
    Vec3 torque{};               // normalised mixer torque commands, after injection
    float collective = 0.0f;
    float excitation = 0.0f;
    float motor[kMotors] = {0, 0, 0, 0, 0};
    float dt_s = 0.0f;
    uint8_t sensor_clipped = 0;  // HQ_SATURATION_GYRO / _ACCEL bits of the last IMU sample
    uint8_t saturation = 0;      // HQ_SATURATION bits of this loop (mixer and sensor)
};

class FlightController {
public:
    FlightController(const FlightControllerConfig& config, I2cBus& i2c, Clock& clock,
                     SerialPort& telemetry, MotorOutputs& motors);

    InitResult init();
    // One loop iteration at the clock's current time with the latest RC input.
    void step(const RcInput& rc);
    // The target's measurement of the loop just run: CPU cycles of its work and the loop
    // ticks missed since boot (HQ_FW_STATUS loop_cycles_*, loop_overruns).
    void record_loop(uint32_t cycles, uint32_t overruns_total) {
        load_.record(cycles, overruns_total);
    }

    const Supervisor& supervisor() const { return supervisor_; }
    bool armed() const { return supervisor_.armed(); }
    FlightMode mode() const { return supervisor_.mode(); }
    const LoopState& state() const { return state_; }
    const Mpu6050& imu() const { return imu_; }
    // The FIFO data the MPU6050 is configured for (HQ_SENSOR_KIND).
    uint8_t sensor_kind() const;
    uint32_t telemetry_dropped() const { return telemetry_dropped_; }
    uint32_t loops() const { return loops_; }

private:
    bool read_imu(float dt_s);
    void handle_commands(const RcInput& rc, uint64_t now_us);
    void handle_message(const mavlink_message_t& msg, const RcInput& rc, uint64_t now_us);
    void handle_command_long(const mavlink_message_t& msg, const RcInput& rc, uint64_t now_us);
    void handle_excitation(const mavlink_message_t& msg, uint64_t now_us);
    void recover_imu(uint64_t now_us);
    void run_control(const RcInput& rc, float excitation, float dt_s);
    void send_events();
    void send_telemetry();
    void send_excitation_status(Reason reason);
    void send_statustext(uint8_t severity, const char* text);
    void send(const mavlink_message_t& msg);
    float clamp_dt(uint64_t now_us);

    FlightControllerConfig config_;
    I2cBus& i2c_;
    Clock& clock_;
    SerialPort& telemetry_;
    MotorOutputs& motors_;
    Mpu6050 imu_;
    ComplementaryFilter filter_;
    Cascade cascade_;
    Mixer mixer_;
    Supervisor supervisor_;

    LoopState state_{};
    LoopLoad load_{};
    bool last_exc_accepted_ = false;
    bool have_time_ = false;
    uint64_t last_us_ = 0, last_slow_us_ = 0;
    uint32_t loops_ = 0, seq_ = 0;
    uint32_t telemetry_dropped_ = 0, dt_clamped_ = 0;
    mavlink_status_t tx_status_{};
    mavlink_status_t rx_status_{};
    mavlink_message_t rx_msg_{};
};

}  // namespace hq
