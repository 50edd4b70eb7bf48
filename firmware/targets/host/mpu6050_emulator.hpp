// Register-level model of an MPU6050 behind the host build's I2C bus: the unchanged driver
// talks to it exactly as to the chip. The simulator feeds it the FIFO bytes the real chip
// would produce each frame (push_fifo); the model keeps the chip's 1024-byte FIFO with its
// overflow behaviour (oldest bytes lost, INT_STATUS FIFO_OFLOW set, packets misaligned until
// a FIFO reset), WHO_AM_I, power, rate and filter registers, USER_CTRL (FIFO/DMP enable,
// self-clearing FIFO and DMP reset), INT_STATUS (cleared by reading), FIFO_COUNT, FIFO_R_W,
// and the bank/start-address/R_W window onto DMP memory with address auto-increment.
// Faults for tests (HQ_IMU_FAULT on the sim link): silent (answers, produces no data), absent
// (every transfer NACKs), a power-on reset (registers, FIFO and DMP memory lost), and a FIFO
// overflow.
#pragma once

#include <cstddef>
#include <cstdint>

#include "../../hal/i2c.hpp"

namespace hq {

class Mpu6050Emulator final : public I2cBus {
public:
    static constexpr uint16_t kFifoSize = 1024;
    static constexpr uint16_t kMemorySize = 4096;   // 16 banks of 256 bytes

    Mpu6050Emulator();

    bool write(uint8_t address, uint8_t reg, const uint8_t* data, size_t n) override;
    bool read(uint8_t address, uint8_t reg, uint8_t* data, size_t n) override;

    // Data the chip produced since the last frame. Accepted only when the FIFO is enabled
    // and configured for that kind of data (DMP packets need DMP_EN; raw samples need
    // FIFO_EN = gyro+accel); returns the number of bytes accepted.
    size_t push_fifo(const uint8_t* data, size_t n, bool dmp_packets);

    bool dmp_enabled() const;
    bool raw_fifo_enabled() const;
    uint16_t fifo_count() const { return count_; }
    uint8_t reg(uint8_t r) const { return regs_[r & 0x7F]; }
    const uint8_t* memory() const { return memory_; }
    void set_present(bool present) { present_ = present; }   // false: every transfer NACKs
    void set_silent(bool silent) { silent_ = silent; }        // true: push_fifo() takes nothing
    // Power-on defaults, as after a brown-out: registers, FIFO and DMP memory are lost.
    void power_on_reset();
    // Fills the FIFO past its 1024 bytes with data the driver cannot parse, as a loop that
    // stalled for a while would find it: FIFO_OFLOW set, packets misaligned. Only when the
    // FIFO is enabled (a disabled FIFO cannot overflow).
    void force_overflow();

private:
    void reset();
    void write_register(uint8_t reg, uint8_t value);
    uint8_t read_register(uint8_t reg);
    uint8_t pop_fifo();
    void append(uint8_t byte);

    uint8_t regs_[128];
    uint8_t memory_[kMemorySize];
    uint8_t fifo_[kFifoSize];
    uint16_t head_ = 0, count_ = 0;       // ring buffer: oldest byte at head_
    uint16_t mem_address_ = 0;
    bool present_ = true;
    bool silent_ = false;
};

}  // namespace hq
