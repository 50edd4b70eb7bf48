#include "mpu6050_emulator.hpp"

#include <cstring>

#include "../../core/mpu6050.hpp"

namespace hq {

using namespace mpu6050;

Mpu6050Emulator::Mpu6050Emulator() {
    std::memset(memory_, 0, sizeof(memory_));
    reset();
}

void Mpu6050Emulator::reset() {
    std::memset(regs_, 0, sizeof(regs_));
    regs_[PWR_MGMT_1] = 0x40;                 // SLEEP after reset (register map reset value)
    regs_[WHO_AM_I] = WHO_AM_I_VALUE;
    head_ = count_ = 0;
    mem_address_ = 0;
}

void Mpu6050Emulator::power_on_reset() {
    std::memset(memory_, 0, sizeof(memory_));
    reset();
}

void Mpu6050Emulator::force_overflow() {
    if (!(regs_[USER_CTRL] & USER_FIFO_EN)) return;
    // One byte more than the FIFO holds, none of it at a packet boundary: the oldest byte is
    // lost and FIFO_OFLOW is set, exactly as when the chip overruns.
    for (uint16_t i = 0; i <= kFifoSize; ++i) append(static_cast<uint8_t>(0xA5 ^ i));
}

void Mpu6050Emulator::append(uint8_t byte) {
    if (count_ == kFifoSize) {                // full: the oldest byte is lost
        head_ = static_cast<uint16_t>((head_ + 1) % kFifoSize);
        --count_;
        regs_[INT_STATUS] |= INT_FIFO_OFLOW;
    }
    fifo_[(head_ + count_) % kFifoSize] = byte;
    ++count_;
}

bool Mpu6050Emulator::dmp_enabled() const {
    return (regs_[USER_CTRL] & USER_DMP_EN) && (regs_[USER_CTRL] & USER_FIFO_EN);
}

bool Mpu6050Emulator::raw_fifo_enabled() const {
    return (regs_[USER_CTRL] & USER_FIFO_EN) && regs_[FIFO_EN] == FIFO_EN_GYRO_ACCEL &&
           !(regs_[USER_CTRL] & USER_DMP_EN);
}

size_t Mpu6050Emulator::push_fifo(const uint8_t* data, size_t n, bool dmp_packets) {
    if (silent_ || (dmp_packets ? !dmp_enabled() : !raw_fifo_enabled())) return 0;
    for (size_t i = 0; i < n; ++i) append(data[i]);
    if (n > 0) regs_[INT_STATUS] |= dmp_packets ? INT_DMP : INT_DATA_RDY;
    return n;
}

uint8_t Mpu6050Emulator::pop_fifo() {
    if (count_ == 0) return 0xFF;
    const uint8_t b = fifo_[head_];
    head_ = static_cast<uint16_t>((head_ + 1) % kFifoSize);
    --count_;
    return b;
}

void Mpu6050Emulator::write_register(uint8_t reg, uint8_t value) {
    switch (reg) {
        case PWR_MGMT_1:
            if (value & PWR_DEVICE_RESET) {
                reset();
                return;
            }
            regs_[reg] = value;
            return;
        case USER_CTRL:
            if (value & USER_FIFO_RESET) head_ = count_ = 0;
            regs_[reg] = value & static_cast<uint8_t>(~(USER_FIFO_RESET | USER_DMP_RESET));
            return;
        case MEM_START_ADDR:
            regs_[reg] = value;
            mem_address_ = static_cast<uint16_t>(regs_[BANK_SEL] * 256 + value);
            return;
        case BANK_SEL:
            regs_[reg] = value;
            mem_address_ = static_cast<uint16_t>(value * 256 + regs_[MEM_START_ADDR]);
            return;
        case MEM_R_W:
            memory_[mem_address_ % kMemorySize] = value;
            mem_address_ = static_cast<uint16_t>((mem_address_ + 1) % kMemorySize);
            return;
        case FIFO_R_W:
        case WHO_AM_I:
        case INT_STATUS:
        case FIFO_COUNT_H:
        case FIFO_COUNT_H + 1:
            return;                           // read-only
        default:
            regs_[reg & 0x7F] = value;
    }
}

uint8_t Mpu6050Emulator::read_register(uint8_t reg) {
    switch (reg) {
        case INT_STATUS: {
            const uint8_t s = regs_[INT_STATUS];
            regs_[INT_STATUS] = 0;            // cleared by reading
            return s;
        }
        case FIFO_COUNT_H: return static_cast<uint8_t>(count_ >> 8);
        case FIFO_COUNT_H + 1: return static_cast<uint8_t>(count_ & 0xFF);
        case FIFO_R_W: return pop_fifo();
        case MEM_R_W: {
            const uint8_t b = memory_[mem_address_ % kMemorySize];
            mem_address_ = static_cast<uint16_t>((mem_address_ + 1) % kMemorySize);
            return b;
        }
        default: return regs_[reg & 0x7F];
    }
}

bool Mpu6050Emulator::write(uint8_t address, uint8_t reg, const uint8_t* data, size_t n) {
    if (!present_ || address != kAddress) return false;
    for (size_t i = 0; i < n; ++i) {
        // FIFO_R_W and MEM_R_W stay put; other registers auto-increment.
        const uint8_t r = (reg == FIFO_R_W || reg == MEM_R_W) ? reg : static_cast<uint8_t>(reg + i);
        write_register(r, data[i]);
    }
    return true;
}

bool Mpu6050Emulator::read(uint8_t address, uint8_t reg, uint8_t* data, size_t n) {
    if (!present_ || address != kAddress) return false;
    for (size_t i = 0; i < n; ++i) {
        const uint8_t r = (reg == FIFO_R_W || reg == MEM_R_W) ? reg : static_cast<uint8_t>(reg + i);
        data[i] = read_register(r);
    }
    return true;
}

}  // namespace hq
