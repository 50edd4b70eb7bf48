#include "mpu6050.hpp"

#include <cmath>

namespace hq {

using namespace mpu6050;

namespace {
int16_t be16(const uint8_t* p) { return static_cast<int16_t>((p[0] << 8) | p[1]); }

// Three big-endian int16 at `p`, `stride` bytes apart: does any read full scale?
bool any_full_scale(const uint8_t* p, int stride) {
    for (int i = 0; i < 3; ++i) {
        const int16_t v = be16(p + i * stride);
        if (v == INT16_MAX || v == INT16_MIN) return true;
    }
    return false;
}
int32_t be32(const uint8_t* p) {
    return static_cast<int32_t>((static_cast<uint32_t>(p[0]) << 24) |
                                (static_cast<uint32_t>(p[1]) << 16) |
                                (static_cast<uint32_t>(p[2]) << 8) | p[3]);
}
constexpr float kDegToRad = 0.017453292519943295f;
// The chip's scales in the driver's single precision.
constexpr float kGyroLsb = static_cast<float>(kGyroLsbPerDegS);
constexpr float kAccelLsb = static_cast<float>(kAccelLsbPerG);
constexpr float kQ30 = static_cast<float>(kQuatScale);
// A DMP quaternion whose norm is this far from 1 is misaligned data, not an attitude.
constexpr float kQuatNormTolerance = 0.05f;
// Start-up waits (MotionApps' own): after the I2C master reset, and per poll of the FIFO count
// while the DMP settles.
constexpr uint32_t kMasterResetWaitUs = 20000, kSettlePollUs = 1000;
}  // namespace

namespace mpu6050 {

bool next_dmp_entry(const uint8_t* table, uint16_t size, uint16_t& pos, DmpTableEntry& out) {
    if (table == nullptr || size < 3 || pos > size - 3) return false;
    out = DmpTableEntry{};
    out.bank = table[pos];
    out.offset = table[pos + 1];
    out.length = table[pos + 2];
    const uint16_t body = out.length == 0 ? 1 : out.length;     // a special: its code byte
    if (body > size - pos - 3) return false;
    if (out.length == 0) {
        out.special = table[pos + 3];
    } else {
        out.data = table + pos + 3;
    }
    pos = static_cast<uint16_t>(pos + 3 + body);
    return true;
}

int count_dmp_entries(const uint8_t* table, uint16_t size, bool specials_allowed) {
    uint16_t pos = 0;
    int n = 0;
    DmpTableEntry e;
    while (next_dmp_entry(table, size, pos, e)) {
        if (e.length == 0 && (!specials_allowed || e.special != kDmpSpecialIntEnable)) return -1;
        if (e.address() + e.length > kDmpMemorySize) return -1;
        ++n;
    }
    return pos == size && n > 0 ? n : -1;
}

}  // namespace mpu6050

ImuHealth Mpu6050::probe(I2cBus& bus) {
    uint8_t who = 0, power = 0, user = 0;
    if (!read_reg(bus, WHO_AM_I, who) || who != WHO_AM_I_VALUE) return ImuHealth::NoAnswer;
    if (mode_ == SensorMode::None) return ImuHealth::Unconfigured;
    if (!read_reg(bus, PWR_MGMT_1, power) || !read_reg(bus, USER_CTRL, user)) {
        return ImuHealth::NoAnswer;
    }
    const uint8_t running = static_cast<uint8_t>(
        mode_ == SensorMode::Dmp ? USER_DMP_EN | USER_FIFO_EN : USER_FIFO_EN);
    const uint8_t clock = mode_ == SensorMode::Dmp ? PWR_CLK_PLL_ZGYRO : PWR_CLK_PLL_XGYRO;
    if (power != clock || (user & running) != running) return ImuHealth::Unconfigured;
    return ImuHealth::Configured;
}

float Mpu6050::sample_rate_hz() const {
    // CONFIG DLPF_CFG 0 and 7 turn the filter off (register map rev 4.2, section 4.3).
    const float gyro_hz = (config_.dlpf == 0 || config_.dlpf == 7) ? 8000.0f : 1000.0f;
    const float raw_hz = gyro_hz / (1.0f + static_cast<float>(config_.sample_rate_div));
    const bool dmp = mode_ == SensorMode::Dmp ||
                     (mode_ == SensorMode::None && config_.dmp_image != nullptr &&
                      config_.dmp_config != nullptr && config_.dmp_updates != nullptr);
    return dmp ? raw_hz / (1.0f + static_cast<float>(config_.dmp_rate_div)) : raw_hz;
}

uint16_t Mpu6050::packet_size() const {
    return mode_ == SensorMode::Dmp ? kDmpPacketSize : kRawPacketSize;
}

bool Mpu6050::write_reg(I2cBus& bus, uint8_t reg, uint8_t value) {
    if (bus.write(config_.address, reg, &value, 1)) return true;
    ++counters_.bus_errors;
    return false;
}

bool Mpu6050::read_reg(I2cBus& bus, uint8_t reg, uint8_t& value) {
    if (bus.read(config_.address, reg, &value, 1)) return true;
    ++counters_.bus_errors;
    return false;
}

InitResult Mpu6050::wake(I2cBus& bus, Clock& clock) {
    if (!write_reg(bus, PWR_MGMT_1, PWR_DEVICE_RESET)) return InitResult::NoDevice;
    clock.delay_us(100000);                       // reset takes up to 100 ms
    uint8_t who = 0;
    if (!write_reg(bus, PWR_MGMT_1, PWR_CLK_PLL_XGYRO) || !read_reg(bus, WHO_AM_I, who)) {
        return InitResult::BusError;
    }
    if (who != WHO_AM_I_VALUE) return InitResult::NoDevice;
    clock.delay_us(10000);                        // PLL settles
    return InitResult::OkRaw;
}

bool Mpu6050::configure_raw(I2cBus& bus) {
    return write_reg(bus, SMPLRT_DIV, config_.sample_rate_div) &&
           write_reg(bus, CONFIG, config_.dlpf) && write_reg(bus, GYRO_CONFIG, GYRO_FS_2000DPS) &&
           write_reg(bus, ACCEL_CONFIG, ACCEL_FS_2G);
}

InitResult Mpu6050::init(I2cBus& bus, Clock& clock) {
    mode_ = SensorMode::None;
    dmp_failure_ = DmpStep::None;
    InitResult woke = wake(bus, clock);
    if (woke != InitResult::OkRaw) return woke;
    InitResult result = InitResult::OkRaw;
    if (config_.dmp_image != nullptr && config_.dmp_image_size > 0) {
        if (init_dmp(bus, clock)) {
            mode_ = SensorMode::Dmp;
            if (start_fifo(bus)) return InitResult::OkDmp;
            mode_ = SensorMode::None;
            return InitResult::BusError;
        }
        // The chip is left half set up (DMP memory, interrupts, I2C master): start again from
        // a reset for the raw path.
        result = InitResult::OkRawFallback;
        woke = wake(bus, clock);
        if (woke != InitResult::OkRaw) return woke;
    }
    mode_ = SensorMode::Raw;
    if (!configure_raw(bus) || !start_fifo(bus)) {
        mode_ = SensorMode::None;
        return InitResult::BusError;
    }
    return result;
}

bool Mpu6050::fail(DmpStep step) {
    dmp_failure_ = step;
    return false;
}

// MotionApps 2.0's dmpInitialize, after the reset and wake-up that init() has done; the steps
// are numbered as in docs/mpu6050.md ("DMP path").
bool Mpu6050::init_dmp(I2cBus& bus, Clock& clock) {
    // Both tables must be there and parse, before anything is written.
    if (config_.dmp_image_size > kDmpMemorySize || config_.dmp_config == nullptr ||
        config_.dmp_updates == nullptr ||
        count_dmp_entries(config_.dmp_config, config_.dmp_config_size, true) < 0 ||
        count_dmp_entries(config_.dmp_updates, config_.dmp_updates_size, false) != kDmpUpdateCount) {
        return fail(DmpStep::Tables);
    }
    // 2. The gyro offset TC registers, to be written back after the configuration.
    uint8_t tc[3] = {0, 0, 0};
    if (!bus.read(config_.address, XG_OFFS_TC, tc, 3)) {
        ++counters_.bus_errors;
        return fail(DmpStep::Registers);
    }
    // 3. The auxiliary I2C master: slave 0 pointed away and back, master off and reset.
    if (!write_reg(bus, I2C_SLV0_ADDR, kSlaveAddressDummy) || !write_reg(bus, USER_CTRL, 0x00) ||
        !write_reg(bus, I2C_SLV0_ADDR, config_.address) ||
        !write_reg(bus, USER_CTRL, USER_I2C_MST_RESET)) {
        return fail(DmpStep::Registers);
    }
    clock.delay_us(kMasterResetWaitUs);
    // 4. The image, from bank 0, offset 0.
    if (!write_dmp_memory(bus, 0, config_.dmp_image, config_.dmp_image_size)) {
        return fail(DmpStep::Image);
    }
    // 5. The configuration table.
    if (!apply_config(bus)) return false;
    // 6. The registers.
    if (!dmp_registers(bus, tc)) return fail(DmpStep::Registers);
    // 7. Updates 1 and 2.
    uint16_t pos = 0;
    if (!apply_updates(bus, pos, kDmpUpdateGroups[0])) return false;
    // 8. Empty the FIFO; 9. the motion-detection thresholds; 10. FIFO on, DMP on and reset.
    if (!write_reg(bus, USER_CTRL, USER_FIFO_RESET) || !drain_fifo(bus) ||
        !write_reg(bus, MOT_THR, kMotThr) || !write_reg(bus, ZRMOT_THR, kZrmotThr) ||
        !write_reg(bus, MOT_DUR, kMotDur) || !write_reg(bus, ZRMOT_DUR, kZrmotDur) ||
        !write_reg(bus, USER_CTRL, USER_FIFO_RESET) || !write_reg(bus, USER_CTRL, USER_FIFO_EN) ||
        !write_reg(bus, USER_CTRL, USER_FIFO_EN | USER_DMP_EN) ||
        !write_reg(bus, USER_CTRL, USER_FIFO_EN | USER_DMP_EN | USER_DMP_RESET)) {
        return fail(DmpStep::Registers);
    }
    // 11. Updates 3 to 5 with the DMP running; 12. let it run; update 6; 13. run; update 7.
    if (!apply_updates(bus, pos, kDmpUpdateGroups[1])) return false;
    if (!settle_dmp(bus, clock)) return fail(DmpStep::Registers);
    if (!apply_updates(bus, pos, kDmpUpdateGroups[2])) return false;
    if (!settle_dmp(bus, clock)) return fail(DmpStep::Registers);
    if (!apply_updates(bus, pos, kDmpUpdateGroups[3])) return false;
    // 14. DMP off, FIFO emptied, interrupt status cleared; start_fifo() turns the DMP on.
    uint8_t status = 0;
    if (!write_reg(bus, USER_CTRL, USER_FIFO_EN) ||
        !write_reg(bus, USER_CTRL, USER_FIFO_EN | USER_FIFO_RESET) ||
        !read_reg(bus, INT_STATUS, status)) {
        return fail(DmpStep::Registers);
    }
    return true;
}

bool Mpu6050::apply_config(I2cBus& bus) {
    uint16_t pos = 0;
    DmpTableEntry e;
    while (next_dmp_entry(config_.dmp_config, config_.dmp_config_size, pos, e)) {
        if (e.length == 0) {                      // count_dmp_entries() allowed only 0x01
            if (!write_reg(bus, INT_ENABLE, kDmpSpecialIntEnableValue)) return fail(DmpStep::Config);
            continue;
        }
        // The FIFO rate divisor is ours (Mpu6050Config::dmp_rate_div), not the table's.
        const uint8_t rate[2] = {0x00, config_.dmp_rate_div};
        if (!write_dmp_memory(bus, e.address(), e.is_rate() ? rate : e.data, e.length)) {
            return fail(DmpStep::Config);
        }
    }
    return true;
}

bool Mpu6050::dmp_registers(I2cBus& bus, const uint8_t tc[3]) {
    // MotionApps' order. ACCEL_CONFIG is ours: MotionApps leaves it at its reset value, the
    // same +/-2 g.
    return write_reg(bus, PWR_MGMT_1, PWR_CLK_PLL_ZGYRO) &&
           write_reg(bus, INT_ENABLE, INT_DMP | INT_FIFO_OFLOW) &&
           write_reg(bus, SMPLRT_DIV, config_.sample_rate_div) &&
           write_reg(bus, CONFIG, static_cast<uint8_t>(CONFIG_EXT_SYNC_TEMP_OUT_L | config_.dlpf)) &&
           write_reg(bus, GYRO_CONFIG, GYRO_FS_2000DPS) && write_reg(bus, ACCEL_CONFIG, ACCEL_FS_2G) &&
           write_reg(bus, DMP_CFG_1, DMP_CFG_1_VALUE) && write_reg(bus, DMP_CFG_2, DMP_CFG_2_VALUE) &&
           write_reg(bus, XG_OFFS_TC, static_cast<uint8_t>(tc[0] & ~TC_OTP_BNK_VLD)) &&
           write_reg(bus, YG_OFFS_TC, tc[1]) && write_reg(bus, ZG_OFFS_TC, tc[2]);
}

bool Mpu6050::apply_updates(I2cBus& bus, uint16_t& pos, uint8_t count) {
    DmpTableEntry e;
    for (uint8_t i = 0; i < count; ++i) {
        if (!next_dmp_entry(config_.dmp_updates, config_.dmp_updates_size, pos, e) ||
            !write_dmp_memory(bus, e.address(), e.data, e.length)) {
            return fail(DmpStep::Updates);
        }
    }
    return true;
}

bool Mpu6050::settle_dmp(I2cBus& bus, Clock& clock) {
    // MotionApps waits (without a limit) for more than 2 bytes of DMP output. Here the wait is
    // bounded by two DMP output periods plus 10 ms, and its end is not an error: a DMP that
    // never produces output is caught later by the IMU timeout. (The emulated chip gets data
    // only from the simulator's frames, so in the SIL the wait always runs out, instantly.)
    const float period_us = 1e6f / sample_rate_hz();
    const uint32_t polls = static_cast<uint32_t>(2.0f * period_us / static_cast<float>(kSettlePollUs)) + 10u;
    for (uint32_t i = 0; i < polls; ++i) {
        uint8_t count_be[2] = {0, 0};
        if (!bus.read(config_.address, FIFO_COUNT_H, count_be, 2)) {
            ++counters_.bus_errors;
            return false;
        }
        if (((count_be[0] << 8) | count_be[1]) >= kDmpSettleBytes) break;
        clock.delay_us(kSettlePollUs);
    }
    uint8_t status = 0;
    return drain_fifo(bus) && read_reg(bus, INT_STATUS, status);
}

bool Mpu6050::drain_fifo(I2cBus& bus) {
    uint8_t count_be[2] = {0, 0};
    if (!bus.read(config_.address, FIFO_COUNT_H, count_be, 2)) {
        ++counters_.bus_errors;
        return false;
    }
    uint16_t left = static_cast<uint16_t>((count_be[0] << 8) | count_be[1]);
    if (left > kFifoSize) left = kFifoSize;
    uint8_t sink[kDmpPacketSize];
    while (left > 0) {
        const uint16_t n = left < kDmpPacketSize ? left : kDmpPacketSize;
        if (!bus.read(config_.address, FIFO_R_W, sink, n)) {
            ++counters_.bus_errors;
            return false;
        }
        left = static_cast<uint16_t>(left - n);
    }
    return true;
}

bool Mpu6050::write_memory(I2cBus& bus, uint16_t address, const uint8_t* data, uint16_t n) {
    const uint8_t bank = static_cast<uint8_t>(address / kBankSize);
    const uint8_t start = static_cast<uint8_t>(address % kBankSize);
    if (!write_reg(bus, BANK_SEL, bank) || !write_reg(bus, MEM_START_ADDR, start)) return false;
    if (bus.write(config_.address, MEM_R_W, data, n)) return true;
    ++counters_.bus_errors;
    return false;
}

bool Mpu6050::verify_memory(I2cBus& bus, uint16_t address, const uint8_t* data, uint16_t n) {
    uint8_t back[kMemChunk];
    const uint8_t bank = static_cast<uint8_t>(address / kBankSize);
    const uint8_t start = static_cast<uint8_t>(address % kBankSize);
    if (!write_reg(bus, BANK_SEL, bank) || !write_reg(bus, MEM_START_ADDR, start)) return false;
    if (!bus.read(config_.address, MEM_R_W, back, n)) {
        ++counters_.bus_errors;
        return false;
    }
    for (uint16_t i = 0; i < n; ++i) {
        if (back[i] != data[i]) return false;
    }
    return true;
}

bool Mpu6050::write_dmp_memory(I2cBus& bus, uint16_t address, const uint8_t* data, uint16_t n) {
    for (uint16_t done = 0; done < n;) {
        // Chunks of at most 16 bytes that never cross a 256-byte bank, each read back.
        const uint16_t at = static_cast<uint16_t>(address + done);
        uint16_t k = static_cast<uint16_t>(n - done);
        if (k > kMemChunk) k = kMemChunk;
        const uint16_t to_bank_end = static_cast<uint16_t>(kBankSize - (at % kBankSize));
        if (k > to_bank_end) k = to_bank_end;
        if (!write_memory(bus, at, data + done, k) || !verify_memory(bus, at, data + done, k)) {
            return false;
        }
        done = static_cast<uint16_t>(done + k);
    }
    return true;
}

bool Mpu6050::start_fifo(I2cBus& bus) {
    if (mode_ == SensorMode::Dmp) {
        return write_reg(bus, FIFO_EN, 0x00) && write_reg(bus, INT_ENABLE, INT_DMP | INT_FIFO_OFLOW) &&
               write_reg(bus, USER_CTRL, USER_FIFO_RESET | USER_DMP_RESET) &&
               write_reg(bus, USER_CTRL, USER_DMP_EN | USER_FIFO_EN);
    }
    return write_reg(bus, FIFO_EN, FIFO_EN_GYRO_ACCEL) &&
           write_reg(bus, INT_ENABLE, INT_DATA_RDY | INT_FIFO_OFLOW) &&
           write_reg(bus, USER_CTRL, USER_FIFO_RESET) && write_reg(bus, USER_CTRL, USER_FIFO_EN);
}

bool Mpu6050::reset_fifo(I2cBus& bus) {
    ++counters_.resyncs;
    const uint8_t enable = static_cast<uint8_t>(mode_ == SensorMode::Dmp ? USER_DMP_EN | USER_FIFO_EN
                                                                         : USER_FIFO_EN);
    return write_reg(bus, USER_CTRL, USER_FIFO_RESET) && write_reg(bus, USER_CTRL, enable);
}

bool Mpu6050::poll(I2cBus& bus, ImuSample& sample) {
    if (mode_ == SensorMode::None) return false;
    uint8_t status = 0, count_be[2] = {0, 0};
    if (!read_reg(bus, INT_STATUS, status)) return false;
    if (!bus.read(config_.address, FIFO_COUNT_H, count_be, 2)) {
        ++counters_.bus_errors;
        return false;
    }
    const uint16_t count = static_cast<uint16_t>((count_be[0] << 8) | count_be[1]);
    const uint16_t size = packet_size();
    if (status & INT_FIFO_OFLOW) ++counters_.overflows;
    if ((status & INT_FIFO_OFLOW) || count > kFifoSize || (count % size) != 0) {
        // Misaligned: the only way back to packet boundaries is an empty FIFO.
        reset_fifo(bus);
        return false;
    }
    if (count < size) return false;
    uint8_t packet[kDmpPacketSize];
    for (uint16_t left = count; left >= size; left -= size) {
        if (!bus.read(config_.address, FIFO_R_W, packet, size)) {
            ++counters_.bus_errors;
            return false;
        }
        if (left >= 2 * size) ++counters_.dropped;    // an older packet: drained unread
    }
    if (mode_ == SensorMode::Raw) {
        parse_raw_packet(packet, sample);
    } else if (!parse_dmp_packet(packet, sample)) {
        ++counters_.bad_packets;
        reset_fifo(bus);
        return false;
    }
    ++counters_.packets;
    return true;
}

bool Mpu6050::parse_dmp_packet(const uint8_t* p, ImuSample& out) {
    // Q30: the int32 over 2^30. float keeps 24 bits, which is 1e-7 of a unit quaternion.
    Quat q{static_cast<float>(be32(p)) / kQ30, static_cast<float>(be32(p + 4)) / kQ30,
           static_cast<float>(be32(p + 8)) / kQ30, static_cast<float>(be32(p + 12)) / kQ30};
    const float norm = std::sqrt(q.w * q.w + q.x * q.x + q.y * q.y + q.z * q.z);
    if (!(std::fabs(norm - 1.0f) < kQuatNormTolerance)) return false;
    out.attitude = dmp_to_frd(q);
    out.has_attitude = true;
    const float g = kDegToRad / kGyroLsb, a = kGravity / kAccelLsb;
    out.gyro_rad_s = chip_to_frd(Vec3{be16(p + 16) * g, be16(p + 20) * g, be16(p + 24) * g});
    out.accel_m_s2 = chip_to_frd(Vec3{be16(p + 28) * a, be16(p + 32) * a, be16(p + 36) * a});
    out.gyro_clipped = any_full_scale(p + 16, 4);
    out.accel_clipped = any_full_scale(p + 28, 4);
    return true;
}

void Mpu6050::parse_raw_packet(const uint8_t* p, ImuSample& out) {
    const float g = kDegToRad / kGyroLsb, a = kGravity / kAccelLsb;
    out.accel_m_s2 = chip_to_frd(Vec3{be16(p) * a, be16(p + 2) * a, be16(p + 4) * a});
    out.gyro_rad_s = chip_to_frd(Vec3{be16(p + 6) * g, be16(p + 8) * g, be16(p + 10) * g});
    out.has_attitude = false;
    out.accel_clipped = any_full_scale(p, 2);
    out.gyro_clipped = any_full_scale(p + 6, 2);
}

}  // namespace hq
