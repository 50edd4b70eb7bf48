#include "clock.hpp"

#include "cpu.hpp"
#include "mk64f12.hpp"
#include "watchdog.hpp"

namespace hq::teensy {

using namespace hq::mk64;

namespace {

uint32_t g_core_hz = kResetCoreHz;
uint32_t g_last_cycles = 0;     // cycles64() state: the last 32-bit reading and the wraps
uint32_t g_wraps = 0;

// Waits until (MCG_S & mask) == value, for at most `ms` milliseconds of the clock now running.
bool wait_mcg(uint8_t mask, uint8_t value, uint32_t ms) {
    const uint32_t budget = g_core_hz / 1000u * ms;
    const uint32_t start = cycles32();
    while ((MCG::S::read() & mask) != value) {
        if (cycles32() - start > budget) return false;
    }
    return true;
}

// Timeouts: a 16 MHz crystal starts within a few milliseconds; the PLL locks within 1 ms
// (the K64's data sheet gives about 0.2 ms); clock switches take a few reference cycles.
constexpr uint32_t kCrystalStartMs = 100;
constexpr uint32_t kSwitchMs = 10;
constexpr uint32_t kPllLockMs = 10;

}  // namespace

void start_cycle_counter() {
    CoreDebug::DEMCR::set(CoreDebug::DEMCR::TRCENA);
    DWT::CYCCNT::write(0);
    DWT::CTRL::set(DWT::CTRL::CYCCNTENA);
    g_last_cycles = 0;
    g_wraps = 0;
}

uint64_t cycles64() {
    IrqGuard guard;
    const uint32_t now = DWT::CYCCNT::read();
    if (now < g_last_cycles) ++g_wraps;
    g_last_cycles = now;
    return (static_cast<uint64_t>(g_wraps) << 32) | now;
}

uint32_t core_hz() { return g_core_hz; }

ClockFault start_clocks() {
    // FEI -> FBE: start the crystal (10 pF of load: SC8P + SC2P) and run the MCG from it.
    OSC::CR::write(OSC::CR::ERCLKEN | OSC::CR::SC8P | OSC::CR::SC2P);
    MCG::C2::write(MCG::C2::RANGE(2) | MCG::C2::EREFS);           // very high range, crystal
    MCG::C1::write(MCG::C1::CLKS(2) | MCG::C1::FRDIV(4));         // external; 16 MHz / 512
    if (!wait_mcg(MCG::S::OSCINIT0, MCG::S::OSCINIT0, kCrystalStartMs)) return ClockFault::Crystal;
    if (!wait_mcg(MCG::S::IREFST, 0, kSwitchMs)) return ClockFault::ExternalRef;
    if (!wait_mcg(MCG::S::CLKST_MASK, MCG::S::CLKST(2), kSwitchMs)) return ClockFault::BypassClock;
    g_core_hz = kCrystalHz;

    // FBE -> PBE: PLL reference 16 MHz / 4 = 4 MHz, times 30 = 120 MHz.
    MCG::C5::write(MCG::C5::PRDIV0(3));
    MCG::C6::write(MCG::C6::PLLS | MCG::C6::VDIV0(6));
    if (!wait_mcg(MCG::S::PLLST, MCG::S::PLLST, kSwitchMs)) return ClockFault::PllLock;
    if (!wait_mcg(MCG::S::LOCK0, MCG::S::LOCK0, kPllLockMs)) return ClockFault::PllLock;

    // Dividers before the switch: core /1, bus /2, FlexBus /3, flash /5 (<= 25 MHz);
    // USB = 120 MHz * (USBFRAC + 1) / (USBDIV + 1) = 120 * 2 / 5 = 48 MHz.
    SIM::CLKDIV1::write(SIM::CLKDIV1::OUTDIV1(0) | SIM::CLKDIV1::OUTDIV2(1) |
                        SIM::CLKDIV1::OUTDIV3(2) | SIM::CLKDIV1::OUTDIV4(4));
    SIM::CLKDIV2::write(SIM::CLKDIV2::USBDIV(4) | SIM::CLKDIV2::USBFRAC);

    // PBE -> PEE.
    MCG::C1::write(MCG::C1::CLKS(0) | MCG::C1::FRDIV(4));
    if (!wait_mcg(MCG::S::CLKST_MASK, MCG::S::CLKST(3), kSwitchMs)) return ClockFault::PllClock;
    g_core_hz = kCoreHz;
    start_cycle_counter();      // time starts at 120 MHz: micros() never mixes two rates

    // Peripherals that take "PLL/FLL" clock take the PLL; USB from the divider above.
    SIM::SOPT2::set(SIM::SOPT2::USBSRC | SIM::SOPT2::PLLFLLSEL(1));
    return ClockFault::None;
}

uint64_t TeensyClock::micros() const { return divide_time(cycles64(), g_core_hz / 1000000u); }

void TeensyClock::delay_us(uint32_t us) {
    // Start-up waits (the IMU's reset, 100 ms) outlast nothing but keep the watchdog fed and
    // the idle work going.
    const uint64_t end = cycles64() + static_cast<uint64_t>(us) * (g_core_hz / 1000000u);
    uint64_t next_refresh = 0;
    for (uint64_t now = cycles64(); now < end; now = cycles64()) {
        if (now >= next_refresh) {
            Watchdog::refresh();
            if (idle_ != nullptr) idle_();
            next_refresh = now + g_core_hz / 1000u;        // every millisecond
        }
    }
}

}  // namespace hq::teensy
