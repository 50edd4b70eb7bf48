// The card-image file as a block device (block_device.hpp).
#include "block_device.hpp"

namespace hq {

bool set_card_fault(CardFaults& f, const std::string& name, uint64_t value) {
    const bool on = value != 0;
    const uint32_t blocks = static_cast<uint32_t>(value);
    if (name == "no_card") f.no_card = on;
    else if (name == "write_protected") f.write_protected = on;
    else if (name == "writable_blocks") f.writable_blocks = blocks;
    else if (name == "failing_writes") f.failing_writes = on;
    else if (name == "busy_after_write_us") f.busy_after_write_us = value;
    else if (name == "busy_every_us") f.busy_every_us = value;
    else if (name == "busy_for_us") f.busy_for_us = value;
    else if (name == "power_cut_after_writes") f.power_cut_after_writes = blocks;
    else return false;
    return true;
}

FileBlockDevice::~FileBlockDevice() {
    if (file_ != nullptr) std::fclose(file_);
}

BlockStatus FileBlockDevice::start() {
    if (file_ != nullptr) std::fclose(file_);
    file_ = nullptr;
    blocks_ = 0;
    blocks_written_ = 0;
    powered_ = true;
    result_ = BlockStatus::Ok;
    if (faults_.no_card) return BlockStatus::NoCard;
    file_ = std::fopen(path_.c_str(), "r+b");
    if (file_ == nullptr) return BlockStatus::NoCard;
    if (std::fseek(file_, 0, SEEK_END) != 0) return BlockStatus::Failed;
    const long bytes = std::ftell(file_);
    if (bytes < 0) return BlockStatus::Failed;
    blocks_ = static_cast<uint32_t>(static_cast<uint64_t>(bytes) / kBlockBytes);
    started_us_ = clock_.micros();
    busy_until_us_ = started_us_;
    return BlockStatus::Ok;
}

bool FileBlockDevice::busy() const {
    const uint64_t now = clock_.micros();
    if (now < busy_until_us_) return true;
    if (faults_.busy_every_us == 0 || faults_.busy_for_us == 0) return false;
    return (now - started_us_) % faults_.busy_every_us < faults_.busy_for_us;
}

BlockStatus FileBlockDevice::finish(BlockStatus s) {
    result_ = s;
    return BlockStatus::Ok;       // the transfer ran (or was refused); poll() gives the result
}

BlockStatus FileBlockDevice::begin_read(uint32_t lba, uint8_t* data, uint32_t n) {
    if (file_ == nullptr || !powered_ || faults_.no_card) return BlockStatus::NoCard;
    if (busy()) return BlockStatus::Busy;
    if (n == 0 || lba >= blocks_ || n > blocks_ - lba) return BlockStatus::OutOfRange;
    const bool ok = std::fseek(file_, static_cast<long>(lba) * kBlockBytes, SEEK_SET) == 0 &&
                    std::fread(data, kBlockBytes, n, file_) == n;
    return finish(ok ? BlockStatus::Ok : BlockStatus::Failed);
}

BlockStatus FileBlockDevice::begin_write(uint32_t lba, const uint8_t* data, uint32_t n) {
    if (file_ == nullptr || !powered_ || faults_.no_card) return BlockStatus::NoCard;
    if (busy()) return BlockStatus::Busy;
    if (faults_.write_protected) return BlockStatus::WriteProtected;
    if (n == 0 || lba >= blocks_ || n > blocks_ - lba) return BlockStatus::OutOfRange;
    if (faults_.writable_blocks != 0 && lba + n > faults_.writable_blocks) {
        return BlockStatus::OutOfRange;
    }
    if (faults_.failing_writes) return finish(BlockStatus::Failed);
    bool ok = std::fseek(file_, static_cast<long>(lba) * kBlockBytes, SEEK_SET) == 0;
    for (uint32_t i = 0; ok && i < n; ++i) {
        if (faults_.power_cut_after_writes != 0 && blocks_written_ >= faults_.power_cut_after_writes) {
            powered_ = false;       // the power is gone: what was written stays, nothing more
            break;
        }
        ok = std::fwrite(data + i * kBlockBytes, kBlockBytes, 1, file_) == 1;
        ++blocks_written_;
    }
    ok = std::fflush(file_) == 0 && ok;
    busy_until_us_ = clock_.micros() + faults_.busy_after_write_us;
    if (!powered_) return finish(BlockStatus::NoCard);
    return finish(ok ? BlockStatus::Ok : BlockStatus::Failed);
}

BlockStatus FileBlockDevice::poll() {
    if (result_ == BlockStatus::Ok && powered_ && busy()) return BlockStatus::Busy;
    const BlockStatus s = result_;
    result_ = BlockStatus::Ok;    // a failure is said once; the device is usable again
    return s;
}

}  // namespace hq
