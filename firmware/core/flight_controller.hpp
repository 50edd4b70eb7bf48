// FlightController: the one place that does a loop iteration's I/O. It reads the IMU through
// the HAL, computes and clamps dt, runs the cascade with any excitation injected, checks for
// non-finite values, writes the motors, and sends telemetry; it parses commands arriving on
// the telemetry link. Everything else in core/ is pure computation.
//
// Modes (HQ_MODE): disarmed, angle (sticks: roll/pitch angle, yaw rate), rate (sticks: body
// rates), sysid (angle or rate mode with an excitation running). Arming only with the
// throttle low, by the RC arm switch (channel 5 high) or MAV_CMD_COMPONENT_ARM_DISARM.
// Failsafe: RC lost (no valid frame for rc_timeout_us) or, when armed by command, no HEARTBEAT
// from the host for link_timeout_us -> motors off and disarmed, with a STATUSTEXT.
//
// Telemetry every loop: ATTITUDE and HQ_SYSID_SAMPLE (always the loop's last message);
// HEARTBEAT and HQ_FW_STATUS once a second; HQ_EXCITATION_STATUS on every change and in answer
// to a command; STATUSTEXT on faults.
// A message that does not fit the link is dropped whole and counted, never blocking the loop.
#pragma once

#include <cstdint>

#include "../hal/clock.hpp"
#include "../hal/i2c.hpp"
#include "../hal/outputs.hpp"
#include "../hal/serial.hpp"
#include "controllers.hpp"
#include "excitation.hpp"
#include "mixer.hpp"
#include "mpu6050.hpp"

#include <heliquad/mavlink.h>

namespace hq {

enum class Mode : uint8_t { Disarmed = 0, Angle = 1, Rate = 2, Sysid = 3 };

struct FlightControllerConfig {
    float loop_rate_hz = 200.0f;
    CascadeGains gains = CascadeGains::paper_defaults();
    MixerGeometry geometry{};
    Mpu6050Config imu{};
    uint8_t system_id = 1;
    uint8_t component_id = 1;            // MAV_COMP_ID_AUTOPILOT1
    uint32_t rc_timeout_us = 500000;     // RC failsafe
    uint32_t link_timeout_us = 1500000;  // host HEARTBEAT failsafe when armed by command
    float max_stick_angle_rad = 0.5236f; // 30 deg at full stick
    float max_stick_rate_rad_s = 3.4907f;// 200 deg/s at full stick (rate mode)
    float max_yaw_rate_rad_s = 1.5708f;  // 90 deg/s at full yaw stick
    float max_angle_rad = 1.3963f;       // 80 deg: setpoints (with excitation) are clamped here
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
};

class FlightController {
public:
    FlightController(const FlightControllerConfig& config, I2cBus& i2c, Clock& clock,
                     SerialPort& telemetry, MotorOutputs& motors);

    InitResult init();
    // One loop iteration at the clock's current time with the latest RC input.
    void step(const RcInput& rc);

    Mode mode() const { return mode_; }
    bool armed() const { return mode_ != Mode::Disarmed; }
    const LoopState& state() const { return state_; }
    const Excitation& excitation() const { return excitation_; }
    const Mpu6050& imu() const { return imu_; }
    uint32_t telemetry_dropped() const { return telemetry_dropped_; }
    uint32_t loops() const { return loops_; }

private:
    void read_imu(float dt_s);
    void handle_commands(const RcInput& rc);
    void handle_message(const mavlink_message_t& msg, const RcInput& rc);
    void handle_rc_arming(const RcInput& rc);
    bool try_arm(const RcInput& rc, bool by_command);
    void disarm(const char* reason);
    void check_failsafes(const RcInput& rc);
    void run_control(const RcInput& rc, float dt_s);
    void send_telemetry();
    void send_excitation_status(bool accepted);
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
    AttitudeController attitude_ctl_;
    RateController rate_ctl_;
    Mixer mixer_;
    Excitation excitation_;

    Mode mode_ = Mode::Disarmed;
    Mode flight_mode_ = Mode::Angle;      // mode to use when armed (angle or rate)
    bool armed_by_command_ = false;
    bool rc_arm_switch_was_high_ = false;
    LoopState state_{};
    Axis exc_axis_ = Axis::Roll;
    Injection exc_injection_ = Injection::Mixer;
    bool exc_was_active_ = false;
    bool have_time_ = false;
    uint64_t last_us_ = 0, last_host_heartbeat_us_ = 0, last_slow_us_ = 0;
    uint32_t loops_ = 0, seq_ = 0;
    uint32_t telemetry_dropped_ = 0, dt_clamped_ = 0, nan_events_ = 0;
    mavlink_status_t tx_status_{};
    mavlink_status_t rx_status_{};
    mavlink_message_t rx_msg_{};
};

}  // namespace hq
