// The simulator's end of the sim link (docs/link-contract.md): one HQ_SENSOR_FRAME out,
// exactly one HQ_ACTUATOR_FRAME back with the same time and counter. The pty is opened (and
// made raw) by Python with pyserial; this class owns the byte exchange on its fd, which it
// switches to blocking reads with a VTIME slice.
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>

#include <hq_mavlink.hpp>
#include "plant/rig_plant.hpp"

namespace hqsim {

// The sensor frame's FIFO bytes and RC channels (the dialect's array lengths).
constexpr size_t kFifoCapacity = MAVLINK_MSG_HQ_SENSOR_FRAME_FIELD_FIFO_LEN;
constexpr size_t kRcChannels = MAVLINK_MSG_HQ_SENSOR_FRAME_FIELD_RC_US_LEN;

enum class LinkStatus : int {
    Ok = 0,
    WriteFailed = 1,      // the write failed (errno in `error`): the firmware is gone
    Closed = 2,           // the pty hung up: the firmware is gone
    Timeout = 3,          // no reply within the timeout
    WrongFrame = 4,       // a reply with another frame counter (in `reply.frame`)
    Cancelled = 5,        // the engine was asked to stop
    RotorCount = 6,       // the firmware flies another number of rotors than the plant has
};

struct Reply {
    uint64_t time_us = 0;
    uint32_t frame = 0;
    std::array<float, kMaxRotors> motor{};   // 0 past motor_count
    uint8_t motor_count = 0, armed = 0, mode = 0, sensor_kind = 0;
};

class SimLinkPort {
public:
    SimLinkPort(int fd, int timeout_ms);

    // `sync`: the caller pauses after this frame to read the telemetry (HQ_SENSOR_FRAME.sync).
    // `imu_fault`: HQ_IMU_FAULT of the emulated chip at this frame (fault injection).
    LinkStatus exchange(uint64_t time_us, uint32_t frame, uint8_t fifo_kind, const uint8_t* fifo,
                        size_t fifo_len, const uint16_t rc_us[kRcChannels], bool sync,
                        uint8_t imu_fault,
                        Reply* reply);
    int error() const { return errno_; }

private:
    bool write_all(const uint8_t* data, size_t len);
    LinkStatus wait_reply(uint32_t frame, Reply* reply);

    static constexpr unsigned char kReadSliceDs = 1;   // VTIME: 0.1 s

    int fd_;
    int timeout_ms_;
    int errno_ = 0;
    mavlink_status_t tx_status_{}, rx_status_{};
    mavlink_message_t rx_msg_{};
};

}  // namespace hqsim
