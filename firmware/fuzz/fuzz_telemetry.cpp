// libFuzzer target: the firmware's telemetry command path. A FlightController on the emulated
// MPU6050 gets fuzz-chosen bytes on its telemetry link (any message of the dialect, framed
// with a correct CRC, with any length; raw bytes; well-formed commands with fuzzed fields:
// HEARTBEAT, arm/disarm and the other commands it answers, SET_MODE, HQ_EXCITATION (sines and
// multisines), the parameter protocol with real names), fuzzed RC inputs, IMU data and IMU
// faults, a fuzzed parameter store, and runs loops between them. Besides the sanitizers,
// every loop checks the rules a pilot relies on: motors off unless armed, never an
// excitation while disarmed nor beyond its declared peak, motor commands finite and within
// 0..1, every parameter within its range.
//
//   build: cmake -S firmware -B build/fuzz -DCMAKE_CXX_COMPILER=clang++ -DHQ_FUZZ=ON
//   run:   build/fuzz/fuzz_telemetry CORPUS -max_total_time=60   (or tests/fuzz/run.py)
#include <cmath>
#include <cstdlib>

#include "core/flight_controller.hpp"
#include "fuzz_input.hpp"
#include "sensor/mpu6050_emulator.hpp"
#include "targets/host/clock.hpp"
#include "targets/host/motors.hpp"

