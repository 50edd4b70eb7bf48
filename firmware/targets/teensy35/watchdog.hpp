// The MK64's watchdog, on again once the loop runs: the last line of defence against a hang.
//
// Reset_Handler turns the watchdog off (it must be configured within a few cycles of reset,
// long before the clocks and the IMU are up) but leaves ALLOWUPDATE set; start() unlocks it
// and enables it on the 1 kHz low-power oscillator with a timeout of timeout_ms. refresh()
// (two key writes) must then come at least once per timeout: the loop refreshes it every
// iteration, and TeensyClock::delay_us() during the IMU's start-up waits. If the firmware
// hangs, the chip resets: its pins fall back to inputs, the ESCs lose their signal and stop,
// and the board boots again with the motors at their stop pulse.
#pragma once

#include <cstdint>

namespace hq::teensy {

class Watchdog {
public:
    // 500 ms: longer than the IMU re-initialisation's longest stretch between refreshes (the
    // DMP upload, read-back and configuration, about 0.2-0.3 s of I2C at 375 kHz, with margin
    // for the low-power oscillator's tolerance), and still short: a hang holds the last motor
    // command for at most half a second (ArduPilot's watchdog allows about two).
    static constexpr uint32_t kTimeoutMs = 500;

    static void start(uint32_t timeout_ms);
    static void refresh();
};

}  // namespace hq::teensy
