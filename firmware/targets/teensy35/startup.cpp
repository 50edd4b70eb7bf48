// Reset, the vector table and the flash configuration field of the Teensy 3.5 image.
//
// Reset_Handler, in order: the watchdog off (its unlock must come within a few cycles of
// reset), CP10/CP11 granted so the FPU may be used (before any floating-point instruction:
// nothing before this point touches a float), the cycle counter on (the clock's timeouts
// count cycles), .data copied from flash, .bss zeroed, constructors run, then hq_teensy_main() (main.cpp), which never returns.
//
// The vector table is a constant built at compile time, placed at address 0 by the linker
// script; every slot holds an extern "C" handler (a C++ name would leave the slot bound to
// the default). Unused interrupts go to Default_Handler, which is the fault path: an
// interrupt nobody enabled means something wrote where it should not have.
#include <cstdint>

#include "clock.hpp"
#include "cpu.hpp"
#include "led.hpp"
#include "mk64f12.hpp"

extern "C" {
// From the linker script.
extern uint32_t _estack;
extern uint32_t _sidata, _sdata, _edata, _sbss, _ebss;
extern void (*__preinit_array_start[])();
extern void (*__preinit_array_end[])();
extern void (*__init_array_start[])();
extern void (*__init_array_end[])();

[[noreturn]] void hq_teensy_main();     // main.cpp

[[noreturn]] void Reset_Handler();
void NMI_Handler();
void HardFault_Handler();
void MemManage_Handler();
void BusFault_Handler();
void UsageFault_Handler();
void Default_Handler();
void SysTick_Handler();
void UART0_RX_TX_IRQHandler();
void FTM3_IRQHandler();
void I2C0_IRQHandler();
void USB0_IRQHandler();
}

namespace {

using Handler = void (*)();
constexpr int kIrqs = hq::mk64::irq::kCount;
static_assert(kIrqs == 86, "MK64FX512: 86 interrupt vectors");

struct VectorTable {
    uint32_t* stack_top;
    Handler exceptions[15];      // vectors 1..15
    Handler irqs[kIrqs];         // vectors 16..
};
static_assert(sizeof(VectorTable) == 4 * (16 + 86), "408-byte vector table");

constexpr VectorTable make_vectors() {
    VectorTable v{};
    v.stack_top = &_estack;
    v.exceptions[0] = Reset_Handler;
    v.exceptions[1] = NMI_Handler;
    v.exceptions[2] = HardFault_Handler;
    v.exceptions[3] = MemManage_Handler;
    v.exceptions[4] = BusFault_Handler;
    v.exceptions[5] = UsageFault_Handler;
    // 7..10 and 13 are reserved (zero).
    v.exceptions[10] = Default_Handler;      // SVCall: nothing here issues SVC
    v.exceptions[11] = Default_Handler;      // DebugMonitor
    v.exceptions[13] = Default_Handler;      // PendSV
    v.exceptions[14] = SysTick_Handler;
    for (Handler& h : v.irqs) h = Default_Handler;
    v.irqs[hq::mk64::irq::UART0_RX_TX] = UART0_RX_TX_IRQHandler;
    v.irqs[hq::mk64::irq::FTM3] = FTM3_IRQHandler;
    v.irqs[hq::mk64::irq::I2C0] = I2C0_IRQHandler;
    v.irqs[hq::mk64::irq::USB0] = USB0_IRQHandler;
    return v;
}

}  // namespace

extern "C" {

extern const VectorTable hq_vectors;
__attribute__((section(".vectors"), used)) const VectorTable hq_vectors = make_vectors();

// Flash configuration field (0x400-0x40F, placed and asserted by the linker script):
// backdoor key and protection bytes erased (0xFF: no key, nothing write-protected);
// FSEC 0xFE: SEC = 0b10 unsecure (a secured part would refuse the bootloader and mass-erase
// at the next button press), factory access, mass erase and backdoor left at their erased
// "enabled/disabled" defaults; FOPT 0xF9: LPBOOT 1 (normal boot, full-speed dividers),
// EZPORT_DIS 0 (EzPort off), NMI_DIS 0 (the NMI pin ignored), other bits erased.
extern const uint8_t hq_flash_config[16];
__attribute__((section(".flashconfig"), used)) const uint8_t hq_flash_config[16] = {
    0xFF, 0xFF, 0xFF, 0xFF, 0xFF, 0xFF, 0xFF, 0xFF,     // backdoor comparison key
    0xFF, 0xFF, 0xFF, 0xFF,                             // FPROT3..0
    0xFE,                                               // FSEC
    0xF9,                                               // FOPT
    0xFF,                                               // FEPROT
    0xFF,                                               // FDPROT
};

void Reset_Handler() {
    using namespace hq::mk64;
    // 1. Watchdog: unlock (two 16-bit writes back to back), then disable it.
    WDOG::UNLOCK::write(0xC520);
    WDOG::UNLOCK::write(0xD928);
    __asm volatile("nop\n nop");
    WDOG::STCTRLH::write(static_cast<uint16_t>(WDOG::STCTRLH::RESET_VALUE &
                                               ~WDOG::STCTRLH::WDOGEN));   // 0x01D2
    // 2. The FPU: full access to CP10 and CP11.
    SystemControl::CPACR::set(SystemControl::CPACR::CP10(3) | SystemControl::CPACR::CP11(3));
    hq::teensy::dsb();
    hq::teensy::isb();
    hq::teensy::start_cycle_counter();
    // 3. .data, .bss, constructors.
    for (uint32_t *src = &_sidata, *dst = &_sdata; dst < &_edata;) *dst++ = *src++;
    for (uint32_t* dst = &_sbss; dst < &_ebss;) *dst++ = 0;
    for (auto* f = __preinit_array_start; f < __preinit_array_end; ++f) (*f)();
    for (auto* f = __init_array_start; f < __init_array_end; ++f) (*f)();
    hq_teensy_main();
}

void NMI_Handler() {}     // the NMI pin is disabled in FOPT; nothing else raises it
void HardFault_Handler() { hq_fatal(static_cast<uint32_t>(hq::teensy::FaultCode::CpuFault)); }
void MemManage_Handler() { hq_fatal(static_cast<uint32_t>(hq::teensy::FaultCode::CpuFault)); }
void BusFault_Handler() { hq_fatal(static_cast<uint32_t>(hq::teensy::FaultCode::CpuFault)); }
void UsageFault_Handler() { hq_fatal(static_cast<uint32_t>(hq::teensy::FaultCode::CpuFault)); }
void Default_Handler() { hq_fatal(static_cast<uint32_t>(hq::teensy::FaultCode::UnexpectedIrq)); }

// A pure virtual call (an object used before or after its lifetime) is a fault.
void __cxa_pure_virtual() { hq_fatal(static_cast<uint32_t>(hq::teensy::FaultCode::CpuFault)); }

// errno, for the C library's math wrappers (acosf, asinf, sqrtf set it on a domain error;
// nothing in the image reads it). Defined here, newlib's own __errno is not linked, nor its
// reentrancy structure (impure_data) that holds errno there: about 100 B of RAM.
int* __errno() {
    static int errno_value = 0;
    return &errno_value;
}

}  // extern "C"