namespace {

using hqfuzz::Reader;

// The telemetry link: commands queued by the harness come out of read(); what the firmware
// sends is counted and dropped, and the link is full whenever the input says so.
class FuzzSerial final : public hq::SerialPort {
public:
    size_t read(uint8_t* data, size_t n) override {
        size_t k = 0;
        while (k < n && head_ < count_) data[k++] = buf_[head_++];
        return k;
    }
    size_t write(const uint8_t*, size_t n) override { return full_ ? 0 : n; }
    void push(const uint8_t* data, size_t n) {
        if (head_ == count_) head_ = count_ = 0;
        for (size_t i = 0; i < n && count_ < sizeof buf_; ++i) buf_[count_++] = data[i];
    }
    void set_full(bool full) { full_ = full; }

private:
    uint8_t buf_[4096];
    size_t head_ = 0, count_ = 0;
    bool full_ = false;
};

constexpr uint64_t kLoopUs = 5000;
// The host's ids: a ground station's.
constexpr uint8_t kGcs = MAV_COMP_ID_MISSIONPLANNER;
constexpr int kMaxLoops = 48;              // per input: keeps executions fast

void check_rules(const hq::FlightController& fc, const hq::HostMotors& motors) {
    const float* m = motors.values();
    for (int i = 0; i < hq::kMaxRotors; ++i) {
        if (!std::isfinite(m[i]) || m[i] < 0.0f || m[i] > 1.0f) std::abort();
        if (!fc.armed() && m[i] != 0.0f) std::abort();
    }
    if (!fc.armed() && fc.supervisor().excitation().active()) std::abort();
    if (!fc.armed() && fc.state().excitation != 0.0f) std::abort();
    // Never beyond the bound of its injection point, nor a multisine's declared peak.
    const hq::ExcitationConfig& exc = fc.supervisor().excitation_config();
    if (fc.state().excitation != 0.0f &&
        !(std::fabs(fc.state().excitation) <=
          exc.amplitude * (1.0f + hq::Excitation::kPeakMargin))) {
        std::abort();
    }
    if (!hqfuzz::params_in_range(fc.params())) std::abort();
}

// The commands the firmware answers, for COMMAND_LONG with fuzzed parameters.
constexpr uint16_t kCommands[] = {MAV_CMD_COMPONENT_ARM_DISARM, MAV_CMD_DO_SET_MODE,
                                  MAV_CMD_SET_MESSAGE_INTERVAL, MAV_CMD_GET_MESSAGE_INTERVAL,
                                  MAV_CMD_REQUEST_MESSAGE, MAV_CMD_REQUEST_AUTOPILOT_CAPABILITIES,
                                  MAV_CMD_PREFLIGHT_STORAGE};

// A PARAM_SET of a real parameter, the value inside its range, at an edge, or any float.
void param_set(Reader& in, mavlink_status_t& tx, mavlink_message_t& msg) {
    const int index = in.u8() % hq::kParamCount;
    const hq::ParamInfo& p = hq::param_info(index);
    char name[hq::kParamNameLen] = {};
    for (size_t i = 0; i < hq::kParamNameLen && p.name[i] != '\0'; ++i) name[i] = p.name[i];
    const uint8_t how = in.u8();
    const float value = how % 3 == 0 ? in.f32()
                        : how % 3 == 1 ? p.min + (p.max - p.min) * (in.u8() / 255.0f)
                                       : ((how & 8) ? p.max : p.min);
    mavlink_msg_param_set_pack_status(255, kGcs, &tx, &msg, 1, MAV_COMP_ID_AUTOPILOT1, name, value,
                                      MAV_PARAM_TYPE_REAL32);
}


// A command with fuzzed fields but the right shape, so deep states (armed, exciting) are
// reachable: the fuzzer only has to find field values, not checksums.
size_t command_packet(Reader& in, uint8_t* out, mavlink_status_t& tx) {
    mavlink_message_t msg;
    switch (in.u8() % 7) {
        case 5:
            param_set(in, tx, msg);
            break;
        case 6:
            if (in.u8() & 1) {
                mavlink_msg_param_request_list_pack_status(255, kGcs, &tx, &msg, 1, 0);
            } else {
                const char by_index[hq::kParamNameLen] = {};     // the packer copies all 16
                mavlink_msg_param_request_read_pack_status(255, kGcs, &tx, &msg, 1, 0, by_index,
                                                           static_cast<int16_t>(in.u16()));
            }
            break;
        case 0:
            mavlink_msg_heartbeat_pack_status(255, kGcs, &tx, &msg, MAV_TYPE_GCS,
                                              MAV_AUTOPILOT_INVALID, 0, 0, 0);
            break;
        case 1: {
            const uint8_t target = in.u8() & 1 ? 1 : in.u8();
            const uint8_t pick = in.u8();
            const uint16_t command = pick & 1 ? kCommands[(pick >> 1) % (sizeof kCommands / sizeof kCommands[0])]
                                              : in.u16();
            mavlink_msg_command_long_pack_status(255, kGcs, &tx, &msg, target,
                                                 MAV_COMP_ID_AUTOPILOT1, command, 0, in.f32(),
                                                 in.f32(), 0, 0, 0, 0, 0);
            break;
        }
        case 2:
            // Every HQ_MODE, and 0 and one above, which are refused.
            mavlink_msg_set_mode_pack_status(255, kGcs, &tx, &msg, 1,
                                             MAV_MODE_FLAG_CUSTOM_MODE_ENABLED,
                                             in.u8() % (HQ_MODE_ENUM_END + 1));
            break;
        default: {
            const uint8_t axis = in.u8(), injection = in.u8(), action = in.u8();
            const float freq = (axis & 0x80) ? in.f32() : 0.5f + (in.u8() % 40) * 0.25f;
            const float amp = (injection & 0x80) ? in.f32() : (in.u8() % 100) * 0.01f;
            const uint8_t cycles = in.u8() % 8, fade = in.u8() % 3;
            // A sine, a multisine (lines in order or not, any float amplitude and phase, a
            // gap before the last), a chirp of either law, or an unknown signal.
            const uint8_t signal = in.u8() % (HQ_SIGNAL_ENUM_END + 1);
            uint16_t orders[hq::kMaxHarmonics] = {};
            float amps[hq::kMaxHarmonics] = {}, phases[hq::kMaxHarmonics] = {};
            const int lines = signal == HQ_SIGNAL_MULTISINE ? in.u8() % (hq::kMaxHarmonics + 1) : 0;
            for (int i = 0; i < lines; ++i) {
                const uint8_t how = in.u8();
                orders[i] = static_cast<uint16_t>((how & 0x80) ? in.u8() * 256 + in.u8()
                                                               : 1 + i * (1 + how % 4));
                amps[i] = (how & 0x40) ? in.f32() : (in.u8() % 50) * 0.01f;
                phases[i] = (how & 0x20) ? in.f32() : (in.u8() % 64) * 0.1f;
            }
            // A chirp's stop frequency and sweep: any float, or one in or near the band.
            const bool chirp = signal == HQ_SIGNAL_CHIRP || signal == HQ_SIGNAL_CHIRP_LINEAR;
            const float stop = !chirp ? 0.0f
                               : (in.u8() & 1) ? in.f32() : 0.05f + (in.u8() % 64) * 0.8f;
            const float sweep = !chirp ? 0.0f : (in.u8() & 1) ? in.f32() : 1.0f + in.u8() * 2.0f;
            // Every axis and injection point, and one unknown of each.
            mavlink_msg_hq_excitation_pack_status(
                255, kGcs, &tx, &msg, 1, MAV_COMP_ID_AUTOPILOT1,
                action % HQ_EXCITATION_ACTION_ENUM_END, axis % (HQ_AXIS_ENUM_END + 1),
                injection % (HQ_INJECTION_ENUM_END + 1), freq, amp, cycles, fade, signal, orders,
                amps, phases, stop, sweep);
            break;
        }
    }
    return mavlink_msg_to_send_buffer(out, &msg);
}

// One HQ_IMU_FAULT, as the host build's sim link applies it (no bus timing: a stuck bus fails
// every transfer, as a missing chip does).
void imu_fault(Reader& in, hq::Mpu6050Emulator& chip) {
    const uint8_t fault = in.u8() % HQ_IMU_FAULT_ENUM_END;
    chip.set_present(fault != HQ_IMU_FAULT_NACK && fault != HQ_IMU_FAULT_STUCK_BUS);
    chip.set_silent(fault == HQ_IMU_FAULT_SILENT);
    if (fault == HQ_IMU_FAULT_RESET) chip.power_on_reset();
    if (fault == HQ_IMU_FAULT_OVERFLOW) chip.force_overflow();
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
    Reader in(data, size);
    hqfuzz::Vehicle<FuzzSerial> v(in);
    hq::RcInput rc;
    const uint16_t rest[hq::kRcChannels] = {1500, 1500, 1000, 1500, 1000, 1000, 0, 0};
    for (int c = 0; c < hq::kRcChannels; ++c) rc.channel_us[c] = rest[c];
    rc.age_us = 0;
    mavlink_status_t tx{};
    uint8_t packet[hqfuzz::kMaxPacket];
    uint8_t seq = 0;
    int loops = 0;
    while (!in.done() && loops < kMaxLoops) {
        switch (in.u8() % 7) {
            case 0:
                v.telemetry.push(packet, hqfuzz::any_packet(in, packet, seq++));
                break;
            case 1: {
                uint8_t raw[64];
                v.telemetry.push(raw, in.bytes(raw, in.u8() % sizeof raw));
                break;
            }
            case 2:
                v.telemetry.push(packet, command_packet(in, packet, tx));
                break;
            case 3: {
                const uint8_t ch = in.u8() % hq::kRcChannels;
                rc.channel_us[ch] = static_cast<uint16_t>(in.u16() % 2200);
                rc.age_us = (in.u8() & 7) == 0 ? in.u32() : 0;
                break;
            }
            case 4:
                imu_fault(in, v.chip);
                break;
            case 5:
                v.telemetry.set_full(in.u8() & 1);
                break;
            default: {
                const int n = 1 + in.u8() % 8;
                for (int i = 0; i < n && loops < kMaxLoops; ++i, ++loops) {
                    const uint8_t step = in.u8();
                    v.clock.set(v.clock.micros() + (step == 0xFF ? in.u32() : kLoopUs));
                    uint8_t sample[hq::mpu6050::kDmpPacketSize];
                    in.bytes(sample, sizeof sample);
                    v.chip.push_fifo(sample, v.chip.dmp_enabled() ? hq::mpu6050::kDmpPacketSize
                                                              : hq::mpu6050::kRawPacketSize,
                                   v.chip.dmp_enabled());
                    v.step(rc);
                    check_rules(v.fc, v.motors);
                }
                break;
            }
        }
    }
    return 0;
}
