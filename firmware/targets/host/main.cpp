// heliquad-fw-host: the firmware's host build, driven in lockstep by the simulator.
//
//   heliquad-fw-host --sim-link PATH --telemetry PATH [--loop-hz 200] [--dmp-image FILE]
//                    [--idle-timeout-s 10] [--params FILE] [--program FILE]
//                    [--telemetry-backlog-bytes N] [--sd-image FILE [--sd-faults NAME=VALUE,...]]
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
// The SD card (docs/sd-card.md): --sd-image FILE is the card, a card-image file; one that does
// not exist is made first, FAT32 at the default size (card_image.hpp); without it the board
// has no card. The card's state follows the IMU's start-up line ("card: ok", "card: no card",
// "card: write-protected", "card: full", "card: failed"). --sd-faults sets the image's faults
// (block_device.hpp's names, e.g. busy_after_write_us=250000,write_protected=1; a name alone
// is 1), the busy ones in force from the first sensor frame on, the others from the start. Every card access runs in the spare-time service after a
// step's reply; while it waits for a busy card, the next sensor frames are served (each with
// its step and reply) from inside the wait, so the card never holds up the loop. With a
// card the board logs each arming to it (core/log/logger.hpp) and serves its logs over the
// MAVLink log protocol (core/link/log_transfer.hpp, docs/ground-stations.md).
//
// DMP firmware (the MotionApps image and its tables, a file made with `heliquad dmp-image`):
// --dmp-image FILE, else the one compiled in with -DHQ_DMP_IMAGE, else none (the raw FIFO
// path). A bad file, or a bare image of the old format, is refused with one line (exit 2).
//
// Creates two pseudo-terminals and publishes their slave devices as PATH symlinks:
//   sim link:  HQ_SENSOR_FRAME in (time, frame counter, MPU6050 FIFO bytes, RC), exactly one
//              HQ_ACTUATOR_FRAME out per frame (same time and counter, the motor outputs
//              and their count);
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

#include <sys/stat.h>
#include <unistd.h>

#include "../../core/flight_controller.hpp"
#include "../../core/link/gcs_link.hpp"
#include "../../core/log/spare_tasks.hpp"
#include "../../hal/reset_cause.hpp"
#include "../dmp_image.hpp"
#include "block_device.hpp"
#include "card_image.hpp"
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
    std::string sim_link, telemetry, dmp_image, params, program, sd_image, sd_faults;
    float loop_hz = hq::kLoopRateHz;
    int idle_timeout_s = kIdleTimeoutS;
    long telemetry_backlog_bytes = 0;
};

