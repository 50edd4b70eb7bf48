// MPU6050 driver written against the I2C interface (no platform code).
//
// Two paths, chosen at init():
// - DMP: the user supplies the InvenSense MotionApps 2.0 image (1929 bytes; not ours to
//   commit; see docs/mpu6050.md for where it comes from). It is uploaded in 16-byte chunks
//   through BANK_SEL / MEM_START_ADDR / MEM_R_W and read back to verify; the DMP then fills
//   the FIFO with 42-byte packets (quaternion Q30, gyro, accel; big-endian).
// - Raw: without an image, or when the upload does not verify, the FIFO carries 12-byte
//   accel+gyro samples and the firmware's ComplementaryFilter estimates attitude, so the
//   vehicle still flies.
//
// poll() reads INT_STATUS (which clears it) and FIFO_COUNT; on an overflow (the FIFO holds
// 1024 bytes, not a multiple of 42, so packets are misaligned afterwards) or an implausible
// count it resets the FIFO and counts a resync; otherwise it drains to the newest packet.
// Every fault has a counter.
//
// Register map: InvenSense MPU-6000/6050 Register Map rev 4.2; addresses in SPEC.md.
#pragma once

#include <cstdint>

#include "../hal/clock.hpp"
#include "../hal/i2c.hpp"
#include "attitude.hpp"
#include "types.hpp"

namespace hq {

namespace mpu6050 {
constexpr uint8_t kAddress = 0x68;
constexpr uint8_t SMPLRT_DIV = 0x19, CONFIG = 0x1A, GYRO_CONFIG = 0x1B, ACCEL_CONFIG = 0x1C;
constexpr uint8_t FIFO_EN = 0x23, INT_ENABLE = 0x38, INT_STATUS = 0x3A, USER_CTRL = 0x6A;
constexpr uint8_t PWR_MGMT_1 = 0x6B, BANK_SEL = 0x6D, MEM_START_ADDR = 0x6E, MEM_R_W = 0x6F;
constexpr uint8_t DMP_CFG_1 = 0x70, DMP_CFG_2 = 0x71, FIFO_COUNT_H = 0x72, FIFO_R_W = 0x74;
constexpr uint8_t WHO_AM_I = 0x75, WHO_AM_I_VALUE = 0x68;
// Bits
constexpr uint8_t INT_FIFO_OFLOW = 1u << 4, INT_DMP = 1u << 1, INT_DATA_RDY = 1u << 0;
constexpr uint8_t USER_DMP_EN = 1u << 7, USER_FIFO_EN = 1u << 6, USER_DMP_RESET = 1u << 3,
                  USER_FIFO_RESET = 1u << 2;
constexpr uint8_t PWR_DEVICE_RESET = 1u << 7, PWR_CLK_PLL_XGYRO = 0x01;
constexpr uint8_t FIFO_EN_GYRO_ACCEL = 0x78;   // XG, YG, ZG, ACCEL
constexpr uint8_t GYRO_FS_2000DPS = 0x18, ACCEL_FS_2G = 0x00;
constexpr uint8_t DMP_CFG_1_VALUE = 0x03, DMP_CFG_2_VALUE = 0x00;
// FIFO and packets
constexpr uint16_t kFifoSize = 1024;
constexpr uint16_t kDmpPacketSize = 42, kRawPacketSize = 12;
constexpr uint16_t kMemChunk = 16, kBankSize = 256;
constexpr uint8_t kDmpRateBank = 2, kDmpRateOffset = 0x16;
// Scales: gyro at +/-2000 deg/s is 16.4 LSB per deg/s; accel at +/-2 g is 16384 LSB per g.
// The DMP packet's gyro and accel high halves use the same scales (docs/mpu6050.md).
constexpr float kGyroLsbPerDegS = 16.4f, kAccelLsbPerG = 16384.0f, kQuatScale = 1073741824.0f;
constexpr float kGravity = 9.80665f;
}  // namespace mpu6050

struct Mpu6050Config {
    uint8_t address = mpu6050::kAddress;
    uint8_t sample_rate_div = 4;        // 1 kHz / (1 + 4) = 200 Hz sensor rate (DLPF on)
    uint8_t dlpf = 3;                   // CONFIG DLPF_CFG 3: 44 Hz gyro bandwidth
    uint8_t dmp_rate_div = 0;           // DMP output 200 / (1 + div) Hz
    const uint8_t* dmp_image = nullptr; // MotionApps 2.0 image, or nullptr for the raw path
    uint16_t dmp_image_size = 0;
};

enum class SensorMode : uint8_t { None = 0, Dmp = 1, Raw = 2 };

// What probe() finds.
enum class ImuHealth : uint8_t {
    Configured = 0,     // answers, and holds the configuration init() wrote
    Unconfigured = 1,   // answers, but lost its configuration (reset, brown-out) or never had it
    NoAnswer = 2,       // no acknowledge, or WHO_AM_I is not an MPU6050's
};

enum class InitResult : uint8_t {
    OkDmp = 0,
    OkRaw = 1,          // no image given: raw path by choice
    OkRawFallback = 2,  // image given but its upload did not verify: raw path
    NoDevice = 3,       // WHO_AM_I wrong or no answer
    BusError = 4,
};

// One FIFO sample in body FRD.
struct ImuSample {
    Quat attitude{};          // DMP only (identity on the raw path)
    Vec3 gyro_rad_s{};
    Vec3 accel_m_s2{};
    bool has_attitude = false;
};

struct Mpu6050Counters {
    uint32_t packets = 0;        // packets parsed
    uint32_t dropped = 0;        // older packets drained unread to reach the newest
    uint32_t overflows = 0;      // INT_STATUS FIFO_OFLOW seen
    uint32_t resyncs = 0;        // FIFO resets after overflow or a bad count or packet
    uint32_t bad_packets = 0;    // DMP quaternion far from unit norm (misaligned data)
    uint32_t bus_errors = 0;     // I2C transfers that failed
};

class Mpu6050 {
public:
    explicit Mpu6050(const Mpu6050Config& config) : config_(config) {}

