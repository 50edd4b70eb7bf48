// enter_bootloader (bootloader.hpp).
#include "bootloader.hpp"

#include "clock.hpp"
#include "cpu.hpp"
#include "watchdog.hpp"

namespace hq::teensy {

void enter_bootloader(Ftm0Motors& motors, UsbCdcSerial& usb) {
    motors.disarm();                       // the stop pulse from the next PWM period
    Watchdog::refresh();                   // the drain is far shorter than its timeout
    const uint32_t start = cycles32();
    constexpr uint32_t kDrainCycles = kBootloaderDrainUs * (kCoreHz / 1000000u);
    while (cycles32() - start < kDrainCycles) {
        usb.task();
        usb.flush();
    }
    irq_disable();
    __asm volatile("bkpt #0");             // the bootloader chip takes over here
    for (;;) {
    }
}

}  // namespace hq::teensy