[[noreturn]] void usage(const char* msg) {
    std::fprintf(stderr,
                 "heliquad-fw-host: %s\nusage: heliquad-fw-host --sim-link PATH --telemetry PATH "
                 "[--loop-hz %g] [--dmp-image FILE] [--idle-timeout-s %d] [--params FILE] "
                 "[--program FILE] [--telemetry-backlog-bytes N] "
                 "[--sd-image FILE [--sd-faults NAME=VALUE,...]]\n",
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
        else if (a == "--sd-image") o.sd_image = v;
        else if (a == "--sd-faults") o.sd_faults = v;
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
    if (!o.sd_faults.empty() && o.sd_image.empty()) usage("--sd-faults needs --sd-image");
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

// One turn of the lockstep loop: telemetry shipped as a USB CDC device ships it, then the
// sim link's bytes (each new sensor frame one step and its reply). The main loop turns it,
// and so does a FatFs call waiting for a busy card (CardWaitServing).
class HostLoop {
public:
    HostLoop(const Options& opt, hq::PtySerial& sim, hq::PtySerial& telemetry,
             hq::SimLinkHandler& handler, SimLinkPty& replies)
        : opt_(opt), sim_(sim), telemetry_(telemetry), handler_(handler), replies_(replies),
          last_input_(Wall::now()) {}

    // False when the build must exit (exit_code() says why), and from then on.
    bool turn() {
        if (!done_) done_ = !serve();
        return !done_;
    }
    // True when the last turn ran at least one step.
    bool stepped_now() const { return stepped_now_; }
    int exit_code() const { return exit_code_; }

private:
    using Wall = std::chrono::steady_clock;   // the idle timeout only; never the core's clock

    const Options& opt_;
    hq::PtySerial& sim_;
    hq::PtySerial& telemetry_;
    hq::SimLinkHandler& handler_;
    SimLinkPty& replies_;
    Wall::time_point last_input_;
    bool serve();

    bool stepped_ = false, stepped_now_ = false, done_ = false;
    int exit_code_ = 0;
    uint8_t buf_[512] = {};
};

bool HostLoop::serve() {
    stepped_now_ = false;
    // Telemetry ships as a USB CDC device ships it: in chunks, once a chunk is buffered,
    // after a frame marked `sync` (the simulator pauses to read it), or when the sim link
    // has been quiet for a moment. Fewer, larger writes keep the lockstep fast.
    if (telemetry_.buffered() >= kTelemetryChunk) telemetry_.flush();
    const long wait_us = telemetry_.buffered() && stepped_ ? kTelemetryQuietUs : kIdlePollUs;
    // Telemetry input (commands) is polled in the same call unless it is already known
    // to be waiting for the next step.
    if (!sim_.wait_readable_us(wait_us, telemetry_.input_pending() ? nullptr : &telemetry_)) {
        if (stepped_) telemetry_.flush();
        if (Wall::now() - last_input_ >= std::chrono::seconds(opt_.idle_timeout_s)) {
            std::fprintf(stderr, "heliquad-fw-host: no sensor frame for %d s; exiting\n",
                         opt_.idle_timeout_s);
            exit_code_ = 3;
            return false;
        }
        return !g_stop;
    }
    last_input_ = Wall::now();
    stepped_ = true;
    const size_t n = sim_.read(buf_, sizeof(buf_));
    const uint32_t lost_before = handler_.lost();
    const uint32_t frames_before = handler_.frames();
    if (!handler_.feed(buf_, n, replies_)) {
        std::fprintf(stderr, "heliquad-fw-host: sim link write failed; exiting\n");
        exit_code_ = 4;
        return false;
    }
    stepped_now_ = handler_.frames() != frames_before;
    if (handler_.lost() != lost_before) {
        std::fprintf(stderr, "heliquad-fw-host: %u sensor frame(s) lost by frame %u\n",
                     handler_.lost() - lost_before, handler_.last_frame());
    }
    return !g_stop;
}

// While the card is busy the loop goes on: each busy poll is one turn (the next frames'
// steps and replies; the card's busy time is lockstep time, which only those frames move).
// When the build must exit, the card is released so the waiting FatFs call ends.
class CardWaitServing final : public hq::CardWait {
public:
    CardWaitServing(HostLoop& loop, hq::FileBlockDevice& card) : loop_(loop), card_(card) {}
    void card_busy() override {
        if (!exiting_ && !loop_.turn()) exiting_ = true;
        if (exiting_) card_.release();
    }

private:
    HostLoop& loop_;
    hq::FileBlockDevice& card_;
    bool exiting_ = false;
};

// Makes the card image when it does not exist, mounts it, prints its state, then sets the
// faults asked for (in force from the first frame on); the card's state. A bad file or fault
// is refused (exit 2).
hq::CardState start_card(const Options& opt, hq::FileBlockDevice& card, hq::SpareTime& spare) {
    struct stat st {};
    if (::stat(opt.sd_image.c_str(), &st) == 0 && S_ISDIR(st.st_mode)) {
        usage(("--sd-image " + opt.sd_image + ": is a folder, not a card image").c_str());
    }
    if (::access(opt.sd_image.c_str(), F_OK) != 0) {
        const std::string error = hq::make_card_image(opt.sd_image, hq::kDefaultCardImageBytes);
        if (!error.empty()) usage(("--sd-image " + error).c_str());
    }
    hq::CardFaults faults;
    size_t at = 0;
    while (at < opt.sd_faults.size()) {
        size_t end = opt.sd_faults.find(',', at);
        if (end == std::string::npos) end = opt.sd_faults.size();
        const std::string item = opt.sd_faults.substr(at, end - at);
        const size_t eq = item.find('=');
        const std::string name = item.substr(0, eq);
        const uint64_t value = eq == std::string::npos ? 1 : std::strtoull(item.c_str() + eq + 1, nullptr, 10);
        if (!hq::set_card_fault(faults, name, value)) usage(("unknown --sd-faults fault " + name).c_str());
        at = end + 1;
    }
    // The busy faults act once the loop runs (at start-up no frame moves the lockstep clock
    // on which a busy card's time passes); the others from the start.
    hq::CardFaults at_start = faults;
    at_start.busy_after_write_us = at_start.busy_every_us = at_start.busy_for_us = 0;
    card.set_faults(at_start);
    const hq::CardState state = spare.start();
    card.set_faults(faults);
    std::printf("card: %s\n", hq::card_state_name(state));
    return state;
}

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
    link_cfg.log = &fc.logger();                 // the link's own STATUSTEXTs, logged
    static hq::GcsLink link(link_cfg, telemetry, inbox);   // nor its queues
    static hq::LogTransfer log_transfer;          // the log protocol: the card's logs
    if (!opt.sd_image.empty()) link.serve_logs(log_transfer);
    const hq::InitResult init = fc.init();
    link.send_notices(fc.status());
    std::printf("sim link: %s -> %s\ntelemetry: %s -> %s\nimu: %s\n", opt.sim_link.c_str(),
                sim.slave_path().c_str(), opt.telemetry.c_str(), telemetry.slave_path().c_str(),
                init == hq::InitResult::OkDmp ? "dmp" : "raw");

    SimLinkPty replies(sim, telemetry);
    hq::SimLinkHandler handler(fc, link, clock, chip, motors, link_cfg.system_id,
                              link_cfg.component_id);
    HostLoop loop(opt, sim, telemetry, handler, replies);
    static hq::FileBlockDevice card(opt.sd_image, clock);
    CardWaitServing wait(loop, card);
    static hq::LogFiles files(card, clock, &wait);
    hq::SpareTime spare(files);
    hq::LoggerTask logger_task(fc);
    hq::LogProtocolTask protocol_task(log_transfer);
    spare.add(logger_task);
    spare.add(protocol_task);
    // The card's state for the boot report (and said in the first step when it cannot log).
    fc.set_card_state(opt.sd_image.empty() ? hq::CardState::NoCard : start_card(opt, card, spare));
    std::printf("ready\n");
    std::fflush(stdout);

    // What init() sent (the parameters' and the IMU's start-up messages) waits for the first
    // frame: the simulator opens the telemetry port before it steps, and opening a serial
    // port discards what was already waiting there.
    while (!g_stop && loop.turn()) {
        if (loop.stepped_now()) spare.run();   // the card's turn: after the reply
    }
    files.end_log();
    telemetry.flush();
    std::fprintf(stderr,
                 "heliquad-fw-host: %u loops, %u frames lost, %u repeated, %u telemetry bytes "
                 "dropped, %zu unread telemetry bytes dropped\n",
                 fc.loops(), handler.lost(), handler.repeated(), link.telemetry_dropped(),
                 telemetry.discarded());
    sim.close();
    telemetry.close();
    return loop.exit_code();
}
