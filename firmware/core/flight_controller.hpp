// FlightController: the one place that does a loop iteration's I/O. It reads the IMU through
// the HAL, computes and clamps dt, hands the commands that arrived on the telemetry link and
// the loop's facts to the Supervisor (which owns the state and every safety rule, see
// supervisor.hpp and docs/safety.md), runs the cascade with the excitation the Supervisor
// gives, checks for non-finite values, writes the motors only when the Supervisor says they
// may spin, re-initialises a stale IMU when the Supervisor asks, answers the MAVLink
// parameter protocol (params.hpp) and sends telemetry.
//
// Telemetry (flight_controller_link.cpp; docs/link-contract.md): every loop ATTITUDE and
// HQ_SYSID_SAMPLE (always the loop's last message); HEARTBEAT, HQ_FW_STATUS and SYS_STATUS
// once a second; SERVO_OUTPUT_RAW, SCALED_IMU, HIGHRES_IMU and RC_CHANNELS at 10, 10, 10 and
// 5 Hz; each but
// HEARTBEAT and HQ_SYSID_SAMPLE at the interval SET_MESSAGE_INTERVAL asks for, within what
// the link carries. HQ_EXCITATION_STATUS in answer to every HQ_EXCITATION and when an
// excitation ends; STATUSTEXT for every Supervisor event and parameter refusal; COMMAND_ACK
// for every COMMAND_LONG and COMMAND_INT addressed to it or broadcast; PARAM_VALUE for the
// parameter protocol, a few per loop.
// A message that does not fit the link is dropped whole and counted, never blocking the loop
// (a PARAM_VALUE is sent again in the next loop instead).
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
#include "params.hpp"
#include "rc.hpp"
#include "supervisor.hpp"

#include <heliquad/mavlink.h>

namespace hq {

// The control loop's rate unless configured otherwise, and the most the host build runs
// (its --loop-hz), Hz.
constexpr float kLoopRateHz = 200.0f;
constexpr float kMaxLoopRateHz = 2000.0f;

struct FlightControllerConfig {
    float loop_rate_hz = kLoopRateHz;
    // The parameters' defaults (gains, limits, endpoints, thresholds, the IMU's path); the
    // values stored in `storage` replace them at init().
    Tunables tunables{};
    MixerGeometry geometry{};
    Mpu6050Config imu{};
    AttitudeFilterConfig attitude_filter{};   // the raw path's ComplementaryFilter
    uint8_t system_id = 1;
    uint8_t component_id = MAV_COMP_ID_AUTOPILOT1;
    // Where the parameters persist (nullptr: defaults at every start, nothing saved).
    ParamStorage* storage = nullptr;
    // What the telemetry link carries, bytes per second (921600 baud, 10 bits a byte):
    // SET_MESSAGE_INTERVAL refuses rates that would need more than 80 % of it.
    uint32_t link_bytes_per_s = 92160;
    // CPU cycles per second of the target's cycle counter (SYS_STATUS load); 0: none.
    uint32_t cpu_hz = 0;
    // The board's unique id (AUTOPILOT_VERSION.uid, and uid2 whole): the chip's own on the
    // Teensy (SIM_UIDH..UIDL, 128 bits, most significant word first); the host build's
    // stand-in is targets/host/main.cpp's.
    uint64_t uid = 0;
    uint8_t uid2[18] = {};
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
    Vec3 accel{};                // m/s^2, the last IMU sample's
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
    const Params& params() const { return params_; }
    // The FIFO data the MPU6050 is configured for (HQ_SENSOR_KIND).
    uint8_t sensor_kind() const;
    uint32_t telemetry_dropped() const { return telemetry_dropped_; }
    uint32_t loops() const { return loops_; }

