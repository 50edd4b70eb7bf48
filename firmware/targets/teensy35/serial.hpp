// UART0 telemetry on pins 0 (RX, PTB16) and 1 (TX, PTB17), 8N1, for a telemetry radio or a
// 3.3 V USB-serial cable, at the baud rate SER_TEL1_BAUD gives (921600 by default).
//
// Interrupt driven both ways: write() copies into a TX ring and enables the transmit
// interrupt, which keeps the UART's 8-byte FIFO fed; the receive interrupt moves bytes into
// an RX ring that read() drains. Telemetry is about 25 kB/s; 921600 baud carries 92 kB/s,
// so the ring absorbs a loop's burst and drains before the next one; a slower radio fills
// the ring, and per the HAL contract write() never blocks: a message that does not fit the
// ring is refused whole (returns 0; the link counts it dropped).
// Baud: UART0 runs from the core clock, baud = f / (16 (SBR + BRFA / 32)); at 120 MHz
// SBR 8, BRFA 4 gives 923 077 baud (+0.16 %).
#pragma once

#include <cstddef>
#include <cstdint>

#include "../../hal/serial.hpp"

namespace hq::teensy {

class Uart0Serial final : public SerialPort {
public:
    static constexpr size_t kTxRing = 2048, kRxRing = 1024;     // powers of two

    // False when the baud rate cannot be made within 2 % from the core clock.
    bool begin(uint32_t baud);
    size_t read(uint8_t* data, size_t n) override;
    size_t write(const uint8_t* data, size_t n) override;

    uint32_t rx_overruns() const;
};

// SBR and BRFA for a baud rate from clock_hz; false if the error would exceed 2 %. Constant
// so that main.cpp checks at compile time that every rate SER_TEL1_BAUD takes is made.
constexpr bool uart_divisor(uint32_t clock_hz, uint32_t baud, uint16_t& sbr, uint8_t& brfa) {
    if (baud == 0) return false;
    // Divisor in 1/32 steps: 32 f / (16 baud) = 2 f / baud, rounded.
    const uint64_t div32 = (2ull * clock_hz + baud / 2) / baud;
    if (div32 < 32 || div32 >= (8192ull << 5)) return false;
    sbr = static_cast<uint16_t>(div32 >> 5);
    brfa = static_cast<uint8_t>(div32 & 31u);
    const uint64_t actual_x32 = 2ull * clock_hz * 32 / div32;     // 32 x actual baud
    const uint64_t want_x32 = 32ull * baud;
    const uint64_t err = actual_x32 > want_x32 ? actual_x32 - want_x32 : want_x32 - actual_x32;
    return err * 50 <= want_x32;                                   // within 2 %
}

}  // namespace hq::teensy
