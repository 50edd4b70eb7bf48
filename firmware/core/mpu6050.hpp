// MPU6050 driver written against the I2C interface (no platform code).
//
// Two paths, chosen at init():
// - DMP: the user supplies InvenSense's MotionApps 2.0 DMP firmware: the image (1929 bytes),
//   the configuration table (dmpConfig, 192 bytes) and the update table (dmpUpdates, 47
//   bytes); none of it is ours to commit (docs/mpu6050.md says where it comes from). init()
//   performs MotionApps' dmpInitialize sequence (docs/mpu6050.md, step by step): the image
//   is uploaded in 16-byte chunks through BANK_SEL / MEM_START_ADDR / MEM_R_W and read back,
//   then the configuration table is applied (DMP memory writes, read back, and its special
//   entries), then the registers and the update table in MotionApps' order. The DMP then
//   fills the FIFO with 42-byte packets (quaternion Q30, gyro, accel; big-endian).
// - Raw: without the DMP firmware, or when any step of its set-up fails (a write that does
//   not read back, a malformed table), the chip is reset and the FIFO carries 12-byte
//   accel+gyro samples; the firmware's ComplementaryFilter estimates attitude, so the
//   vehicle still flies.
//
// poll() reads INT_STATUS (which clears it) and FIFO_COUNT; on an overflow (the FIFO holds
// 1024 bytes, not a multiple of 42, so packets are misaligned afterwards) or an implausible
// count it resets the FIFO and counts a resync; otherwise it drains to the newest packet.
// Every fault has a counter.
//
// Register map: InvenSense MPU-6000/6050 Register Map rev 4.2, which the addresses below follow.
#pragma once

#include <cstdint>

#include "../hal/clock.hpp"
#include "../hal/i2c.hpp"
#include "attitude.hpp"
#include "types.hpp"

