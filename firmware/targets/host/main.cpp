// heliquad-fw-host: the firmware's host build, driven in lockstep by the simulator.
//
//   heliquad-fw-host --sim-link PATH --telemetry PATH [--loop-hz 200] [--dmp-image FILE]
//                    [--idle-timeout-s 10] [--params FILE] [--program FILE]
//                    [--telemetry-backlog-bytes N]
//
// --telemetry-backlog-bytes N bounds what waits for a reader on the telemetry pty (default
// 0: unbounded, for the lockstep simulator): when nobody reads, the oldest bytes are dropped,
// as a board's USB or UART buffer holds a few KiB, not seconds (heliquad board uses it).
//
// Parameters (the MAVLink parameter protocol, docs/parameters.md) persist in --params FILE,
// created at the first save; without it every start has the defaults and nothing is saved.
// The on-board program (core/program.hpp) persists in --program FILE the same way (its own
// record in its own file: a program and the parameters are saved at different times, and
// either survives the other's damage); without it a program is kept until the process ends.
//
// DMP firmware (the MotionApps image and its tables, a file made with `heliquad dmp-image`):
// --dmp-image FILE, else the one compiled in with -DHQ_DMP_IMAGE, else none (the raw FIFO
// path). A bad file, or a bare image of the old format, is refused with one line (exit 2).
//
// Creates two pseudo-terminals and publishes their slave devices as PATH symlinks:
//   sim link:  HQ_SENSOR_FRAME in (time, frame counter, MPU6050 FIFO bytes, RC), exactly one
//              HQ_ACTUATOR_FRAME out per frame (same time and counter, five motor outputs);
//   telemetry: what the Teensy sends over USB serial (telemetry out, commands in).
// Prints "ready" on stdout when both exist. Each sensor frame sets the clock, the frame's FIFO
// bytes go into the emulated MPU6050, and one FlightController step runs. A repeated frame
// counter gets the previous reply again without a step; a gap is counted and reported. With
// no frame for the idle timeout, or on SIGINT/SIGTERM, it exits cleanly (links removed).
#include <chrono>
#include <csignal>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <fstream>
#include <iterator>
#include <string>
#include <vector>

#include "../../core/flight_controller.hpp"
#include "../../core/link/gcs_link.hpp"
#include "../../hal/reset_cause.hpp"
#include "../dmp_image.hpp"
#include "clock.hpp"
#include "i2c.hpp"
#include "motors.hpp"
#include "param_storage.hpp"
#include "sensor/mpu6050_emulator.hpp"
#include "serial.hpp"
#include "sim_link_handler.hpp"

