// The firmware's end of the sim link (docs/link-contract.md), without the pty: bytes in,
// one FlightController step (with the
// telemetry link's requests before it and its telemetry after) per new HQ_SENSOR_FRAME, exactly one HQ_ACTUATOR_FRAME out.
//
// Per frame: the clock is set to time_us (never backwards: a frame from the past runs at the
// latest time seen); the frame's imu_fault acts on the emulated MPU6050
// (SILENT and NACK hold while frames carry them, RESET and OVERFLOW act once); its FIFO bytes
// go into the chip (fifo_len is clamped to the field's 168 bytes); the RC channels become the
// loop's RcInput (age 0 when any channel has a pulse, "never" when none has); one step runs.
// A repeated frame counter gets the previous reply again without a step; a forward gap is
// counted as lost frames.
// Messages other than HQ_SENSOR_FRAME, and damaged bytes, are ignored.
#pragma once

#include <cstddef>
#include <cstdint>

#include "../../core/flight_controller.hpp"
#include "../../core/link/gcs_link.hpp"
#include "clock.hpp"
#include "motors.hpp"
#include "sensor/mpu6050_emulator.hpp"

namespace hq {

// Where replies go: the sim link's pty in heliquad-fw-host, a buffer in the fuzzer.
class SimLinkReplies {
public:
    // One reply packet; `sync`: the simulator reads the telemetry link after this frame.
    // Returns false when the link is gone.
    virtual bool reply(const uint8_t* packet, size_t n, bool sync) = 0;

protected:
    ~SimLinkReplies() = default;
};

class SimLinkHandler {
public:
    SimLinkHandler(FlightController& fc, GcsLink& link, HostClock& clock, Mpu6050Emulator& chip,
                   const HostMotors& motors, uint8_t system_id, uint8_t component_id);

    // Feeds bytes from the sim link. Returns false as soon as `out` refuses a reply.
    bool feed(const uint8_t* data, size_t n, SimLinkReplies& out);

    uint32_t frames() const { return frames_; }
    uint32_t lost() const { return lost_; }
    uint32_t repeated() const { return repeated_; }
    uint32_t last_frame() const { return last_frame_; }
    // True when the parser is between packets (the next STX starts a new one).
    bool between_packets() const { return rx_status_.parse_state <= MAVLINK_PARSE_STATE_IDLE; }

private:
    bool on_frame(const mavlink_message_t& msg, SimLinkReplies& out);
    void apply_fault(uint8_t fault);

    FlightController& fc_;
    GcsLink& link_;
    HostClock& clock_;
    Mpu6050Emulator& chip_;
    const HostMotors& motors_;
    uint8_t system_id_, component_id_;
    mavlink_status_t rx_status_{}, tx_status_{};
    mavlink_message_t rx_msg_{};
    bool have_last_ = false;
    uint32_t last_frame_ = 0, frames_ = 0, lost_ = 0, repeated_ = 0;
    uint8_t out_[MAVLINK_MAX_PACKET_LEN] = {};
    uint16_t out_len_ = 0;
};

}  // namespace hq
