// Register-level model of an MPU6050, a part of the simulator's sensor: behind the host build's
// I2C bus (firmware/targets/host) and behind the emulated MK64's I2C0 (chip/), the unchanged
// driver talks to it exactly as to the chip. Built for the host only (library hq_host_devices),
// never into the Teensy image. The simulator feeds it the FIFO bytes the real chip would
// produce each frame (push_fifo); the model keeps the chip's 1024-byte FIFO with its overflow
// behaviour (oldest bytes lost, INT_STATUS FIFO_OFLOW set, packets misaligned until a FIFO
// reset), WHO_AM_I, power, rate and filter registers, USER_CTRL (FIFO/DMP enable, self-clearing
// FIFO and DMP reset), INT_STATUS (cleared by reading), FIFO_COUNT, FIFO_R_W, and the
// bank/start-address/R_W window onto DMP memory with address auto-increment. Faults for tests
// (HQ_IMU_FAULT on the sim link): silent (answers, produces no data), absent (every transfer
// NACKs), a power-on reset (registers, FIFO and DMP memory lost), a FIFO overflow, and a stuck
// DMP memory byte (it ignores writes).
//
// The DMP: the model runs no DMP code (the simulator computes the packets), but it checks that
// the driver set the DMP up as MotionApps 2.0 does before it accepts DMP packets. Given the
// reference firmware (set_dmp_reference: the image, the configuration table and the update
// table the DMP is to run), it follows the DMP memory writes since the last reset: the image
// from address 0, byte by byte and in order; then every configuration-table entry in the
// table's order (memory entries with their data, except the FIFO rate divisor's, which is the
// driver's choice; the special entry 0x01 as INT_ENABLE = 0x32); then the seven updates in
// order, 1-2 with the DMP off and 3-7 with it on. The first write out of that order is
// recorded with its reason and the chip stays unconfigured until the next reset. DMP packets
// are accepted only when all of it happened and DMP_CFG_1/2 hold 0x03/0x00 (dmp_configured(),
// dmp_status() says why not). What the model cannot check is whether the reference itself is
// InvenSense's: that is the rig's job.
#pragma once

#include <cstddef>
#include <cstdint>

#include "core/mpu6050.hpp"
#include "hal/i2c.hpp"

namespace hq {

class Mpu6050Emulator final : public I2cBus {
public:
    static constexpr uint16_t kFifoSize = 1024;
    static constexpr uint16_t kMemorySize = mpu6050::kDmpMemorySize;   // 8 banks of 256 bytes
    static constexpr uint16_t kMaxTable = 1024;    // longest configuration or update table kept

    // How far the DMP set-up has come since the last reset (in the reference's order).
    struct DmpProgress {
        uint16_t image_bytes = 0;      // of the image, written in order from address 0
        uint16_t config_entries = 0;   // configuration-table entries applied, in order
        uint16_t updates = 0;          // update-table entries applied, in order
    };

    Mpu6050Emulator();

    bool write(uint8_t address, uint8_t reg, const uint8_t* data, size_t n) override;
    bool read(uint8_t address, uint8_t reg, uint8_t* data, size_t n) override;

    // Data the chip produced since the last frame. Accepted only when the FIFO is enabled
    // and configured for that kind of data (DMP packets need DMP_EN; raw samples need
    // FIFO_EN = gyro+accel); returns the number of bytes accepted.
    size_t push_fifo(const uint8_t* data, size_t n, bool dmp_packets);

    // The DMP firmware the chip is to run (copied). False, and no reference, when a size is out
    // of range or a table does not parse. Resets the set-up check.
    bool set_dmp_reference(const uint8_t* image, uint16_t image_size, const uint8_t* config,
                           uint16_t config_size, const uint8_t* updates, uint16_t updates_size);
    // True when the whole MotionApps set-up has been applied since the last reset.
    bool dmp_configured() const;
    // "configured", or why not (one line).
    const char* dmp_status() const;
    const DmpProgress& dmp_progress() const { return progress_; }
    uint16_t dmp_config_entries() const { return config_entries_; }
    // A DMP memory byte that ignores writes (a fault for tests); kMemorySize for none.
    void set_stuck_memory_byte(uint16_t address) { stuck_ = address; }

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
    void memory_written(uint16_t address, uint8_t value);
    void register_written(uint8_t reg, uint8_t value);
    void table_write(const uint8_t* table, uint16_t size, uint16_t& done, const char* name,
                     uint16_t address, uint8_t value);
    bool holds(uint16_t address, const uint8_t* data, uint16_t n, bool rate) const;
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
    uint16_t stuck_ = kMemorySize;

    // The reference DMP firmware and the check of its set-up.
    uint8_t ref_image_[kMemorySize];
    uint8_t ref_config_[kMaxTable];
    uint8_t ref_updates_[kMaxTable];
    uint16_t ref_image_size_ = 0, ref_config_size_ = 0, ref_updates_size_ = 0;
    uint16_t config_entries_ = 0, update_entries_ = 0;
    DmpProgress progress_{};
    uint16_t entry_byte_ = 0;             // bytes of the current table entry written
    bool refused_ = false;                // an out-of-order write since the last reset
    char refusal_[160] = {};              // why (dmp_status())
    mutable char status_[160] = {};
};

}  // namespace hq
