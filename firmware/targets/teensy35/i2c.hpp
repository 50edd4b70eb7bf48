// I2C0 master on pins 18 (SDA, PTB3) and 19 (SCL, PTB2): the MPU6050's bus.
//
// 375 kHz (F = 0x1D: bus 60 MHz / 160; the MPU6050 allows at most 400 kHz), glitch filter 4
// bus clocks. Once the loop tick runs, a byte's wait sleeps in WFI until the I2C0 interrupt
// (IICIF with IICIE) says the byte is done; before that (the IMU start-up) it polls. Every
// byte waits at most kByteTimeoutUs, measured with the cycle counter and checked at every
// wake-up; asleep, a bus that never answers is noticed at the next wake-up, which SysTick
// guarantees: within one tick (5 ms at 200 Hz) instead of 1 ms. A timeout, a lost
// arbitration or a bus left busy ends the transfer with false and recovers the bus: the pins
// become GPIO, SCL is clocked up to 9 times until the slave releases SDA, a STOP is made by
// hand, and the pins go back to I2C. The pins are open drain: the board needs pull-ups on
// both lines (GY-521 breakouts have them).
#pragma once

#include <cstddef>
#include <cstdint>

#include "../../hal/i2c.hpp"

namespace hq::teensy {

class I2c0Bus final : public I2cBus {
public:
    static constexpr uint32_t kByteTimeoutUs = 1000;
    static constexpr uint8_t kFrequencyDivider = 0x1D;   // ICR 0x1D: SCL divider 160
    static constexpr uint8_t kGlitchFilter = 4;
    // Its handler only wakes the thread: below the interrupts with deadlines (RC capture 4,
    // the UART FIFO at line rate 8), above nothing that waits on it; SysTick (12) stays the
    // lowest. Distinct levels keep the order of a simultaneous wake-up defined.
    static constexpr uint8_t kIrqPriority = 10;

    void begin();
    bool write(uint8_t address, uint8_t reg, const uint8_t* data, size_t n) override;
    bool read(uint8_t address, uint8_t reg, uint8_t* data, size_t n) override;

    uint32_t timeouts() const { return timeouts_; }
    uint32_t nacks() const { return nacks_; }
    uint32_t recoveries() const { return recoveries_; }
    uint32_t arbitration_lost() const { return arbitration_lost_; }

private:
    enum class Result : uint8_t { Ok, Nack, Timeout, Lost };
    bool start(uint8_t address_byte);
    Result send(uint8_t byte);
    bool wait_byte();
    bool wait_idle();
    void stop();
    bool fail(Result r);
    void recover();
    void mux_i2c();

    uint32_t timeouts_ = 0, nacks_ = 0, recoveries_ = 0, arbitration_lost_ = 0;
};

}  // namespace hq::teensy
