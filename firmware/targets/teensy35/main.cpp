// heliquad-fw-teensy35: the firmware on the Teensy 3.5.
//
// Start-up, in order: clocks (a failure ends in the fault path, blink code 1-5, the ESCs
// never driven); the status LED; the ESC outputs, at their stop pulse from their first edge;
// RC capture; the I2C bus; the USB port (usb/usb_serial.hpp), attached now so that the
// start-up's waits answer a host enumerating it; the FlightController (its parameters in the
// top two flash sectors, param_storage.hpp) and its IMU start-up (MPU6050 reset,
// configuration and, with an image built in, the DMP upload); UART0 at the baud rate the
// parameters give (SER_TEL1_BAUD); the two MAVLink links (GcsLink, core/link/), one on the
// USB port and one on UART0, sharing the loop's inbox and the log protocol; the SD card
// (block_device.hpp: its identification, its finding and size in hq_sd_probe, below) and
// its FAT file system (core/log/log_files.hpp), whose state the boot report names; the 200 Hz
// loop timer; the watchdog (watchdog.hpp). Then, every tick: refresh the watchdog, read the RC
// input, take both links' requests, run one FlightController step, send each link's answers
// and telemetry, the USB stack's work, hand the USB transmit buffer to the controller, record
// the cycles all that took (HQ_FW_STATUS reports their median and maximum each second, and
// the overruns), update the LED; then the spare time's work on the card (the on-board log's
// ring drained into its file, the log protocol's answers: core/log/spare_tasks.hpp), during
// which a tick that comes while the card is busy runs its step at once (StepWhenDue); then
// sleep until the next tick (servicing the USB stack whenever an interrupt wakes the core).
// After each step the loop's state goes to hq_loop_report (below). A host that sets 134
// baud on the USB port asks for the bootloader: the loop refuses it while armed and
// otherwise, once its messages are out, stops the motors and enters the bootloader
// (bootloader.hpp).
#include <cstdint>
#include <new>

#include "../../core/flight_controller.hpp"
#include "../../core/link/gcs_link.hpp"
#include "../../core/log/card_disk.hpp"
#include "../../core/log/spare_tasks.hpp"
#include "../../hal/reset_cause.hpp"
#include "../dmp_image.hpp"
#include "block_device.hpp"
#include "bootloader.hpp"
#include "clock.hpp"
#include "forever.hpp"
#include "i2c.hpp"
#include "led.hpp"
#include "loop_timer.hpp"
#include "motors.hpp"
#include "param_storage.hpp"
#include "rc_input.hpp"
#include "serial.hpp"
#include "usb/usb_serial.hpp"
#include "mk64f12.hpp"
#include "watchdog.hpp"