namespace {

volatile std::sig_atomic_t g_stop = 0;   // the one global: signal handlers need one
void on_signal(int) { g_stop = 1; }

// With no sensor frame for this long, the build exits (--idle-timeout-s), s.
constexpr int kIdleTimeoutS = 10;

struct Options {
    std::string sim_link, telemetry, dmp_image, params, program;
    float loop_hz = hq::kLoopRateHz;
    int idle_timeout_s = kIdleTimeoutS;
    long telemetry_backlog_bytes = 0;
};

[[noreturn]] void usage(const char* msg) {
    std::fprintf(stderr,
                 "heliquad-fw-host: %s\nusage: heliquad-fw-host --sim-link PATH --telemetry PATH "
                 "[--loop-hz %g] [--dmp-image FILE] [--idle-timeout-s %d] [--params FILE] "
                 "[--program FILE] [--telemetry-backlog-bytes N]\n",
                 msg, static_cast<double>(hq::kLoopRateHz), kIdleTimeoutS);
    std::exit(2);
}

Options parse(int argc, char** argv) {
    Options o;
    for (int i = 1; i < argc; ++i) {
        const std::string a = argv[i];
        if (a == "--help" || a == "-h") usage("firmware-in-the-loop host build");
        if (i + 1 >= argc) usage(("missing value for " + a).c_str());
        const char* v = argv[++i];
        if (a == "--sim-link") o.sim_link = v;
        else if (a == "--telemetry") o.telemetry = v;
        else if (a == "--dmp-image") o.dmp_image = v;
        else if (a == "--params") o.params = v;
        else if (a == "--program") o.program = v;
        else if (a == "--loop-hz") o.loop_hz = std::strtof(v, nullptr);
        else if (a == "--idle-timeout-s") o.idle_timeout_s = std::atoi(v);
        else if (a == "--telemetry-backlog-bytes") o.telemetry_backlog_bytes = std::atol(v);
        else usage(("unknown option " + a).c_str());
    }
    if (o.sim_link.empty() || o.telemetry.empty()) usage("--sim-link and --telemetry are required");
    if (!(o.loop_hz > 0.0f && o.loop_hz <= hq::kMaxLoopRateHz)) {
        char msg[48];
        std::snprintf(msg, sizeof msg, "--loop-hz must be in (0, %g]",
                      static_cast<double>(hq::kMaxLoopRateHz));
        usage(msg);
    }
    if (o.idle_timeout_s <= 0) usage("--idle-timeout-s must be positive");
    if (o.telemetry_backlog_bytes < 0) usage("--telemetry-backlog-bytes must not be negative");
    return o;
}

// Telemetry is written to its pty in chunks of this size, after a `sync` frame, or when the
// sim link has been quiet for kTelemetryQuietUs (a full-speed USB CDC device ships its
// buffer every 1 ms frame).
constexpr size_t kTelemetryChunk = 1024;
constexpr long kTelemetryQuietUs = 1000;
constexpr long kIdlePollUs = 100000;
// A reply may wait this long for room on the sim link's pty (the simulator reads it at once).
constexpr int kReplyTimeoutMs = 5000;

// Replies go straight to the sim link's pty; a `sync` frame also ships the telemetry.
class SimLinkPty final : public hq::SimLinkReplies {
public:
    SimLinkPty(hq::PtySerial& sim, hq::PtySerial& telemetry) : sim_(sim), telemetry_(telemetry) {}
    bool reply(const uint8_t* packet, size_t n, bool sync) override {
        if (!sim_.write_all(packet, n, kReplyTimeoutMs)) return false;
        if (sync) telemetry_.flush();
        return true;
    }

private:
    hq::PtySerial& sim_;
    hq::PtySerial& telemetry_;
};

}  // namespace