    InitResult init(I2cBus& bus, Clock& clock);

    // Reads what the FIFO holds. Returns true and fills `sample` when a new packet was read.
    bool poll(I2cBus& bus, ImuSample& sample);

    // Reads WHO_AM_I, PWR_MGMT_1 and USER_CTRL: is the chip there, and does it still run as
    // init() left it? After a reset or brown-out PWR_MGMT_1 reads SLEEP and USER_CTRL has
    // neither FIFO_EN nor DMP_EN. Three register reads; for when samples stop coming.
    ImuHealth probe(I2cBus& bus);

    // Samples per second the configured path delivers: the gyro's output rate (1 kHz with the
    // low-pass filter on, 8 kHz with it off) over (1 + SMPLRT_DIV), and on the DMP path over
    // (1 + dmp_rate_div) again. Before init(), the rate of the path an image would choose.
    float sample_rate_hz() const;

    SensorMode mode() const { return mode_; }
    uint16_t packet_size() const;
    const Mpu6050Counters& counters() const { return counters_; }

    // Decoders of one FIFO packet (big-endian), into body FRD.
    static bool parse_dmp_packet(const uint8_t* p, ImuSample& out);
    static void parse_raw_packet(const uint8_t* p, ImuSample& out);

private:
    bool write_reg(I2cBus& bus, uint8_t reg, uint8_t value);
    bool read_reg(I2cBus& bus, uint8_t reg, uint8_t& value);
    bool upload_dmp(I2cBus& bus);
    bool write_memory(I2cBus& bus, uint16_t address, const uint8_t* data, uint16_t n);
    bool verify_memory(I2cBus& bus, uint16_t address, const uint8_t* data, uint16_t n);
    bool start_fifo(I2cBus& bus);
    bool reset_fifo(I2cBus& bus);

    Mpu6050Config config_;
    SensorMode mode_ = SensorMode::None;
    Mpu6050Counters counters_{};
};

}  // namespace hq
