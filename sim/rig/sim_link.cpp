#include "rig/sim_link.hpp"

#include <fcntl.h>
#include <termios.h>
#include <unistd.h>

#include <cerrno>
#include <chrono>
#include <cstring>
#include <stdexcept>

namespace hqsim {
namespace {

// The simulator's MAVLink identity on the sim link.
constexpr uint8_t kSystemId = 1;
constexpr uint8_t kComponentId = MAV_COMP_ID_IMU;

int ms_since(std::chrono::steady_clock::time_point t0) {
    return static_cast<int>(std::chrono::duration_cast<std::chrono::milliseconds>(
                                std::chrono::steady_clock::now() - t0)
                                .count());
}

}  // namespace

SimLinkPort::SimLinkPort(int fd, int timeout_ms) : fd_(fd), timeout_ms_(timeout_ms) {
    // Blocking reads that give up after kReadSliceDs tenths of a second (VMIN 0, VTIME): a
    // reply costs one read() instead of poll() and read().
    termios t{};
    const int flags = ::fcntl(fd_, F_GETFL);
    if (flags < 0 || ::tcgetattr(fd_, &t) != 0) {
        throw std::invalid_argument("the sim link must be a terminal (the firmware's pty)");
    }
    t.c_cc[VMIN] = 0;
    t.c_cc[VTIME] = kReadSliceDs;
    if (::tcsetattr(fd_, TCSANOW, &t) != 0 || ::fcntl(fd_, F_SETFL, flags & ~O_NONBLOCK) != 0) {
        throw std::invalid_argument("cannot set up the sim link's terminal");
    }
}

bool SimLinkPort::write_all(const uint8_t* data, size_t len) {
    // Blocking, without a timeout of its own: a frame is written only once the previous one
    // was answered (or its wait failed), so the pty never fills and the write cannot stall.
    while (len > 0) {
        const ssize_t n = ::write(fd_, data, len);
        if (n > 0) {
            data += n;
            len -= static_cast<size_t>(n);
        } else if (n < 0 && errno != EINTR) {
            errno_ = errno;            // EIO: the firmware is gone
            return false;
        }
    }
    return true;
}

LinkStatus SimLinkPort::exchange(uint64_t time_us, uint32_t frame, uint8_t fifo_kind,
                                 const uint8_t* fifo, size_t fifo_len,
                                 const uint16_t rc_us[kRcChannels], bool sync, uint8_t imu_fault,
                                 Reply* reply) {
    uint8_t padded[kFifoCapacity] = {};
    if (fifo_len > kFifoCapacity) fifo_len = kFifoCapacity;
    if (fifo_len) std::memcpy(padded, fifo, fifo_len);
    mavlink_message_t msg;
    mavlink_msg_hq_sensor_frame_pack_status(kSystemId, kComponentId, &tx_status_, &msg, time_us,
                                            frame, fifo_kind, static_cast<uint8_t>(fifo_len),
                                            sync ? 1 : 0, rc_us, padded, imu_fault);
    uint8_t out[MAVLINK_MAX_PACKET_LEN];
    const uint16_t len = mavlink_msg_to_send_buffer(out, &msg);
    if (!write_all(out, len)) return LinkStatus::WriteFailed;
    return wait_reply(frame, reply);
}

LinkStatus SimLinkPort::wait_reply(uint32_t frame, Reply* reply) {
    const auto t0 = std::chrono::steady_clock::now();
    uint8_t buf[512];
    for (;;) {
        const int left = timeout_ms_ - ms_since(t0);
        if (left <= 0) return LinkStatus::Timeout;
        const ssize_t n = ::read(fd_, buf, sizeof buf);
        if (n == 0) continue;                          // a read slice passed without data
        if (n < 0 && errno == EINTR) continue;
        if (n <= 0) return LinkStatus::Closed;         // EIO or EOF: the pty's master is gone
        for (ssize_t i = 0; i < n; ++i) {
            mavlink_message_t m;
            mavlink_status_t st;
            if (mavlink_frame_char_buffer(&rx_msg_, &rx_status_, buf[i], &m, &st) !=
                    MAVLINK_FRAMING_OK ||
                m.msgid != MAVLINK_MSG_ID_HQ_ACTUATOR_FRAME) {
                continue;
            }
            mavlink_hq_actuator_frame_t a;
            mavlink_msg_hq_actuator_frame_decode(&m, &a);
            reply->time_us = a.time_us;
            reply->frame = a.frame;
            static_assert(sizeof a.motor == sizeof reply->motor, "HQ_ACTUATOR_FRAME.motor: kMaxRotors");
            std::memcpy(reply->motor.data(), a.motor, sizeof a.motor);
            reply->motor_count = a.motor_count;
            reply->armed = a.armed;
            reply->mode = a.mode;
            reply->sensor_kind = a.sensor_kind;
            // One reply per frame: anything after it belongs to no request (dropped).
            return a.frame == frame ? LinkStatus::Ok : LinkStatus::WrongFrame;
        }
    }
}

}  // namespace hqsim
