// The status LED (pin 13, PTC5) and its blink codes.
//
//   pattern                          meaning
//   slow blink, 1 Hz                 running, disarmed
//   steady on                        armed
//   code 6, repeating                IMU fault: not found at start, or no fresh samples now
//   code 1-5, forever (halted)       clock start-up failed at that step (clock.hpp)
//   code 7, forever (halted)         CPU fault (HardFault, MemManage, BusFault, UsageFault)
//   code 8, forever (halted)         an unexpected interrupt
//   code 9, forever (halted)         the loop timer or the telemetry UART could not start
//
// A code N is N short flashes (0.2 s on, 0.3 s off) and a 1.5 s pause.
#pragma once

#include <cstdint>

namespace hq::teensy {

enum class FaultCode : uint8_t {
    ImuFault = 6,
    CpuFault = 7,
    UnexpectedIrq = 8,
    StartUp = 9,
};

enum class LedPattern : uint8_t { Disarmed, Armed, ImuFault };

void led_begin();
void led_set(bool on);
// Whether the LED is on at time t_ms into a repeating blink code.
bool blink_code_on(uint32_t code, uint32_t t_ms);
void led_update(uint64_t now_us, LedPattern pattern);

}  // namespace hq::teensy

// The fault path: ESCs to their stop pulse (if they were ever started), interrupts off, the
// LED blinking `code` forever (the watchdog, if running, is kept fed: this state is safe
// and its code should stay readable). Also the target of every CPU fault handler.
extern "C" [[noreturn]] void hq_fatal(uint32_t code);
