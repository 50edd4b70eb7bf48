#include "sensor/mpu6050_emulator.hpp"

#include <cstdio>
#include <cstring>

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
    progress_ = DmpProgress{};             // after a reset the DMP must be set up again
    entry_byte_ = 0;
    refused_ = false;
    refusal_[0] = '\0';
}

bool Mpu6050Emulator::set_dmp_reference(const uint8_t* image, uint16_t image_size,
                                        const uint8_t* config, uint16_t config_size,
                                        const uint8_t* updates, uint16_t updates_size) {
    ref_image_size_ = ref_config_size_ = ref_updates_size_ = 0;
    config_entries_ = update_entries_ = 0;
    reset();
    if (image == nullptr || image_size == 0 || image_size > kMemorySize || config == nullptr ||
        config_size > kMaxTable || updates == nullptr || updates_size > kMaxTable) {
        return false;
    }
    const int n_config = count_dmp_entries(config, config_size, true);
    const int n_updates = count_dmp_entries(updates, updates_size, false);
    if (n_config < 1 || n_updates != kDmpUpdateCount) return false;
    std::memcpy(ref_image_, image, image_size);
    std::memcpy(ref_config_, config, config_size);
    std::memcpy(ref_updates_, updates, updates_size);
    ref_image_size_ = image_size;
    ref_config_size_ = config_size;
    ref_updates_size_ = updates_size;
    config_entries_ = static_cast<uint16_t>(n_config);
    update_entries_ = static_cast<uint16_t>(n_updates);
    return true;
}

namespace {
// The index-th entry of a table that count_dmp_entries() accepted.
DmpTableEntry entry_at(const uint8_t* table, uint16_t size, uint16_t index) {
    uint16_t pos = 0;
    DmpTableEntry e;
    for (uint16_t i = 0; i <= index; ++i) next_dmp_entry(table, size, pos, e);
    return e;
}
}  // namespace

bool Mpu6050Emulator::holds(uint16_t address, const uint8_t* data, uint16_t n, bool rate) const {
    if (rate) return true;                 // the divisor is the driver's choice
    for (uint16_t i = 0; i < n; ++i) {
        if (memory_[(address + i) % kMemorySize] != data[i]) return false;
    }
    return true;
}

void Mpu6050Emulator::table_write(const uint8_t* table, uint16_t size, uint16_t& done,
                                  const char* name, uint16_t address, uint8_t value) {
    const uint16_t total = table == ref_config_ ? config_entries_ : update_entries_;
    const DmpTableEntry e = entry_at(table, size, done);
    const unsigned due = static_cast<unsigned>(done) + 1;
    if (e.length == 0) {
        std::snprintf(refusal_, sizeof refusal_,
                      "%s entry %u of %u (special 0x%02X: INT_ENABLE = 0x%02X) was due; got a "
                      "memory write at bank %u offset 0x%02X",
                      name, due, total, e.special, kDmpSpecialIntEnableValue, address / kBankSize,
                      address % kBankSize);
        refused_ = true;
        return;
    }
    if (address != e.address() + entry_byte_ || (!e.is_rate() && value != e.data[entry_byte_])) {
        // Name the entry that starts at this address, if one does: an entry out of order.
        int other = -1;
        for (uint16_t i = 0; i < total && entry_byte_ == 0; ++i) {
            if (i != done && entry_at(table, size, i).address() == address) {
                other = i + 1;
                break;
            }
        }
        char which[40] = "";
        if (other > 0) std::snprintf(which, sizeof which, " (entry %d's address)", other);
        std::snprintf(refusal_, sizeof refusal_,
                      "%s entry %u of %u (bank %u offset 0x%02X, byte %u) was due; got a write at "
                      "bank %u offset 0x%02X%s",
                      name, due, total, e.bank, e.offset, entry_byte_ + 1u, address / kBankSize,
                      address % kBankSize, which);
        refused_ = true;
        return;
    }
    if (++entry_byte_ < e.length) return;
    entry_byte_ = 0;
    if (!holds(e.address(), e.data, e.length, e.is_rate())) {
        std::snprintf(refusal_, sizeof refusal_,
                      "%s entry %u of %u (bank %u offset 0x%02X): DMP memory does not hold it "
                      "after the write", name, due, total, e.bank, e.offset);
        refused_ = true;
        return;
    }
    ++done;
}

void Mpu6050Emulator::memory_written(uint16_t address, uint8_t value) {
    if (refused_ || ref_image_size_ == 0) return;
    if (progress_.image_bytes < ref_image_size_) {
        if (address != progress_.image_bytes || value != ref_image_[address]) {
            std::snprintf(refusal_, sizeof refusal_,
                          "image byte %u of %u was due; got a write at bank %u offset 0x%02X",
                          progress_.image_bytes + 1u, static_cast<unsigned>(ref_image_size_),
                          address / kBankSize, address % kBankSize);
            refused_ = true;
        } else if (++progress_.image_bytes == ref_image_size_ &&
                   !holds(0, ref_image_, ref_image_size_, false)) {
            std::snprintf(refusal_, sizeof refusal_,
                          "image: DMP memory does not hold it after the upload");
            refused_ = true;
        }
        return;
    }
    if (progress_.config_entries < config_entries_) {
        table_write(ref_config_, ref_config_size_, progress_.config_entries, "configuration",
                    address, value);
        return;
    }
    if (progress_.updates < update_entries_) {
        // MotionApps writes updates 1-2 with the DMP off, 3-7 with it running.
        const bool running = (regs_[USER_CTRL] & USER_DMP_EN) != 0;
        if (entry_byte_ == 0 && running != (progress_.updates >= kDmpUpdateGroups[0])) {
            std::snprintf(refusal_, sizeof refusal_,
                          "update %u of %u was written with the DMP %s (MotionApps: updates 1-%u "
                          "with it off, the rest with it on)",
                          progress_.updates + 1u, static_cast<unsigned>(update_entries_),
                          running ? "on" : "off", static_cast<unsigned>(kDmpUpdateGroups[0]));
            refused_ = true;
            return;
        }
        table_write(ref_updates_, ref_updates_size_, progress_.updates, "update", address, value);
        return;
    }
    std::snprintf(refusal_, sizeof refusal_,
                  "a DMP memory write at bank %u offset 0x%02X after the set-up was complete",
                  address / kBankSize, address % kBankSize);
    refused_ = true;
}