namespace hq {

namespace mpu6050 {
constexpr uint8_t kAddress = 0x68;
// XG/YG/ZG_OFFS_TC are not in the public register map; MotionApps reads and rewrites them
// (bits 6..1 the gyro's offset temperature compensation, bit 0 of XG_OFFS_TC OTP_BNK_VLD).
constexpr uint8_t XG_OFFS_TC = 0x00, YG_OFFS_TC = 0x01, ZG_OFFS_TC = 0x02;
constexpr uint8_t SMPLRT_DIV = 0x19, CONFIG = 0x1A, GYRO_CONFIG = 0x1B, ACCEL_CONFIG = 0x1C;
constexpr uint8_t MOT_THR = 0x1F, MOT_DUR = 0x20, ZRMOT_THR = 0x21, ZRMOT_DUR = 0x22;
constexpr uint8_t I2C_SLV0_ADDR = 0x25;
constexpr uint8_t FIFO_EN = 0x23, INT_ENABLE = 0x38, INT_STATUS = 0x3A, USER_CTRL = 0x6A;
constexpr uint8_t PWR_MGMT_1 = 0x6B, BANK_SEL = 0x6D, MEM_START_ADDR = 0x6E, MEM_R_W = 0x6F;
constexpr uint8_t DMP_CFG_1 = 0x70, DMP_CFG_2 = 0x71, FIFO_COUNT_H = 0x72, FIFO_R_W = 0x74;
constexpr uint8_t WHO_AM_I = 0x75, WHO_AM_I_VALUE = 0x68;
// Bits
constexpr uint8_t INT_FIFO_OFLOW = 1u << 4, INT_DMP = 1u << 1, INT_DATA_RDY = 1u << 0;
constexpr uint8_t USER_DMP_EN = 1u << 7, USER_FIFO_EN = 1u << 6, USER_I2C_MST_EN = 1u << 5,
                  USER_DMP_RESET = 1u << 3, USER_FIFO_RESET = 1u << 2,
                  USER_I2C_MST_RESET = 1u << 1, USER_SIG_COND_RESET = 1u << 0;
constexpr uint8_t PWR_DEVICE_RESET = 1u << 7, PWR_CLK_PLL_XGYRO = 0x01, PWR_CLK_PLL_ZGYRO = 0x03;
constexpr uint8_t TC_OTP_BNK_VLD = 1u << 0;
constexpr uint8_t CONFIG_EXT_SYNC_TEMP_OUT_L = 1u << 3;   // EXT_SYNC_SET (bits 5..3) = 1
constexpr uint8_t FIFO_EN_GYRO_ACCEL = 0x78;   // XG, YG, ZG, ACCEL
constexpr uint8_t GYRO_FS_2000DPS = 0x18, ACCEL_FS_2G = 0x00;
constexpr uint8_t DMP_CFG_1_VALUE = 0x03, DMP_CFG_2_VALUE = 0x00;
// FIFO and packets
constexpr uint16_t kFifoSize = 1024;
constexpr uint16_t kDmpPacketSize = 42, kRawPacketSize = 12;
constexpr uint16_t kMemChunk = 16, kBankSize = 256;
constexpr uint16_t kDmpMemorySize = 8 * kBankSize;   // MotionApps: 8 banks of DMP memory
// MotionApps 2.0 facts (mpu6050 0.0.3, MPU6050.py dmp_initialize and MPUConstants.py):
// the configuration table's entry at bank 2, offset 0x16 (2 bytes, big-endian) is the DMP's
// FIFO rate divisor; its special command 0x01 means INT_ENABLE = 0x32; the update table has
// seven entries, written 2 before the DMP is enabled, 3 after, then 1 and 1, each after the
// DMP has produced output; the motion-detection registers get 2, 80, 156, 0.
constexpr uint8_t kDmpRateBank = 2, kDmpRateOffset = 0x16;
constexpr uint8_t kDmpSpecialIntEnable = 0x01, kDmpSpecialIntEnableValue = 0x32;
constexpr uint8_t kDmpUpdateGroups[4] = {2, 3, 1, 1};
constexpr uint8_t kDmpUpdateCount = 7;
constexpr uint8_t kMotThr = 2, kMotDur = 80, kZrmotThr = 156, kZrmotDur = 0;
constexpr uint8_t kSlaveAddressDummy = 0x7F;
constexpr uint16_t kDmpSettleBytes = 3;   // MotionApps waits for more than 2 FIFO bytes
// Scales, the chip's exact figures: gyro at +/-2000 deg/s is 16.4 LSB per deg/s; accel at
// +/-2 g is 16384 LSB per g; the DMP quaternion is Q30 (2^30 per unit). The DMP packet's gyro
// and accel high halves use the same scales (docs/mpu6050.md). The one definition: the
// simulator's packet encoder (sim/sensor/fifo_packets.*) and its Python names use these.
constexpr double kGyroLsbPerDegS = 16.4, kAccelLsbPerG = 16384.0, kQuatScale = 1073741824.0;

// One entry of a MotionApps DMP table (dmpConfig, dmpUpdates): bank, offset, length, then
// `length` data bytes for DMP memory. A length of 0 marks a special command, whose code is the
// one byte that follows.
struct DmpTableEntry {
    uint8_t bank = 0, offset = 0, length = 0;
    const uint8_t* data = nullptr;   // `length` bytes (a memory write)
    uint8_t special = 0;             // the command code (length 0)
    uint16_t address() const { return static_cast<uint16_t>(bank * kBankSize + offset); }
    bool is_rate() const { return bank == kDmpRateBank && offset == kDmpRateOffset && length == 2; }
};

// Reads the entry at `pos` and moves `pos` past it. False at the end of the table, and for an
// entry that runs past the end.
bool next_dmp_entry(const uint8_t* table, uint16_t size, uint16_t& pos, DmpTableEntry& out);
// The number of entries when the table parses to its very end (specials only where allowed,
// and only the known one), else -1.
int count_dmp_entries(const uint8_t* table, uint16_t size, bool specials_allowed);
}  // namespace mpu6050

struct Mpu6050Config {
    uint8_t address = mpu6050::kAddress;
    uint8_t sample_rate_div = 4;        // 1 kHz / (1 + 4) = 200 Hz sensor rate (DLPF on)
    uint8_t dlpf = 3;                   // CONFIG DLPF_CFG 3: 44 Hz gyro bandwidth
    uint8_t dmp_rate_div = 0;           // DMP output 200 / (1 + div) Hz
    // MotionApps 2.0 DMP firmware, borrowed (never copied): the image, the configuration table
    // (dmpConfig) and the update table (dmpUpdates). All three, or the raw path.
    const uint8_t* dmp_image = nullptr;
    uint16_t dmp_image_size = 0;
    const uint8_t* dmp_config = nullptr;
    uint16_t dmp_config_size = 0;
    const uint8_t* dmp_updates = nullptr;
    uint16_t dmp_updates_size = 0;
};

// The FIFO data the chip is set up for: the dialect's HQ_SENSOR_KIND.
enum class SensorMode : uint8_t {
    None = HQ_SENSOR_NONE,
    Dmp = HQ_SENSOR_DMP,
    Raw = HQ_SENSOR_RAW,
};

// What probe() finds.
enum class ImuHealth : uint8_t {
    Configured = 0,     // answers, and holds the configuration init() wrote
    Unconfigured = 1,   // answers, but lost its configuration (reset, brown-out) or never had it
    NoAnswer = 2,       // no acknowledge, or WHO_AM_I is not an MPU6050's
};

// Where the DMP set-up gave up (InitResult::OkRawFallback).
enum class DmpStep : uint8_t {
    None = 0,
    Tables = 1,      // an image without both tables, or a table that does not parse
    Image = 2,       // the image did not read back equal (or the bus failed)
    Config = 3,      // a configuration-table write did not read back equal
    Registers = 4,   // a register write or read of the sequence failed
    Updates = 5,     // an update-table write did not read back equal
};

enum class InitResult : uint8_t {
    OkDmp = 0,
    OkRaw = 1,          // no DMP firmware given: raw path by choice
    OkRawFallback = 2,  // DMP firmware given but its set-up failed (dmp_failure()): raw path
    NoDevice = 3,       // WHO_AM_I wrong or no answer
    BusError = 4,
};

// One FIFO sample in body FRD.
struct ImuSample {
    Quat attitude{};          // DMP only (identity on the raw path)
    Vec3 gyro_rad_s{};
    Vec3 accel_m_s2{};
    bool has_attitude = false;
    bool gyro_clipped = false;    // a gyro axis read full scale (-32768 or 32767 LSB)
    bool accel_clipped = false;   // an accelerometer axis read full scale
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
    // The set-up the next init() applies.
    void configure(const Mpu6050Config& config) { config_ = config; }

