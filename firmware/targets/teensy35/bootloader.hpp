// The Teensy 3.5's bootloader, entered as a Teensy 3.x enters it: the board's second chip
// (PJRC's bootloader chip) holds the MK64's debug port and takes over when the core halts on
// a BKPT instruction, then waits for teensy_loader_cli. The loop asks for it only disarmed
// (a USB host's 134 baud, answered in the FlightController's step); entering it stops the
// motors first, lets the loop's last messages leave on the USB port for a bounded time, and
// halts. Without the bootloader chip (a bare MK64 without a debugger) the BKPT would be a
// HardFault, whose handler keeps the outputs off.
#pragma once

#include "motors.hpp"
#include "usb/usb_serial.hpp"

namespace hq::teensy {

// How long the USB port gets to send the loop's last messages (the notice saying so).
constexpr uint32_t kBootloaderDrainUs = 20000;

[[noreturn]] void enter_bootloader(Ftm0Motors& motors, UsbCdcSerial& usb);

}  // namespace hq::teensy
