// The processor-in-the-loop drop-in's plain frames, natively (sim/chip/pil/drop_in.py serves
// the rest and says which frames are plain). A plain frame is the next HQ_SENSOR_FRAME in
// order, with no IMU fault, no uplink waiting and nothing unusual on the board: its FIFO
// bytes into the MPU6050, its RC pulses as PilBoard.rc_pulses makes them, the board run to
// its step's outputs, the reply written, the rest of the loop run to its end, the telemetry
// collected and written in chunks; a sync frame's reply after the loop's end, the link's
// drain (PilBoard._drain) and its telemetry: exactly as the Python path does each step.
// Anything else hands over to Python at once: a frame that is not plain before it is
// consumed, a run that stopped for anything but the loop's own stops in the middle of its
// frame (Python finishes that frame from there: PilBoard's phase and the run's code).
#pragma once

#include <poll.h>

#include <cstddef>
#include <cstdint>
#include <string>
#include <vector>

#include "chip/mk64_core.hpp"

namespace hqsim::mk64 {

struct SensorFrame;                       // an HQ_SENSOR_FRAME, decoded (pil_frames.cpp)

class PilFrames {
public:
    // Why serve() returned.
    enum Reason : int {
        kPython = 1,      // `input` starts with bytes for Python (a frame that is not plain)
        kIdle = 2,        // no input on the sim link within the wait, or within quiet_ms
                          // with telemetry waiting (Python's idle rules: the flush)
        kUplink = 3,      // the telemetry link has bytes from the tool
        kSignal = 4,      // a signal interrupted the wait
        kLinkFailed = 5,  // the reply could not be written
        kMidFrame = 6,    // a run stopped for Python in the middle of a frame (phase, code)
        kKeep = 7,        // the flash's stored records changed in the frame just done
        kFrames = 8,      // max_frames frames done
    };
    enum Phase : int { kToOutputs = 1, kToLoopEnd = 2, kDrain = 3 };

    struct Config {
        int sim_fd = -1, tel_fd = -1;
        uint32_t outputs_at = 0, wait_at = 0, card_wait_at = 0;   // 0: none
        uint32_t report_address = 0;
        size_t mpu = 0;                       // Core::owned_slaves index
        bool usb = true;                      // telemetry from the USB host, else UART0
        bool rc_native = false;               // rc_pins drive the receiver's pulses
        std::vector<PinEdges::Pin> rc_pins;   // per RC channel
        uint32_t esc_lo = 0, esc_hi = 0;      // FTM0 counts of zero and full thrust
        double loop_limit_s = 2.0;            // emulated time a loop may take
        double drain_limit_s = 0.004;         // a sync frame's drain, at most
        double drain_margin_s = 20e-6;        // ... ending this long before the next SysTick
        uint8_t system_id = 1, component_id = 1;
        size_t telemetry_chunk = 1024;
        int quiet_ms = 1;                     // telemetry waits no longer for a quiet link
    };

    explicit PilFrames(Core& core) : core_(core) {}
    Config config;
    // Called around each wait on a descriptor (the bindings let other Python threads run
    // meanwhile); null: nothing.
    void* (*before_wait)() = nullptr;
    void (*after_wait)(void*) = nullptr;

    // The state it shares with the Python path (read back and set by drop_in.py).
    uint32_t last_frame = 0;
    uint64_t frames = 0;                      // frames handled here
    uint8_t seq = 0;                          // the replies' MAVLink sequence
    std::vector<uint16_t> rc_last;            // PilBoard._rc_last (empty: none)
    int rc_age = 0;
    uint64_t ftfe_changes = 0;
    uint32_t waits = 0;
    bool in_card_wait = false;
    std::string input;                        // sim-link bytes not consumed yet
    uint64_t bytes_read = 0;                  // read from the sim link, ever
    std::string telemetry;                    // collected, not yet written
    std::string reply;                        // the last reply's bytes
    std::vector<uint32_t> step_cycles;        // each frame's, until taken
    // A hand-over in the middle of a frame: where it was and what the run returned, and the
    // frame's time and counter (for the reply, when it was still to come).
    int phase = 0, code = 0;
    uint64_t frame_time_us = 0;
    bool frame_sync = false;
    uint64_t drain_until = 0, drain_after = 0;    // a drain handed over: its end, its start

    // Plain frames until Python is needed (or max_frames are done): the Reason. `wait_ms`:
    // how long to wait for sim-link input before kIdle.
    int serve(int wait_ms, uint64_t max_frames);

private:
    enum class Packet { kFrame, kPython, kMore };
    Packet next_packet(size_t& total, size_t& payload_len) const;
    bool plain(const uint8_t* payload, size_t len, SensorFrame& f) const;
    int wait_input(int wait_ms);
    int poll_unlocked(pollfd* fds, int n, int timeout_ms);
    bool write_all(const std::string& bytes);
    void write_telemetry();
    void rc_pulses(const uint16_t* rc);
    enum class Reached { kOutputs, kLoopEnd, kHandOver };
    Reached run_to(Phase to);
    uint64_t start_limit(uint64_t until);
    void end_limit(uint64_t limit);
    void encode_reply(const SensorFrame& f);
    void collect();
    // PilBoard._drain: false when handed over (kDrain, code).
    bool drain();

    Core& core_;
};

}  // namespace hqsim::mk64
