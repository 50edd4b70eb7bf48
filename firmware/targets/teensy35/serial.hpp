// UART0 telemetry on pins 0 (RX, PTB16) and 1 (TX, PTB17) at 921600 baud, 8N1, for a 3.3 V
// USB-serial cable.
//
// Interrupt driven both ways: write() copies into a TX ring and enables the transmit
// interrupt, which keeps the UART's 8-byte FIFO fed; the receive interrupt moves bytes into
// an RX ring that read() drains. Telemetry is about 22 kB/s; 921600 baud carries 92 kB/s,
// so the ring absorbs a loop's burst and drains before the next one. Per the HAL contract
// write() never blocks: a message that does not fit the ring is refused whole (returns 0).
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

// SBR and BRFA for a baud rate from clock_hz; false if the error would exceed 2 %.
bool uart_divisor(uint32_t clock_hz, uint32_t baud, uint16_t& sbr, uint8_t& brfa);

}  // namespace hq::teensy
