// heliquad-fw-teensy35: the firmware on the Teensy 3.5.
//
// Start-up, in order: clocks (a failure ends in the fault path, blink code 1-5, the ESCs
// never driven); the status LED; the ESC outputs, at their stop pulse from their first edge;
// the telemetry UART; RC capture; the I2C bus; the FlightController (its parameters in the
// top two flash sectors, param_storage.hpp) and its IMU start-up (MPU6050 reset,
// configuration and, with an image built in, the DMP upload) and its telemetry link
// (GcsLink, core/link/); the 200 Hz
// loop timer; the watchdog (watchdog.hpp). Then, every tick: refresh the watchdog, read the
// RC input, take the link's requests, run one FlightController step, send the link's answers
// and telemetry, record the cycles all that took (HQ_FW_STATUS reports
// their median and maximum each second, and the overruns), update the LED, sleep until the
// next tick. After each step the loop's state goes to hq_loop_report (below).
#include <cstdint>

#include "../../core/flight_controller.hpp"
#include "../../core/link/gcs_link.hpp"
#include "../../hal/reset_cause.hpp"
#include "../dmp_image.hpp"
#include "clock.hpp"
#include "i2c.hpp"
#include "led.hpp"
#include "loop_timer.hpp"
#include "motors.hpp"
#include "param_storage.hpp"
#include "rc_input.hpp"
#include "serial.hpp"
#include "mk64f12.hpp"
#include "watchdog.hpp"

namespace {

constexpr uint32_t kLoopHz = static_cast<uint32_t>(hq::kLoopRateHz);
constexpr uint32_t kTelemetryBaud = 921600;

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

}  // namespace

// The last loop's state, at a fixed symbol in RAM, for a debug probe to watch without
// stopping the loop; the emulated board (heliquad's processor-in-the-loop target) reads it to
// answer each lockstep frame as the host build does. Written once a loop, after the step.
struct LoopReport {
    uint32_t loops;         // FlightController steps since boot
    uint32_t step_cycles;   // core cycles of the last step
    uint32_t overruns;      // loop ticks missed since boot
    uint8_t armed;          // 1 when armed
    uint8_t mode;           // HQ_MODE
    uint8_t sensor_kind;    // HQ_SENSOR_KIND the MPU6050 is configured for
    uint8_t exc_state;      // HQ_EXCITATION_STATE
};
extern "C" {
volatile LoopReport hq_loop_report;
}

extern "C" [[noreturn]] void hq_teensy_main() {
    using namespace hq::teensy;
    const ClockFault clock_fault = start_clocks();
    if (clock_fault != ClockFault::None) hq_fatal(static_cast<uint32_t>(clock_fault));
    led_begin();
    led_set(true);

    static Ftm0Motors motors;
    motors.begin(hq::EscEndpoints{});     // the stop pulse until the parameters say otherwise
    static Uart0Serial telemetry;
    if (!telemetry.begin(kTelemetryBaud)) hq_fatal(static_cast<uint32_t>(FaultCode::StartUp));
    static Ftm3RcInput rc;
    rc.begin();
    static I2c0Bus i2c;
    i2c.begin();
    static TeensyClock clock;
    static FlashParamStorage storage;         // the top two flash sectors (param_storage.hpp)

    hq::FlightControllerConfig cfg;
    cfg.loop_rate_hz = static_cast<float>(kLoopHz);
    cfg.storage = &storage;
    cfg.reset_cause = hq::reset_cause();      // RCM_SRS0/SRS1 (reset_cause.cpp)
    hq::GcsLinkConfig link_cfg;
    link_cfg.loop_rate_hz = cfg.loop_rate_hz;
    link_cfg.cpu_hz = kCoreHz;                        // SYS_STATUS load from the cycle counter
    link_cfg.link_bytes_per_s = kTelemetryBaud / 10;  // 8N1: ten bits a byte
    read_uid(link_cfg);
    hq::use_built_in_dmp(cfg.imu);       // the DMP firmware if the build has one, else raw
    static hq::FlightController fc(cfg, i2c, clock, motors);
    static hq::GcsLink link(link_cfg, clock, telemetry);
    const hq::InitResult init = fc.init();
    link.send_notices(fc.status());

    static LoopTimer timer;
    if (!timer.start(kLoopHz)) hq_fatal(static_cast<uint32_t>(FaultCode::StartUp));
    Watchdog::start(Watchdog::kTimeoutMs);
    for (;;) {
        timer.wait();
        Watchdog::refresh();
        const uint32_t c0 = cycles32();
        link.receive();
        fc.step(rc.read(), link.inbox());
        link.transmit(fc.status());
#ifdef HQ_TEST_LOOP_DELAY_US
        clock.delay_us(HQ_TEST_LOOP_DELAY_US);   // a test build's deliberately slow loop
#endif
        const uint32_t step_cycles = cycles32() - c0;
        link.record_loop(step_cycles, timer.overruns());
        hq_loop_report.loops = fc.loops();
        hq_loop_report.step_cycles = step_cycles;
        hq_loop_report.overruns = timer.overruns();
        hq_loop_report.armed = fc.armed() ? 1 : 0;
        hq_loop_report.mode = static_cast<uint8_t>(fc.mode());
        hq_loop_report.sensor_kind = fc.sensor_kind();
        hq_loop_report.exc_state = static_cast<uint8_t>(fc.supervisor().excitation_state());
        led_update(clock.micros(), led_pattern(fc, init));
    }
}
