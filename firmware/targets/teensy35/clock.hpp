// Teensy 3.5 clocks and time.
//
// start_clocks(): the 16 MHz crystal through the PLL to a 120 MHz core, 60 MHz bus,
// 40 MHz FlexBus, 24 MHz flash and 48 MHz USB clock (docs/teensy35.md lists the steps).
// Every wait on the MCG status has a timeout counted in cycles of the clock running at that
// moment; a timeout returns which step failed, and main() ends in the fault path (the LED's
// blink code) with the ESCs never driven.
//
// TeensyClock: the HAL clock (hal/clock.hpp). micros() comes from the Cortex-M4 cycle
// counter (DWT_CYCCNT, 32 bits, wrapping every 35.8 s at 120 MHz), extended to 64 bits on
// every read; it must be read at least once per wrap, which the 200 Hz loop does.
#pragma once

#include <cstdint>

#include "../../hal/clock.hpp"
#include "mk64f12.hpp"

namespace hq::teensy {

constexpr uint32_t kCrystalHz = 16000000;
constexpr uint32_t kCoreHz = 120000000;
constexpr uint32_t kBusHz = 60000000;
constexpr uint32_t kFlexBusHz = 40000000;
constexpr uint32_t kFlashHz = 24000000;
constexpr uint32_t kUsbHz = 48000000;
// The core clock out of reset (FEI: the FLL from the slow internal reference, 20.97 MHz).
constexpr uint32_t kResetCoreHz = 20971520;

// Which step of start_clocks() timed out (also the fault path's blink code).
enum class ClockFault : uint8_t {
    None = 0,
    Crystal = 1,        // OSCINIT0 never set: no crystal, or it does not start
    ExternalRef = 2,    // the FLL reference did not switch to the crystal (IREFST)
    BypassClock = 3,    // the MCG output did not switch to the external reference (CLKST 2)
    PllLock = 4,        // PLLST or LOCK0 never set
    PllClock = 5,       // the MCG output did not switch to the PLL (CLKST 3)
};

// Starts the cycle counter. Called first thing after reset (before start_clocks, whose
// timeouts count cycles).
void start_cycle_counter();
ClockFault start_clocks();
// The core clock frequency now (kResetCoreHz until start_clocks() succeeds).
uint32_t core_hz();

// 64-bit cycle count since start_cycle_counter(); safe from interrupts and main.
uint64_t cycles64();
// 32-bit cycle count (wraps): for short intervals. Inline: the I2C and loop waits poll it.
inline uint32_t cycles32() { return mk64::DWT::CYCCNT::read(); }

class TeensyClock final : public Clock {
public:
    uint64_t micros() const override;
    // Busy-waits on the cycle counter: start-up only, never in the loop. Every millisecond
    // it feeds the watchdog and runs the idle work, if set (the USB stack's, so a host
    // enumerating the board during the IMU's start-up is answered).
    void delay_us(uint32_t us) override;
    void set_idle(void (*idle)()) { idle_ = idle; }

private:
    void (*idle_)() = nullptr;
};

}  // namespace hq::teensy