void Mpu6050Emulator::register_written(uint8_t reg, uint8_t value) {
    // The configuration table's special entry: INT_ENABLE = 0x32, in its place in the table.
    if (reg != INT_ENABLE || refused_ || ref_image_size_ == 0 ||
        progress_.image_bytes < ref_image_size_ || progress_.config_entries >= config_entries_ ||
        entry_byte_ != 0) {
        return;
    }
    const DmpTableEntry e = entry_at(ref_config_, ref_config_size_, progress_.config_entries);
    if (e.length != 0) return;             // an INT_ENABLE write of the driver's own
    if (value != kDmpSpecialIntEnableValue) {
        std::snprintf(refusal_, sizeof refusal_,
                      "configuration entry %u of %u (special 0x%02X) wants INT_ENABLE = 0x%02X; "
                      "got 0x%02X",
                      progress_.config_entries + 1u, static_cast<unsigned>(config_entries_),
                      e.special, kDmpSpecialIntEnableValue, value);
        refused_ = true;
        return;
    }
    ++progress_.config_entries;
}

bool Mpu6050Emulator::dmp_configured() const {
    return ref_image_size_ > 0 && !refused_ && progress_.image_bytes == ref_image_size_ &&
           progress_.config_entries == config_entries_ && progress_.updates == update_entries_ &&
           regs_[DMP_CFG_1] == DMP_CFG_1_VALUE && regs_[DMP_CFG_2] == DMP_CFG_2_VALUE;
}

const char* Mpu6050Emulator::dmp_status() const {
    if (ref_image_size_ == 0) return "no reference DMP firmware (set_dmp_reference)";
    if (refused_) return refusal_;
    if (progress_.image_bytes < ref_image_size_) {
        std::snprintf(status_, sizeof status_, "image: %u of %u bytes written",
                      static_cast<unsigned>(progress_.image_bytes),
                      static_cast<unsigned>(ref_image_size_));
    } else if (progress_.config_entries < config_entries_) {
        const DmpTableEntry e = entry_at(ref_config_, ref_config_size_, progress_.config_entries);
        std::snprintf(status_, sizeof status_,
                      "configuration: %u of %u entries applied; entry %u (bank %u offset 0x%02X%s) "
                      "not written",
                      static_cast<unsigned>(progress_.config_entries),
                      static_cast<unsigned>(config_entries_), progress_.config_entries + 1u,
                      e.bank, e.offset, e.length == 0 ? ", special" : "");
    } else if (progress_.updates < update_entries_) {
        std::snprintf(status_, sizeof status_, "updates: %u of %u applied",
                      static_cast<unsigned>(progress_.updates),
                      static_cast<unsigned>(update_entries_));
    } else if (regs_[DMP_CFG_1] != DMP_CFG_1_VALUE || regs_[DMP_CFG_2] != DMP_CFG_2_VALUE) {
        std::snprintf(status_, sizeof status_, "DMP_CFG_1/2 are 0x%02X/0x%02X, not 0x%02X/0x%02X",
                      regs_[DMP_CFG_1], regs_[DMP_CFG_2], DMP_CFG_1_VALUE, DMP_CFG_2_VALUE);
    } else {
        return "configured";
    }
    return status_;
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
    // DMP packets need the DMP running and set up as MotionApps sets it up.
    if (silent_ || (dmp_packets ? !(dmp_enabled() && dmp_configured()) : !raw_fifo_enabled())) {
        return 0;
    }
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
            // The reset bits clear themselves.
            regs_[reg] = value & static_cast<uint8_t>(~(USER_FIFO_RESET | USER_DMP_RESET |
                                                        USER_I2C_MST_RESET | USER_SIG_COND_RESET));
            return;
        case MEM_START_ADDR:
            regs_[reg] = value;
            mem_address_ = static_cast<uint16_t>((regs_[BANK_SEL] * 256 + value) % kMemorySize);
            return;
        case BANK_SEL:
            regs_[reg] = value;
            mem_address_ = static_cast<uint16_t>((value * 256 + regs_[MEM_START_ADDR]) % kMemorySize);
            return;
        case MEM_R_W:
            if (mem_address_ != stuck_) memory_[mem_address_ % kMemorySize] = value;
            memory_written(mem_address_, value);
            mem_address_ = static_cast<uint16_t>((mem_address_ + 1) % kMemorySize);
            return;
        case INT_ENABLE:
            regs_[reg] = value;
            register_written(reg, value);
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