namespace {

constexpr uint32_t kLoopHz = static_cast<uint32_t>(hq::kLoopRateHz);

// UART0 makes every rate SER_TEL1_BAUD takes within 2 % at the core clock, so the core's check
// of the parameter (one of kSerialBauds) refuses everything this UART cannot make.
constexpr bool uart0_makes_every_baud() {
    for (const uint32_t baud : hq::kSerialBauds) {
        uint16_t sbr = 0;
        uint8_t brfa = 0;
        if (!hq::teensy::uart_divisor(hq::teensy::kCoreHz, baud, sbr, brfa)) return false;
    }
    return true;
}
static_assert(uart0_makes_every_baud(), "UART0 cannot make one of kSerialBauds at kCoreHz");

hq::teensy::UsbCdcSerial usb;

void service_usb() { usb.task(); }

hq::teensy::LedPattern led_pattern(const hq::FlightController& fc, hq::InitResult init) {
    using hq::teensy::LedPattern;
    if (fc.armed()) return LedPattern::Armed;
    if (init == hq::InitResult::NoDevice || init == hq::InitResult::BusError ||
        fc.supervisor().imu_stale()) {
        return LedPattern::ImuFault;
    }
    return LedPattern::Disarmed;
}

// The chip's unique identification (SIM_UIDH..UIDL, 128 bits) as AUTOPILOT_VERSION carries
// it: uid the low 64 bits (UIDML, UIDL), uid2 all 16 bytes, most significant first.
void read_uid(hq::GcsLinkConfig& cfg) {
    namespace sim = hq::mk64::SIM;
    const uint32_t words[4] = {sim::UIDH::read(), sim::UIDMH::read(), sim::UIDML::read(),
                               sim::UIDL::read()};
    cfg.uid = static_cast<uint64_t>(words[2]) << 32 | words[3];
    for (int w = 0; w < 4; ++w) {
        for (int b = 0; b < 4; ++b) cfg.uid2[4 * w + b] = static_cast<uint8_t>(words[w] >> (24 - 8 * b));
    }
}

// The USB host's 134 baud, as the loop's request (answered in the step: refused while armed),
// into the cleared inbox before the links add theirs.
void ask_bootloader(hq::LoopInbox& inbox) {
    hq::LoopRequest& r = inbox.request[inbox.count++];
    r = hq::LoopRequest{};
    r.kind = hq::RequestKind::Bootloader;
}

}  // namespace

// The last loop's state, at a fixed symbol in RAM, for a debug probe to watch without
// stopping the loop; the emulated board (heliquad's processor-in-the-loop target) reads it to
// answer each lockstep frame as the host build does. Written once a loop: the flight state as
// soon as the step's outputs are final (then hq_step_outputs is called), the cycles and
// overruns when the loop's work is done.
struct LoopReport {
    uint32_t loops;         // FlightController steps since boot
    uint32_t step_cycles;   // core cycles of the last step
    uint32_t overruns;      // loop ticks missed since boot
    uint8_t armed;          // 1 when armed
    uint8_t mode;           // HQ_MODE
    uint8_t sensor_kind;    // HQ_SENSOR_KIND the MPU6050 is configured for
    uint8_t exc_state;      // HQ_EXCITATION_STATE
    uint8_t rotor_count;    // the rotors the loop flies: FTM0 channels 0..rotor_count - 1
};
extern "C" {
volatile LoopReport hq_loop_report;
}

// What the SD card's identification at start-up found, at a fixed symbol for a debug probe
// (and the emulated board) to read: SdhcCard::Finding, the card's size in 512-byte blocks
// (0 without a card) and 1 if the card is write protected. Written once, at start-up.
struct SdProbe {
    uint32_t blocks;
    uint8_t finding;
    uint8_t write_protected;
    uint8_t status;         // BlockStatus of start()
    uint8_t reserved;
};
extern "C" {
volatile SdProbe hq_sd_probe;

// Runs the step of a tick that came while FatFs waits for the card (StepWhenDue, below):
// `loop` is the Loop. Its own symbol, never inlined: the emulated board ends a lockstep frame
// here as at LoopTimer::wait, so that this step too gets its frame's sensor data.
__attribute__((noinline)) void hq_card_wait_step(void* loop);

// Called once a step, as soon as the step's outputs are final: the motors written and
// hq_loop_report's flight state (loops, armed, mode, sensor kind, excitation state, rotor
// count) set. Its own symbol, never inlined or dropped: the emulated board answers its
// lockstep frame here, then runs the rest of the step (the telemetry, the USB stack) while
// the simulator integrates the plant. A few cycles a loop on the board.
__attribute__((noipa)) void hq_step_outputs();
}

namespace {

// What one loop step works on; step() is the loop's body, run once a tick: by the main loop
// after LoopTimer::wait(), and by the card's wait hook (StepWhenDue) when a tick comes while
// FatFs waits for the card.
struct Loop {
    hq::teensy::TeensyClock& clock;
    hq::teensy::Ftm0Motors& motors;
    hq::teensy::Ftm3RcInput& rc;
    hq::FlightController& fc;
    hq::LoopInbox& inbox;
    hq::GcsLink& usb_link;
    hq::GcsLink& uart_link;
    hq::teensy::LoopTimer& timer;
    hq::InitResult init;

