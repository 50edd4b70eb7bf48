#include "chip/pil_frames.hpp"

#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <chrono>
#include <cmath>
#include <cstring>

#include <hq_mavlink.hpp>
#include "sensor/mpu6050_emulator.hpp"

namespace hqsim::mk64 {

namespace {

constexpr uint8_t kStx = MAVLINK_STX;
constexpr size_t kHeader = MAVLINK_NUM_HEADER_BYTES, kCrc = MAVLINK_NUM_CHECKSUM_BYTES,
                 kSignature = MAVLINK_SIGNATURE_BLOCK_LEN;
constexpr uint8_t kSigned = MAVLINK_IFLAG_SIGNED;
constexpr size_t kRcChannels = 7;                // the RC pins (FTM3 channels 0..6)
constexpr int kRcFrameLoops = 4;                 // a 50 Hz receiver's frame: four loops
constexpr size_t kReportSize = 17;               // hq_loop_report: <IIIBBBBB
constexpr size_t kMotors = MAVLINK_MSG_HQ_ACTUATOR_FRAME_FIELD_MOTOR_LEN;   // FTM0's channels
constexpr int kWriteTimeoutMs = 5000;            // as the Python path's write_all

uint32_t u32(const uint8_t* p) {
    return static_cast<uint32_t>(p[0]) | (static_cast<uint32_t>(p[1]) << 8) |
           (static_cast<uint32_t>(p[2]) << 16) | (static_cast<uint32_t>(p[3]) << 24);
}

}  // namespace

struct SensorFrame {
    mavlink_hq_sensor_frame_t m;
};

// The packet at the front of `input`: a whole, CRC-checked HQ_SENSOR_FRAME (kFrame); bytes
// Python's framer must see (kPython: not a packet start, another message, a bad CRC); or a
// packet cut off by the end of the input (kMore).
PilFrames::Packet PilFrames::next_packet(size_t& total, size_t& payload_len) const {
    const auto* b = reinterpret_cast<const uint8_t*>(input.data());
    const size_t n = input.size();
    if (n == 0) return Packet::kMore;
    if (b[0] != kStx) return Packet::kPython;
    if (n < kHeader) return Packet::kMore;
    payload_len = b[1];
    total = kHeader + payload_len + kCrc + ((b[2] & kSigned) ? kSignature : 0);
    if (n < total) return Packet::kMore;
    const uint32_t msgid = b[7] | (b[8] << 8) | (static_cast<uint32_t>(b[9]) << 16);
    if (msgid != MAVLINK_MSG_ID_HQ_SENSOR_FRAME || (b[2] & kSigned)) return Packet::kPython;
    uint16_t crc = crc_calculate(b + 1, static_cast<uint16_t>(kHeader - 1 + payload_len));
    crc_accumulate(MAVLINK_MSG_ID_HQ_SENSOR_FRAME_CRC, &crc);
    const size_t at = kHeader + payload_len;
    if ((b[at] | (b[at + 1] << 8)) != crc) return Packet::kPython;
    return Packet::kFrame;
}

// The frame decoded; true when it is plain (the header's conditions).
bool PilFrames::plain(const uint8_t* payload, size_t len, SensorFrame& f) const {
    mavlink_message_t msg{};
    msg.len = static_cast<uint8_t>(len);
    std::memcpy(_MAV_PAYLOAD_NON_CONST(&msg), payload, len);
    mavlink_msg_hq_sensor_frame_decode(&msg, &f.m);
    if (f.m.frame != last_frame + 1 || f.m.imu_fault != HQ_IMU_FAULT_NONE) return false;
    const bool same = rc_last.size() == kRcChannels &&
                      std::equal(rc_last.begin(), rc_last.end(), f.m.rc_us);
    if (same && rc_age + 1 < kRcFrameLoops) return true;    // no pulses this frame
    if (!config.rc_native) return false;
    for (size_t ch = 0; ch < kRcChannels; ++ch) {
        if (f.m.rc_us[ch] == 0) continue;
        const PinEdges::Pin& pin = config.rc_pins[ch];
        if (!pin.pdir) return false;                        // a pin the pin model drives
        GpioInputs::Port* port = core_.gpio_in.port(pin.pdir);
        if (!port || (port->value & pin.bit)) return false;   // a pulse still on
    }
    return true;
}

int PilFrames::poll_unlocked(pollfd* fds, int n, int timeout_ms) {
    void* state = before_wait ? before_wait() : nullptr;
    const int r = ::poll(fds, static_cast<nfds_t>(n), timeout_ms);
    const int saved = errno;
    if (after_wait) after_wait(state);
    errno = saved;
    return r;
}

int PilFrames::wait_input(int wait_ms) {
    pollfd fds[2] = {{config.sim_fd, POLLIN, 0}, {config.tel_fd, POLLIN, 0}};
    const int r = poll_unlocked(fds, 2, telemetry.empty() ? wait_ms
                                                          : std::min(wait_ms, config.quiet_ms));
    if (r < 0) return errno == EINTR ? kSignal : kPython;
    if (r == 0) return kIdle;
    if (fds[1].revents & POLLIN) return kUplink;
    if (fds[0].revents & (POLLIN | POLLHUP | POLLERR)) {
        char buf[4096];
        const ssize_t got = ::read(config.sim_fd, buf, sizeof buf);
        if (got > 0) {
            input.append(buf, static_cast<size_t>(got));
            bytes_read += static_cast<uint64_t>(got);
            return 0;
        }
        if (got < 0 && errno == EINTR) return kSignal;
        return kPython;                      // EIO, EOF: Python's reads see it
    }
    return kPython;
}

bool PilFrames::write_all(const std::string& bytes) {
    const auto t0 = std::chrono::steady_clock::now();
    size_t done = 0;
    while (done < bytes.size()) {
        const ssize_t n = ::write(config.sim_fd, bytes.data() + done, bytes.size() - done);
        if (n > 0) {
            done += static_cast<size_t>(n);
            continue;
        }
        if (n < 0 && errno != EAGAIN && errno != EWOULDBLOCK && errno != EINTR) return false;
        const auto waited = std::chrono::duration_cast<std::chrono::milliseconds>(
            std::chrono::steady_clock::now() - t0).count();
        if (waited > kWriteTimeoutMs) return false;
        pollfd out{config.sim_fd, POLLOUT, 0};
        poll_unlocked(&out, 1, 50);
    }
    return true;
}

// As DropIn.flush_telemetry: what fits without blocking; the rest waits.
void PilFrames::write_telemetry() {
    if (telemetry.empty()) return;
    const ssize_t n = ::write(config.tel_fd, telemetry.data(), telemetry.size());
    if (n > 0) telemetry.erase(0, static_cast<size_t>(n));
}

// As PilBoard.rc_pulses and Teensy35.rc_capture_pulses: every RC_FRAME_LOOPS frames, and at
// once when a channel changes, one pulse per channel with a signal, all rising on FTM3's next
// count, each ceil(us x counts per us) counts long.
void PilFrames::rc_pulses(const uint16_t* rc) {
    ++rc_age;
    const bool same =
        rc_last.size() == kRcChannels && std::equal(rc_last.begin(), rc_last.end(), rc);
    if (same && rc_age < kRcFrameLoops) return;
    rc_last.assign(rc, rc + kRcChannels);
    rc_age = 0;
    Core& c = core_;
    uint64_t rise = 0;
    bool any = false;
    for (size_t ch = 0; ch < kRcChannels; ++ch) any = any || rc[ch] > 0;
    if (!any || !c.ftm3.next_tick(c, c.now(), rise)) return;
    const auto hz = static_cast<int64_t>(std::nearbyint(c.ftm3.clock_hz(c)));
    const double rate = c.ftm3.ticks_per_cycle(c);
    const double per_tick = rate != 0.0 ? 1 / rate : 0.0;
    std::vector<PinEdges::Pin> rising;
    std::vector<std::pair<uint64_t, std::vector<PinEdges::Pin>>> falls;   // in first-seen order
    for (size_t ch = 0; ch < kRcChannels; ++ch) {
        if (rc[ch] == 0) continue;
        rising.push_back(config.rc_pins[ch]);
        const int64_t counts = (static_cast<int64_t>(rc[ch]) * hz + 999'999) / 1'000'000;
        uint64_t fall = 0;
        const auto width = static_cast<uint64_t>(static_cast<double>(counts) * per_tick);
        c.ftm3.next_tick(c, rise + width, fall);
        auto it = std::find_if(falls.begin(), falls.end(),
                               [&](const auto& g) { return g.first == fall; });
        if (it == falls.end()) {
            falls.push_back({fall, {}});
            it = falls.end() - 1;
        }
        it->second.push_back(config.rc_pins[ch]);
    }
    c.pin_edges.add(c, rise, true, std::move(rising));
    for (auto& [fall, group] : falls) c.pin_edges.add(c, fall, false, std::move(group));
}

// Runs on to the step's outputs (kToOutputs; passing the loop's end first) or to the loop's
// end: kOutputs or kLoopEnd, or kHandOver with `phase` and `code` set for Python.
PilFrames::Reached PilFrames::run_to(Phase to) {
    Core& c = core_;
    const uint64_t limit = start_limit(c.cycles_after(config.loop_limit_s, c.now()));
    Reached reached = Reached::kHandOver;
    int r = 0;
    for (;;) {
        r = c.run(uint64_t{1} << 62);
        if (r != kStopAt) break;
        const uint32_t pc = c.stop_at_pc();
        if (pc == config.outputs_at) {
            if (to == kToOutputs) {
                reached = Reached::kOutputs;
                break;
            }
            continue;
        }
        if (pc == config.wait_at || (config.card_wait_at && pc == config.card_wait_at)) {
            ++waits;
            in_card_wait = pc == config.card_wait_at;
            reached = Reached::kLoopEnd;
        }
        break;                           // the loop's end, or another stop (Python's)
    }
    end_limit(limit);
    if (reached == Reached::kHandOver) {
        phase = to;
        code = r;
    }
    return reached;
}

void PilFrames::encode_reply(const SensorFrame& f) {
    Core& c = core_;
    uint8_t report[kReportSize];
    c.mem_read(config.report_address, report, sizeof report);
    const uint8_t armed = report[12], mode = report[13], kind = report[14];
    const size_t rotors = std::min<size_t>(report[16], kMotors);
    mavlink_hq_actuator_frame_t a{};
    a.time_us = f.m.time_us;
    a.frame = f.m.frame;
    const double lo = config.esc_lo, hi = config.esc_hi;
    for (size_t ch = 0; ch < rotors; ++ch) {
        uint32_t counts = 0;
        const double t = c.ftm0.commanded_value(c, static_cast<int>(ch), counts)
                             ? std::min(1.0, std::max(0.0, (counts - lo) / (hi - lo))) : 0.0;
        a.motor[ch] = static_cast<float>(t);
    }
    a.motor_count = static_cast<uint8_t>(rotors);
    a.armed = armed ? 1 : 0;
    a.mode = mode;
    a.sensor_kind = kind;
    mavlink_status_t status{};
    status.current_tx_seq = seq;
    mavlink_message_t msg;
    mavlink_msg_hq_actuator_frame_encode_status(config.system_id, config.component_id, &status,
                                                &msg, &a);
    seq = status.current_tx_seq;
    uint8_t out[MAVLINK_MAX_PACKET_LEN];
    const uint16_t n = mavlink_msg_to_send_buffer(out, &msg);
    reply.assign(reinterpret_cast<const char*>(out), n);
}

// As PilBoard._drain: the board runs on (it sleeps) until what it queued for its link has
// left, at most drain_limit_s and never closer than drain_margin_s to the next SysTick (none
// at all with that tick pending: the loop overran).
bool PilFrames::drain() {
    Core& c = core_;
    constexpr int kSysTick = 15;
    if ((c.pending_ >> kSysTick) & 1 || c.systick.zero_at < 0) return true;
    const double hz = c.core_hz();
    const uint64_t start = c.now();
    const auto margin = static_cast<int64_t>(config.drain_margin_s * hz);
    const int64_t deadline = std::min(static_cast<int64_t>(start) +
                                          static_cast<int64_t>(config.drain_limit_s * hz),
                                      c.systick.zero_at - margin);
    if (deadline <= static_cast<int64_t>(start)) return true;
    const double seconds = static_cast<double>(deadline - static_cast<int64_t>(start)) / hz;
    const uint64_t until = c.cycles_after(seconds, c.cycles_);
    const uint64_t limit = start_limit(until);
    c.drain_ = config.usb ? Core::kDrainUsb : Core::kDrainUart;
    c.drain_after_ = config.usb ? start : 0;
    const int r = c.run(uint64_t{1} << 62);
    end_limit(limit);
    c.drain_ = Core::kNoDrain;
    c.drain_after_ = 0;
    if (r == kStopAt) {                  // as PilBoard._waited
        ++waits;
        in_card_wait = config.card_wait_at && c.stop_at_pc() == config.card_wait_at;
        return true;
    }
    if (r == kDrained || r == kTime) return true;
    phase = kDrain;
    code = r;
    drain_until = until;
    drain_after = config.usb ? start : 0;
    return false;
}

// The runs that follow end at core cycle `until` at the latest (as Machine.run's time limit):
// the limit's event, and the run's stop and time-up flags cleared.
uint64_t PilFrames::start_limit(uint64_t until) {
    Core& c = core_;
    const uint64_t limit = c.at(until, Ev::TimeLimit, true);
    c.time_up_ = false;
    c.clear_stop();
    return limit;
}

void PilFrames::end_limit(uint64_t limit) {
    core_.cancel(limit);
    core_.time_up_ = false;
}

// As PilBoard._collect_telemetry and end_frame's record of the step's cycles.
void PilFrames::collect() {
    Core& c = core_;
    c.uart0.catch_up(c, c.now());
    if (config.usb) {                    // UART0's bytes leave on pins nothing listens to
        c.uart0.sent.clear();
        telemetry += c.usb0.host.received;
        c.usb0.host.received.clear();
    } else {
        telemetry += c.uart0.take_sent_bytes();
    }
    uint8_t report[kReportSize];
    c.mem_read(config.report_address, report, sizeof report);
    step_cycles.push_back(u32(report + 4));
}

int PilFrames::serve(int wait_ms, uint64_t max_frames) {
    Core& c = core_;
    const size_t mpu = config.mpu;
    if (mpu >= c.owned_slaves.size() || c.log_all || !config.outputs_at) return kPython;
    for (uint64_t done = 0; done < max_frames;) {
        size_t total = 0, payload_len = 0;
        const Packet p = next_packet(total, payload_len);
        if (p == Packet::kPython) return kPython;
        if (p == Packet::kMore) {
            const int w = wait_input(wait_ms);
            if (w) return w;
            continue;
        }
        SensorFrame f;
        const auto* b = reinterpret_cast<const uint8_t*>(input.data());
        if (!plain(b + kHeader, payload_len, f)) return kPython;
        input.erase(0, total);
        last_frame = f.m.frame;
        frame_time_us = f.m.time_us;
        frame_sync = f.m.sync != 0;
        ++frames;
        ++done;
        // begin_frame: the inputs, then the board to the step's outputs
        const size_t fifo_len = std::min<size_t>(f.m.fifo_len, sizeof f.m.fifo);
        if (fifo_len) {
            c.owned_slaves[mpu]->emu->push_fifo(f.m.fifo, fifo_len,
                                                f.m.fifo_kind == HQ_SENSOR_DMP);
        }
        rc_pulses(f.m.rc_us);
        const Reached outputs = run_to(kToOutputs);
        if (outputs == Reached::kHandOver) return kMidFrame;
        encode_reply(f);
        // end_frame: the rest of the loop while the simulator integrates, except after a
        // sync frame, whose telemetry goes first
        if (!frame_sync && !write_all(reply)) return kLinkFailed;
        if (outputs == Reached::kOutputs && run_to(kToLoopEnd) == Reached::kHandOver) {
            return kMidFrame;
        }
        if (frame_sync && !in_card_wait && !drain()) return kMidFrame;
        collect();
        if (frame_sync) {
            write_telemetry();
            if (!write_all(reply)) return kLinkFailed;
        } else if (telemetry.size() >= config.telemetry_chunk) {
            write_telemetry();
        }
        if (c.ftfe.changes != ftfe_changes) return kKeep;
    }
    return kFrames;
}

}  // namespace hqsim::mk64