    // A message the firmware streams or sends on request (SET_MESSAGE_INTERVAL,
    // MAV_CMD_REQUEST_MESSAGE), with its interval in microseconds (0: off).
    struct Stream {
        uint32_t msgid;
        uint32_t default_us;
        uint32_t interval_us;
        uint64_t next_us;
        bool requested;          // once, in the next loop (MAV_CMD_REQUEST_MESSAGE)
    };
    static constexpr int kStreams = 9;

private:
    // flight_controller.cpp: the loop
    bool read_imu(float dt_s);
    void recover_imu(uint64_t now_us);
    InitResult init_imu();
    void run_control(const RcInput& rc, float excitation, float dt_s);
    float clamp_dt(uint64_t now_us);
    void load_params();
    void apply_params(uint8_t changed, uint64_t now_us);
    void save_params_when_due(uint64_t now_us);
    bool save_params();
    // flight_controller_link.cpp: the telemetry link
    void handle_commands(const RcInput& rc, uint64_t now_us);
    void handle_message(const mavlink_message_t& msg, const RcInput& rc, uint64_t now_us);
    void handle_command(const mavlink_message_t& msg, uint16_t command, const float p[7],
                        const RcInput& rc, uint64_t now_us);
    uint8_t command_result(uint16_t command, const float p[7], const RcInput& rc,
                           uint64_t now_us, StationId who, Reason& why);
    uint8_t storage_command(uint32_t action);
    uint8_t interval_command(uint32_t msgid, float interval_us);
    uint8_t request_message(uint32_t msgid);
    void handle_excitation(const mavlink_message_t& msg, uint64_t now_us);
    static void read_harmonics(const mavlink_hq_excitation_t& ex, ExcitationConfig& cfg);
    void handle_param_set(const mavlink_message_t& msg, uint64_t now_us);
    void handle_param_read(const mavlink_message_t& msg);
    void refuse_file_transfer(const mavlink_message_t& msg);
    void send_unknown_param(const char* name, int index);
    bool for_us(uint8_t target_system, uint8_t target_component) const;
    Stream* stream(uint32_t msgid);
    bool stream_due(Stream& s, uint64_t now_us);
    uint32_t stream_bytes_per_s(uint32_t msgid, uint32_t interval_us) const;
    void send_events();
    void send_telemetry();
    void send_stream(uint32_t msgid, uint64_t now_us);
    void send_heartbeat();
    void send_fw_status(uint64_t now_us);
    void send_sys_status();
    void send_autopilot_version();
    void send_servo_output(uint64_t now_us);
    void send_rc_channels(uint64_t now_us);
    void send_scaled_imu(uint64_t now_us);
    void send_highres_imu(uint64_t now_us);
    void send_param_error(const mavlink_message_t& to, const char* name, int index,
                          SetResult why);
    void send_params();
    bool send_param_value(int index);
    void send_excitation_status(Reason reason);
    void send_statustext(uint8_t severity, const char* text);
    bool send(const mavlink_message_t& msg);

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
    Params params_;

    LoopState state_{};
    RcInput rc_{};                           // this loop's RC input (RC_CHANNELS)
    LoopLoad load_{};
    LoopLoad::Report last_load_{};           // the last second's (HQ_FW_STATUS, SYS_STATUS)
    Stream streams_[kStreams];
    bool last_exc_accepted_ = false;
    bool have_time_ = false;
    uint64_t last_us_ = 0;
    uint32_t loops_ = 0, seq_ = 0;
    uint32_t telemetry_dropped_ = 0, dt_clamped_ = 0;
    uint32_t bytes_sent_ = 0, bytes_dropped_ = 0;     // this second's, for SYS_STATUS
    uint16_t drop_rate_ = 0;                          // the last second's, 1/100 %
    InitResult imu_init_ = InitResult::NoDevice;
    uint64_t params_pending_ = 0;            // PARAM_VALUEs to send, one bit per index
    uint64_t params_as_float_ = 0;           // of those, answers to a set sent as REAL32
    bool params_dirty_ = false;              // changed since the last save
    uint64_t params_changed_us_ = 0;
    mavlink_status_t tx_status_{};
    mavlink_status_t rx_status_{};
    mavlink_message_t rx_msg_{};
};

}  // namespace hq