    void step();
};

void Loop::step() {
    using namespace hq::teensy;
    Watchdog::refresh();
    const uint32_t c0 = cycles32();
    inbox.clear();
    if (usb.take_bootloader_request()) ask_bootloader(inbox);   // first: there is room
    usb_link.receive();
    uart_link.receive();
    fc.step(rc.read(), inbox);
    hq_loop_report.loops = fc.loops();
    hq_loop_report.armed = fc.armed() ? 1 : 0;
    hq_loop_report.mode = static_cast<uint8_t>(fc.mode());
    hq_loop_report.sensor_kind = fc.sensor_kind();
    hq_loop_report.exc_state = static_cast<uint8_t>(fc.supervisor().excitation_state());
    hq_loop_report.rotor_count = fc.status().state.rotor_count;
    hq_step_outputs();
    usb_link.transmit(fc.status());
    uart_link.transmit(fc.status());
    // The USB stack's work after the step, not before it: the step's time is its tick's,
    // whatever the host did meanwhile (what arrived is read by the next step).
    usb.task();
    usb.flush();
#ifdef HQ_TEST_LOOP_DELAY_US
    clock.delay_us(HQ_TEST_LOOP_DELAY_US);   // a test build's deliberately slow loop
#endif
    const uint32_t step_cycles = cycles32() - c0;
    usb_link.record_loop(step_cycles, timer.overruns());
    uart_link.record_loop(step_cycles, timer.overruns());
    hq_loop_report.step_cycles = step_cycles;
    hq_loop_report.overruns = timer.overruns();
    led_update(clock.micros(), led_pattern(fc, init));
    if (fc.status().bootloader) enter_bootloader(motors, usb);
}

// The card's wait hook (core/log/card_disk.hpp, docs/sd-card.md): while FatFs waits for a
// busy card, the USB stack is served and the loop's step runs as soon as its tick has come,
// so the card never makes the loop late.
class StepWhenDue final : public hq::CardWait {
public:
    explicit StepWhenDue(Loop& loop) : loop_(loop) {}
    void card_busy() override {
        service_usb();
        if (loop_.timer.take_tick()) hq_card_wait_step(&loop_);
    }

private:
    Loop& loop_;
};

}  // namespace

void hq_card_wait_step(void* loop) { static_cast<Loop*>(loop)->step(); }

void hq_step_outputs() { __asm__ volatile("" ::: "memory"); }