    InitResult init(I2cBus& bus, Clock& clock);

    // Reads what the FIFO holds. Returns true and fills `sample` when a new packet was read.
    bool poll(I2cBus& bus, ImuSample& sample);

    // Reads WHO_AM_I, PWR_MGMT_1 and USER_CTRL: is the chip there, and does it still run as
    // init() left it? After a reset or brown-out PWR_MGMT_1 reads SLEEP and USER_CTRL has
    // neither FIFO_EN nor DMP_EN. Three register reads; for when samples stop coming.
    ImuHealth probe(I2cBus& bus);

    // Samples per second the configured path delivers: the gyro's output rate (1 kHz with the
    // low-pass filter on, 8 kHz with it off) over (1 + SMPLRT_DIV), and on the DMP path over
    // (1 + dmp_rate_div) again. Before init(), the rate of the path the given DMP firmware (all
    // three parts) would choose.
    float sample_rate_hz() const;

    SensorMode mode() const { return mode_; }
    DmpStep dmp_failure() const { return dmp_failure_; }
    uint16_t packet_size() const;
    const Mpu6050Counters& counters() const { return counters_; }

    // Decoders of one FIFO packet (big-endian), into body FRD.
    static bool parse_dmp_packet(const uint8_t* p, ImuSample& out);
    static void parse_raw_packet(const uint8_t* p, ImuSample& out);

private:
    bool write_reg(I2cBus& bus, uint8_t reg, uint8_t value);
    bool read_reg(I2cBus& bus, uint8_t reg, uint8_t& value);
    InitResult wake(I2cBus& bus, Clock& clock);
    bool configure_raw(I2cBus& bus);
    bool init_dmp(I2cBus& bus, Clock& clock);
    bool dmp_registers(I2cBus& bus, const uint8_t tc[3]);
    bool apply_config(I2cBus& bus);
    bool apply_updates(I2cBus& bus, uint16_t& pos, uint8_t count);
    bool settle_dmp(I2cBus& bus, Clock& clock);
    bool drain_fifo(I2cBus& bus);
    bool fail(DmpStep step);
    bool write_dmp_memory(I2cBus& bus, uint16_t address, const uint8_t* data, uint16_t n);
    bool write_memory(I2cBus& bus, uint16_t address, const uint8_t* data, uint16_t n);
    bool verify_memory(I2cBus& bus, uint16_t address, const uint8_t* data, uint16_t n);
    bool start_fifo(I2cBus& bus);
    bool reset_fifo(I2cBus& bus);

    Mpu6050Config config_;
    SensorMode mode_ = SensorMode::None;
    DmpStep dmp_failure_ = DmpStep::None;
    Mpu6050Counters counters_{};
};

}  // namespace hq
