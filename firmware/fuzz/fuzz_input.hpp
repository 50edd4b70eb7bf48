// Shared pieces of the firmware's libFuzzer targets: reading choices out of the fuzz input,
// and framing MAVLink 2 packets from fuzz bytes with a correct checksum, so the fuzzer gets
// past the CRC check to the decoders and handlers (random bytes almost never pass it).
//
// A packet built here can carry any message id of the dialect (or an unknown one), any
// payload length 0..255 (shorter or longer than the message's), a deliberately wrong CRC, or
// the signed flag; the parser and the generated decoders must cope with all of them.
#pragma once

#include <cstddef>
#include <cstdint>
#include <cstring>

#include <hq_mavlink.hpp>

#include "../core/flight_controller.hpp"
#include "../core/link/gcs_link.hpp"
#include "../core/mpu6050.hpp"
#include "../targets/host/clock.hpp"
#include "../targets/host/motors.hpp"
#include "fuzz_reader.hpp"
#include "sensor/mpu6050_emulator.hpp"

namespace hqfuzz {

// A made-up DMP firmware of MotionApps 2.0's shape (the real one is InvenSense's and not in
// the repository): a short image, a configuration table with the special entry and the FIFO
// rate entry, and seven updates. Enough for the driver's DMP set-up and the emulator's check.
constexpr uint8_t kSmallDmpImage[16] = {9, 8, 7, 6, 5, 4, 3, 2, 1, 0, 1, 2, 3, 4, 5, 6};
constexpr uint8_t kSmallDmpConfig[] = {0, 0x40, 2, 0xA1, 0xA2,  0, 0, 0, 0x01,
                                       1, 0x10, 3, 5, 6, 7,     2, 0x16, 2, 0x00, 0x09};
constexpr uint8_t kSmallDmpUpdates[] = {1, 0x20, 1, 1,  1, 0x21, 1, 2,  1, 0x22, 1, 3,
                                        1, 0x23, 1, 4,  1, 0x24, 1, 5,  1, 0x25, 1, 6,
                                        1, 0x26, 1, 7};

// Points the driver's configuration at the made-up DMP firmware and loads the emulated chip
// with the same reference.
inline void use_small_dmp(hq::Mpu6050Config& imu, hq::Mpu6050Emulator& chip) {
    imu.dmp_image = kSmallDmpImage;
    imu.dmp_image_size = sizeof kSmallDmpImage;
    imu.dmp_config = kSmallDmpConfig;
    imu.dmp_config_size = sizeof kSmallDmpConfig;
    imu.dmp_updates = kSmallDmpUpdates;
    imu.dmp_updates_size = sizeof kSmallDmpUpdates;
    chip.set_dmp_reference(imu.dmp_image, imu.dmp_image_size, imu.dmp_config,
                           imu.dmp_config_size, imu.dmp_updates, imu.dmp_updates_size);
}

// Every message of the dialect (common.xml and heliquad.xml), as the generated table has them.
inline const mavlink_msg_entry_t* message_table(size_t* count) {
    static const mavlink_msg_entry_t kEntries[] = MAVLINK_MESSAGE_CRCS;
    *count = sizeof kEntries / sizeof kEntries[0];
    return kEntries;
}

constexpr size_t kMaxPacket = MAVLINK_NUM_NON_PAYLOAD_BYTES + 255 + MAVLINK_SIGNATURE_BLOCK_LEN;

// One MAVLink 2 packet into out (kMaxPacket bytes); its length. flags bit 0: corrupt the CRC;
// bit 1: set the signed flag (and append a 13-byte signature of zeros).
inline size_t frame_packet(uint8_t* out, uint32_t msgid, const uint8_t* payload, uint8_t len,
                           uint8_t seq, uint8_t flags) {
    const mavlink_msg_entry_t* entry = mavlink_get_msg_entry(msgid);
    const bool sign = flags & 2;
    out[0] = MAVLINK_STX;
    out[1] = len;
    out[2] = sign ? MAVLINK_IFLAG_SIGNED : 0;
    out[3] = 0;
    out[4] = seq;
    out[5] = 255;                         // a ground station's ids
    out[6] = 190;
    out[7] = static_cast<uint8_t>(msgid);
    out[8] = static_cast<uint8_t>(msgid >> 8);
    out[9] = static_cast<uint8_t>(msgid >> 16);
    if (len) std::memcpy(out + MAVLINK_CORE_HEADER_LEN + 1, payload, len);
    uint16_t crc = crc_calculate(out + 1, static_cast<uint16_t>(MAVLINK_CORE_HEADER_LEN + len));
    crc_accumulate(entry ? entry->crc_extra : seq, &crc);
    if (flags & 1) crc = static_cast<uint16_t>(crc ^ 0x5A5A);
    size_t n = MAVLINK_CORE_HEADER_LEN + 1 + len;
    out[n++] = static_cast<uint8_t>(crc);
    out[n++] = static_cast<uint8_t>(crc >> 8);
    if (sign) {
        std::memset(out + n, 0, MAVLINK_SIGNATURE_BLOCK_LEN);
        n += MAVLINK_SIGNATURE_BLOCK_LEN;
    }
    return n;
}

// A packet of a message chosen by the input: any id of the table or an unknown one, a length
// that is the message's own or any other, payload bytes from the input.
inline size_t any_packet(Reader& in, uint8_t* out, uint8_t seq) {
    size_t count = 0;
    const mavlink_msg_entry_t* table = message_table(&count);
    const uint16_t pick = in.u16();
    const uint8_t how = in.u8();
    uint32_t msgid;
    uint8_t len;
    if (pick % (count + 1) == count) {
        msgid = in.u32() & 0xFFFFFF;      // most of these are unknown ids
        len = in.u8();
    } else {
        const mavlink_msg_entry_t& e = table[pick % (count + 1)];
        msgid = e.msgid;
        len = (how & 4) ? in.u8() : e.max_msg_len;
    }
    uint8_t payload[255];
    in.bytes(payload, len);
    return frame_packet(out, msgid, payload, len, seq, how & 3 ? (how >> 3) & 3 : 0);
}

// Parameter storage in memory, with what the input says is stored: nothing, a store its own
// check finds damaged, a valid record with one value (and its CRC) from the input, or any
// bytes at all. Saves succeed or fail as the input says.
class MemoryStorage final : public hq::ParamStorage {
public:
    void fill(Reader& in) {
        const uint8_t kind = in.u8();
        status_ = hq::StoreStatus::Ok;
        size_ = 0;
        fail_ = (kind & 0x10) != 0;
        switch (kind % 4) {
            case 0: status_ = hq::StoreStatus::Empty; break;
            case 1: status_ = hq::StoreStatus::Corrupt; break;
            case 2: {
                size_ = hq::Params().encode(data_, sizeof data_);
                const size_t at = 8 + 8 * (in.u8() % hq::kParamCount) + 4;
                in.bytes(data_ + at, 4);
                const uint32_t crc = hq::crc32(data_, size_ - 4);
                for (int i = 0; i < 4; ++i) data_[size_ - 4 + i] = static_cast<uint8_t>(crc >> (8 * i));
                break;
            }
            default: size_ = in.bytes(data_, in.u16() % sizeof data_); break;
        }
    }
    hq::StoreStatus load(uint8_t* data, size_t capacity, size_t& n) override {
        n = size_ < capacity ? size_ : capacity;
        std::memcpy(data, data_, n);
        return status_;
    }
    bool save(const uint8_t* data, size_t n) override {
        if (fail_ || n > sizeof data_) return false;
        std::memcpy(data_, data, n);
        size_ = n;
        status_ = hq::StoreStatus::Ok;
        return true;
    }

private:
    uint8_t data_[hq::ParamStorage::kMaxBytes] = {};
    size_t size_ = 0;
    hq::StoreStatus status_ = hq::StoreStatus::Empty;
    bool fail_ = false;
};

// Every parameter within its range: what the firmware flies with is never a value a set or
// a stored record could not give it legitimately.
inline bool params_in_range(const hq::Params& p) {
    for (int i = 0; i < hq::kParamCount; ++i) {
        const hq::ParamInfo& info = hq::param_info(i);
        const float v = p.get(i);
        if (!(v >= info.min && v <= info.max)) return false;
    }
    return true;
}

// The firmware as both targets fly it: the host build's clock and motors, the emulated
// MPU6050 (given the made-up DMP firmware when the input's first choice is odd), a parameter
// store holding what the input says, and a FlightController on them, initialised; its
// telemetry link (GcsLink) goes to a `Telemetry`.
template <class Telemetry>
struct Vehicle {
    explicit Vehicle(Reader& in)
        : cfg(config(in, chip, storage)), fc(cfg, chip, clock, motors), link(link_cfg, telemetry, inbox) {
        fc.init();
        link.send_notices(fc.status());
    }
    // One loop as the targets run it: the link's requests, the step, its telemetry.
    void step(const hq::RcInput& rc) {
        inbox.clear();
        link.receive();
        fc.step(rc, inbox);
        link.transmit(fc.status());
    }
    hq::HostClock clock;
    hq::HostMotors motors;
    hq::Mpu6050Emulator chip;
    MemoryStorage storage;
    Telemetry telemetry;
    hq::FlightControllerConfig cfg;
    hq::FlightController fc;
    hq::GcsLinkConfig link_cfg;
    hq::LoopInbox inbox;
    hq::GcsLink link;

private:
    static hq::FlightControllerConfig config(Reader& in, hq::Mpu6050Emulator& chip,
                                             MemoryStorage& storage) {
        hq::FlightControllerConfig c;
        if (in.u8() & 1) use_small_dmp(c.imu, chip);
        storage.fill(in);
        c.storage = &storage;
        return c;
    }
};

}  // namespace hqfuzz
