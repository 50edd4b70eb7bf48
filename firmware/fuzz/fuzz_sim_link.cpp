// libFuzzer target: the firmware's sim-link path (targets/host/sim_link_handler.*), what
// heliquad-fw-host does with every byte the simulator sends. Input: HQ_SENSOR_FRAMEs with
// fuzzed fields (time, frame counter, FIFO kind, fifo_len up to 255 against the 168-byte
// field, FIFO bytes, RC, sync, IMU fault), any other message of the dialect or an unknown
// one framed with a correct CRC and any length, and raw bytes. Besides the sanitizers it
// checks the link contract: exactly one reply per sensor frame (a repeat included), each an
// HQ_ACTUATOR_FRAME echoing that frame's time and counter, with motors off unless armed.
//
//   build: cmake -S firmware -B build/fuzz -DCMAKE_CXX_COMPILER=clang++ -DHQ_FUZZ=ON
//   run:   build/fuzz/fuzz_sim_link CORPUS -max_total_time=60   (or tests/fuzz/run.py)
#include <cmath>
#include <cstdlib>
#include <cstring>

#include "core/flight_controller.hpp"
#include "fuzz_input.hpp"
#include "sensor/mpu6050_emulator.hpp"
#include "targets/host/clock.hpp"
#include "targets/host/motors.hpp"
#include "targets/host/sim_link_handler.hpp"

namespace {

using hqfuzz::Reader;

class NoTelemetry final : public hq::SerialPort {
public:
    size_t read(uint8_t*, size_t) override { return 0; }
    size_t write(const uint8_t*, size_t n) override { return n; }
};

// Takes the replies and checks each against the frame that asked for it: a new frame's reply
// echoes its counter and time; a repeated frame gets the previous reply again, byte for byte.
class Replies final : public hq::SimLinkReplies {
public:
    bool reply(const uint8_t* packet, size_t n, bool) override {
        ++count;
        mavlink_message_t msg;
        mavlink_status_t st;
        bool got = false;
        for (size_t i = 0; i < n; ++i) {
            if (mavlink_frame_char_buffer(&rx_msg_, &rx_, packet[i], &msg, &st) ==
                MAVLINK_FRAMING_OK) {
                got = true;
            }
        }
        if (!got || msg.msgid != MAVLINK_MSG_ID_HQ_ACTUATOR_FRAME) std::abort();
        mavlink_hq_actuator_frame_t a;
        mavlink_msg_hq_actuator_frame_decode(&msg, &a);
        if (check == Check::Repeat && (n != last_len_ || std::memcmp(packet, last_, n) != 0)) {
            std::abort();
        }
        if (check == Check::New && (a.frame != expect_frame || a.time_us != expect_time)) {
            std::abort();
        }
        if (a.motor_count < 1 || a.motor_count > hq::kMaxRotors) std::abort();
        for (int i = 0; i < hq::kMaxRotors; ++i) {
            const float m = a.motor[i];
            if (!std::isfinite(m) || m < 0.0f || m > 1.0f || (!a.armed && m != 0.0f)) std::abort();
            if (i >= a.motor_count && m != 0.0f) std::abort();     // past the count: stopped
        }
        std::memcpy(last_, packet, n);
        last_len_ = n;
        return accept;
    }
    enum class Check { None, New, Repeat };
    Check check = Check::None;
    uint32_t count = 0, expect_frame = 0;
    uint64_t expect_time = 0;
    bool accept = true;

private:
    mavlink_status_t rx_{};
    mavlink_message_t rx_msg_{};
    uint8_t last_[MAVLINK_MAX_PACKET_LEN] = {};
    size_t last_len_ = 0;
};

constexpr int kMaxFrames = 48;             // per input: keeps executions fast
constexpr uint64_t kLoopUs = 5000;

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
    Reader in(data, size);
    hqfuzz::Vehicle<NoTelemetry> v(in);
    hq::SimLinkHandler handler(v.fc, v.link, v.clock, v.chip, v.motors, v.link_cfg.system_id,
                               v.link_cfg.component_id);
    Replies replies;
    mavlink_status_t tx{};
    uint8_t packet[hqfuzz::kMaxPacket];
    uint8_t seq = 0;
    uint32_t frame = 0;
    uint64_t time_us = 0;
    int frames = 0;
    while (!in.done() && frames < kMaxFrames) {
        const uint8_t op = in.u8();
        if (op % 4 == 0) {                        // any message, any length: ignored or not
            const size_t n = hqfuzz::any_packet(in, packet, seq++);
            const uint32_t before = replies.count;
            const bool idle = handler.between_packets();
            replies.check = Replies::Check::None;
            replies.accept = true;
            handler.feed(packet, n, replies);
            // A mangled HQ_SENSOR_FRAME is still a frame, with whatever its fields decode to;
            // follow its counter. From between packets, one packet is at most one frame (out
            // of step after noise, its payload may hold embedded frames).
            if (idle && replies.count > before + 1) std::abort();
            if (replies.count > before) frame = handler.last_frame();
            continue;
        }
        if (op % 4 == 1) {                        // line noise
            uint8_t raw[64];
            replies.check = Replies::Check::None;
            replies.accept = true;
            handler.feed(raw, in.bytes(raw, in.u8() % sizeof raw), replies);
            continue;
        }
        // A sensor frame: mostly the next counter and time, sometimes a repeat or a jump.
        const uint8_t how = in.u8();
        if ((how & 7) != 0 || handler.frames() == 0) {
            frame = (how & 7) == 1 ? in.u32() : frame + 1;
            time_us = (how & 0x38) == 0x08 ? in.u64() : time_us + kLoopUs;
        }
        // The same counter as the last frame is a repeat, however it came about.
        const bool repeat = handler.frames() > 0 && frame == handler.last_frame();
        uint16_t rc[MAVLINK_MSG_HQ_SENSOR_FRAME_FIELD_RC_US_LEN];
        for (auto& ch : rc) ch = in.u16() % 2200;
        uint8_t fifo[MAVLINK_MSG_HQ_SENSOR_FRAME_FIELD_FIFO_LEN];
        in.bytes(fifo, sizeof fifo);
        // FIFO kind: every HQ_SENSOR_KIND and one unknown; IMU fault: every HQ_IMU_FAULT.
        const auto kind = static_cast<uint8_t>(in.u8() % (HQ_SENSOR_KIND_ENUM_END + 1));
        const uint8_t fifo_len = in.u8(), sync = in.u8() & 1;
        const auto fault = static_cast<uint8_t>(in.u8() % HQ_IMU_FAULT_ENUM_END);
        mavlink_message_t msg;
        mavlink_msg_hq_sensor_frame_pack_status(1, MAV_COMP_ID_IMU, &tx, &msg, time_us, frame, kind, fifo_len,
                                                sync, rc, fifo, fault);
        const size_t n = mavlink_msg_to_send_buffer(packet, &msg);
        replies.expect_frame = frame;
        replies.expect_time = time_us;
        replies.accept = (in.u8() & 0x1F) != 0;
        const uint32_t before = replies.count;
        // Only a parser between packets is sure to see this frame (after noise it may be
        // inside a bogus frame that swallows it, or find frames inside it).
        const bool clean = handler.between_packets();
        replies.check = !clean ? Replies::Check::None
                        : repeat ? Replies::Check::Repeat : Replies::Check::New;
        const bool kept = handler.feed(packet, n, replies);
        if (clean && (replies.count != before + 1 || kept != replies.accept)) std::abort();
        ++frames;
    }
    return 0;
}
