#include "mpu6050.hpp"

#include <cmath>

namespace hq {

using namespace mpu6050;

namespace {
int16_t be16(const uint8_t* p) { return static_cast<int16_t>((p[0] << 8) | p[1]); }
int32_t be32(const uint8_t* p) {
    return static_cast<int32_t>((static_cast<uint32_t>(p[0]) << 24) |
                                (static_cast<uint32_t>(p[1]) << 16) |
                                (static_cast<uint32_t>(p[2]) << 8) | p[3]);
}
constexpr float kDegToRad = 0.017453292519943295f;
// A DMP quaternion whose norm is this far from 1 is misaligned data, not an attitude.
constexpr float kQuatNormTolerance = 0.05f;
}  // namespace

ImuHealth Mpu6050::probe(I2cBus& bus) {
    uint8_t who = 0, power = 0, user = 0;
    if (!read_reg(bus, WHO_AM_I, who) || who != WHO_AM_I_VALUE) return ImuHealth::NoAnswer;
    if (mode_ == SensorMode::None) return ImuHealth::Unconfigured;
    if (!read_reg(bus, PWR_MGMT_1, power) || !read_reg(bus, USER_CTRL, user)) {
        return ImuHealth::NoAnswer;
    }
    const uint8_t running = static_cast<uint8_t>(
        mode_ == SensorMode::Dmp ? USER_DMP_EN | USER_FIFO_EN : USER_FIFO_EN);
    if (power != PWR_CLK_PLL_XGYRO || (user & running) != running) return ImuHealth::Unconfigured;
    return ImuHealth::Configured;
}

float Mpu6050::sample_rate_hz() const {
    // CONFIG DLPF_CFG 0 and 7 turn the filter off (register map rev 4.2, section 4.3).
    const float gyro_hz = (config_.dlpf == 0 || config_.dlpf == 7) ? 8000.0f : 1000.0f;
    const float raw_hz = gyro_hz / (1.0f + static_cast<float>(config_.sample_rate_div));
    const bool dmp = mode_ == SensorMode::Dmp ||
                     (mode_ == SensorMode::None && config_.dmp_image != nullptr);
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

InitResult Mpu6050::init(I2cBus& bus, Clock& clock) {
    mode_ = SensorMode::None;
    if (!write_reg(bus, PWR_MGMT_1, PWR_DEVICE_RESET)) return InitResult::NoDevice;
    clock.delay_us(100000);                       // reset takes up to 100 ms
    uint8_t who = 0;
    if (!write_reg(bus, PWR_MGMT_1, PWR_CLK_PLL_XGYRO) || !read_reg(bus, WHO_AM_I, who)) {
        return InitResult::BusError;
    }
    if (who != WHO_AM_I_VALUE) return InitResult::NoDevice;
    clock.delay_us(10000);                        // PLL settles
    if (!write_reg(bus, SMPLRT_DIV, config_.sample_rate_div) ||
        !write_reg(bus, CONFIG, config_.dlpf) || !write_reg(bus, GYRO_CONFIG, GYRO_FS_2000DPS) ||
        !write_reg(bus, ACCEL_CONFIG, ACCEL_FS_2G)) {
        return InitResult::BusError;
    }
    InitResult result = InitResult::OkRaw;
    if (config_.dmp_image != nullptr && config_.dmp_image_size > 0) {
        result = upload_dmp(bus) ? InitResult::OkDmp : InitResult::OkRawFallback;
    }
    mode_ = result == InitResult::OkDmp ? SensorMode::Dmp : SensorMode::Raw;
    if (!start_fifo(bus)) {
        mode_ = SensorMode::None;
        return InitResult::BusError;
    }
    return result;
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

bool Mpu6050::upload_dmp(I2cBus& bus) {
    const uint8_t* image = config_.dmp_image;
    for (uint16_t done = 0; done < config_.dmp_image_size;) {
        // Chunks of at most 16 bytes that never cross a 256-byte bank.
        uint16_t n = config_.dmp_image_size - done;
        if (n > kMemChunk) n = kMemChunk;
        const uint16_t to_bank_end = kBankSize - (done % kBankSize);
        if (n > to_bank_end) n = to_bank_end;
        if (!write_memory(bus, done, image + done, n) || !verify_memory(bus, done, image + done, n)) {
            return false;
        }
        done += n;
    }
    const uint8_t rate[2] = {0x00, config_.dmp_rate_div};
    const uint16_t rate_address = kDmpRateBank * kBankSize + kDmpRateOffset;
    return write_memory(bus, rate_address, rate, 2) && verify_memory(bus, rate_address, rate, 2) &&
           write_reg(bus, DMP_CFG_1, DMP_CFG_1_VALUE) && write_reg(bus, DMP_CFG_2, DMP_CFG_2_VALUE);
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
    Quat q{static_cast<float>(be32(p)) / kQuatScale, static_cast<float>(be32(p + 4)) / kQuatScale,
           static_cast<float>(be32(p + 8)) / kQuatScale,
           static_cast<float>(be32(p + 12)) / kQuatScale};
    const float norm = std::sqrt(q.w * q.w + q.x * q.x + q.y * q.y + q.z * q.z);
    if (!(std::fabs(norm - 1.0f) < kQuatNormTolerance)) return false;
    out.attitude = dmp_to_frd(q);
    out.has_attitude = true;
    const float g = kDegToRad / kGyroLsbPerDegS, a = kGravity / kAccelLsbPerG;
    out.gyro_rad_s = chip_to_frd(Vec3{be16(p + 16) * g, be16(p + 20) * g, be16(p + 24) * g});
    out.accel_m_s2 = chip_to_frd(Vec3{be16(p + 28) * a, be16(p + 32) * a, be16(p + 36) * a});
    return true;
}

void Mpu6050::parse_raw_packet(const uint8_t* p, ImuSample& out) {
    const float g = kDegToRad / kGyroLsbPerDegS, a = kGravity / kAccelLsbPerG;
    out.accel_m_s2 = chip_to_frd(Vec3{be16(p) * a, be16(p + 2) * a, be16(p + 4) * a});
    out.gyro_rad_s = chip_to_frd(Vec3{be16(p + 6) * g, be16(p + 8) * g, be16(p + 10) * g});
    out.has_attitude = false;
}

}  // namespace hq