int main(int argc, char** argv) {
    const Options opt = parse(argc, argv);
    std::signal(SIGINT, on_signal);
    std::signal(SIGTERM, on_signal);
    std::signal(SIGPIPE, SIG_IGN);

    std::vector<uint8_t> dmp_file;             // the DMP firmware file (heliquad dmp-image)
    if (!opt.dmp_image.empty()) {
        std::ifstream f(opt.dmp_image, std::ios::binary);
        if (!f) usage(("cannot read DMP image " + opt.dmp_image).c_str());
        dmp_file.assign(std::istreambuf_iterator<char>(f), std::istreambuf_iterator<char>());
    }

    static hq::PtySerial sim, telemetry;        // 64 KiB buffers each: not on the stack
    if (!sim.open(opt.sim_link)) usage(sim.error().c_str());
    if (!telemetry.open(opt.telemetry)) usage(telemetry.error().c_str());
    telemetry.bound_backlog(static_cast<size_t>(opt.telemetry_backlog_bytes));

    hq::HostClock clock;
    hq::HostMotors motors;
    static hq::Mpu6050Emulator chip;
    hq::FlightControllerConfig cfg;
    cfg.loop_rate_hz = opt.loop_hz;
    hq::GcsLinkConfig link_cfg;
    link_cfg.loop_rate_hz = opt.loop_hz;
    // The host build has no chip id: a fixed stand-in, "HQ-HOST" and 1, so a ground station
    // that keys on AUTOPILOT_VERSION.uid sees one stable, non-zero vehicle.
    link_cfg.uid = 0x4851'2D48'4F53'5401ull;
    static hq::FileParamStorage storage(opt.params);
    if (!opt.params.empty()) cfg.storage = &storage;
    static hq::FileParamStorage program_storage(opt.program);
    if (!opt.program.empty()) cfg.program_storage = &program_storage;
    cfg.reset_cause = hq::reset_cause();         // power-on: a process starts afresh
    if (!opt.dmp_image.empty()) {              // --dmp-image wins over a built-in image
        if (const char* bad = hq::use_dmp_file(dmp_file.data(), dmp_file.size(), cfg.imu)) {
            usage((opt.dmp_image + ": " + bad).c_str());
        }
    } else {
        hq::use_built_in_dmp(cfg.imu);
    }
    // The emulated chip runs the DMP firmware the driver was given (docs/mpu6050.md).
    chip.set_dmp_reference(cfg.imu.dmp_image, cfg.imu.dmp_image_size, cfg.imu.dmp_config,
                           cfg.imu.dmp_config_size, cfg.imu.dmp_updates, cfg.imu.dmp_updates_size);
    hq::HostI2cBus bus;
    bus.attach(hq::mpu6050::kAddress, chip);
    hq::FlightController fc(cfg, bus, clock, motors);
    static hq::LoopInbox inbox;                                   // not on the stack
    static hq::GcsLink link(link_cfg, telemetry, inbox);   // nor its queues
    const hq::InitResult init = fc.init();
    link.send_notices(fc.status());
    std::printf("sim link: %s -> %s\ntelemetry: %s -> %s\nimu: %s\nready\n", opt.sim_link.c_str(),
                sim.slave_path().c_str(), opt.telemetry.c_str(), telemetry.slave_path().c_str(),
                init == hq::InitResult::OkDmp ? "dmp" : "raw");
    std::fflush(stdout);

    SimLinkPty replies(sim, telemetry);
    hq::SimLinkHandler handler(fc, link, clock, chip, motors, link_cfg.system_id,
                              link_cfg.component_id);
    using Wall = std::chrono::steady_clock;   // the idle timeout only; never the core's clock
    Wall::time_point last_input = Wall::now();
    int exit_code = 0;
    uint8_t buf[512];

    // What init() sent (the parameters' and the IMU's start-up messages) waits for the first
    // frame: the simulator opens the telemetry port before it steps, and opening a serial
    // port discards what was already waiting there.
    bool stepped = false;
    while (!g_stop) {
        // Telemetry ships as a USB CDC device ships it: in chunks, once a chunk is buffered,
        // after a frame marked `sync` (the simulator pauses to read it), or when the sim link
        // has been quiet for a moment. Fewer, larger writes keep the lockstep fast.
        if (telemetry.buffered() >= kTelemetryChunk) telemetry.flush();
        const long wait_us = telemetry.buffered() && stepped ? kTelemetryQuietUs : kIdlePollUs;
        // Telemetry input (commands) is polled in the same call unless it is already known
        // to be waiting for the next step.
        if (!sim.wait_readable_us(wait_us, telemetry.input_pending() ? nullptr : &telemetry)) {
            if (stepped) telemetry.flush();
            if (Wall::now() - last_input >= std::chrono::seconds(opt.idle_timeout_s)) {
                std::fprintf(stderr, "heliquad-fw-host: no sensor frame for %d s; exiting\n",
                             opt.idle_timeout_s);
                exit_code = 3;
                break;
            }
            continue;
        }
        last_input = Wall::now();
        stepped = true;
        const size_t n = sim.read(buf, sizeof(buf));
        const uint32_t lost_before = handler.lost();
        if (!handler.feed(buf, n, replies)) {
            std::fprintf(stderr, "heliquad-fw-host: sim link write failed; exiting\n");
            exit_code = 4;
            break;
        }
        if (handler.lost() != lost_before) {
            std::fprintf(stderr, "heliquad-fw-host: %u sensor frame(s) lost by frame %u\n",
                         handler.lost() - lost_before, handler.last_frame());
        }
    }
    telemetry.flush();
    std::fprintf(stderr,
                 "heliquad-fw-host: %u loops, %u frames lost, %u repeated, %u telemetry bytes "
                 "dropped, %zu unread telemetry bytes dropped\n",
                 fc.loops(), handler.lost(), handler.repeated(), link.telemetry_dropped(),
                 telemetry.discarded());
    sim.close();
    telemetry.close();
    return exit_code;
}