extern "C" [[noreturn]] void hq_teensy_main() {
    using namespace hq::teensy;
    const ClockFault clock_fault = start_clocks();
    if (clock_fault != ClockFault::None) hq_fatal(static_cast<uint32_t>(clock_fault));
    led_begin();
    led_set(true);

    static Ftm0Motors motors;
    motors.begin(hq::EscEndpoints{});     // the stop pulse until the parameters say otherwise
    static Ftm3RcInput rc;
    rc.begin();
    static I2c0Bus i2c;
    i2c.begin();
    static TeensyClock clock;
    // The USB port attached before the IMU's start-up, whose waits serve it: a host has
    // enumerated the board (about 45 ms after its 100 ms debounce) by the first loop.
    usb.begin();
    clock.set_idle(service_usb);
    // Constant-initialised (constexpr, param_storage.hpp): in .data before any code runs.
    static FlashParamStorage storage = FlashParamStorage::parameters();
    static FlashParamStorage program_storage = FlashParamStorage::program();

    hq::FlightControllerConfig cfg;
    cfg.loop_rate_hz = static_cast<float>(kLoopHz);
    cfg.storage = &storage;
    cfg.program_storage = &program_storage;
    cfg.reset_cause = hq::reset_cause();      // RCM_SRS0/SRS1 (reset_cause.cpp)
    hq::GcsLinkConfig uart_cfg;
    uart_cfg.loop_rate_hz = cfg.loop_rate_hz;
    uart_cfg.cpu_hz = kCoreHz;                        // SYS_STATUS load from the cycle counter
    uart_cfg.link_id = HQ_LINK_UART0;
    read_uid(uart_cfg);
    hq::GcsLinkConfig usb_cfg = uart_cfg;
    usb_cfg.link_bytes_per_s = kUsbLinkBytesPerS;
    usb_cfg.link_id = HQ_LINK_USB;
    hq::use_built_in_dmp(cfg.imu);       // the DMP firmware if the build has one, else raw
    static hq::FlightController fc(cfg, i2c, clock, motors);
    const hq::InitResult init = fc.init();      // the USB host is answered meanwhile
    // UART0 at the stored rate, fixed until the next start-up (a set says "restart to apply").
    const uint32_t baud = fc.params().values().tel1_baud;
    static Uart0Serial telemetry;
    if (!telemetry.begin(baud)) hq_fatal(static_cast<uint32_t>(FaultCode::StartUp));
    uart_cfg.link_bytes_per_s = baud / 10;            // 8N1: ten bits a byte
    // Built here in zeroed (.bss) storage: as a constant-initialised static its 1.3 KB
    // initial image (each request's param_index is -1) would be stored in flash as .data.
    alignas(hq::LoopInbox) static unsigned char inbox_storage[sizeof(hq::LoopInbox)];
    hq::LoopInbox& inbox = *new (inbox_storage) hq::LoopInbox;
    usb_cfg.log = uart_cfg.log = &fc.logger();       // the links' own STATUSTEXTs, logged
    static hq::GcsLink usb_link(usb_cfg, usb, inbox);
    static hq::GcsLink uart_link(uart_cfg, telemetry, inbox);
    usb_link.pair_with(uart_link);
    uart_link.pair_with(usb_link);
    static hq::LogTransfer log_transfer;          // the log protocol, one for both links
    usb_link.serve_logs(log_transfer);
    uart_link.serve_logs(log_transfer);
    log_transfer.set_link_rate(usb_link, kUsbLogBytesPerS);   // the port empties between ticks
    static LoopTimer timer;
    static Loop loop{clock, motors, rc, fc, inbox, usb_link, uart_link, timer, init};

    // The SD card and its file system, owned by the spare-time service: the logger's and the
    // log protocol's work on it runs after each step, never inside one.
    static SdhcCard card(clock);
    static StepWhenDue card_wait(loop);
    static Forever<hq::LogFiles> files(card, clock, &card_wait);   // never destroyed
    static hq::SpareTime spare(files.get());
    static hq::LoggerTask logger_task(fc);
    static hq::LogProtocolTask protocol_task(log_transfer);
    spare.add(logger_task);
    spare.add(protocol_task);
    fc.set_card_state(spare.start());        // the card's identification and FAT mount
    hq_sd_probe.blocks = card.block_count();
    hq_sd_probe.finding = static_cast<uint8_t>(card.finding());
    hq_sd_probe.write_protected = card.write_protected() ? 1 : 0;
    hq_sd_probe.status = static_cast<uint8_t>(
        card.finding() == SdhcCard::Finding::Ready    ? hq::BlockStatus::Ok
        : card.finding() == SdhcCard::Finding::NoCard ? hq::BlockStatus::NoCard
                                                      : hq::BlockStatus::Failed);
    usb_link.send_notices(fc.status());
    uart_link.send_notices(fc.status());

    if (!timer.start(kLoopHz)) hq_fatal(static_cast<uint32_t>(FaultCode::StartUp));
    Watchdog::start(Watchdog::kTimeoutMs);
    for (;;) {
        timer.wait(service_usb);
        loop.step();
        spare.run();                         // the loop's spare time: the card's turn
    }
}
