// Host backend of the HAL I2C bus (hal/i2c.hpp): the emulated devices attached at their
// addresses. A transfer to an address no device holds is a NACK, as on a real bus; the
// device decides everything else (the MPU6050 register emulator NACKs too while a test has
// it absent).
#pragma once

#include <cstddef>
#include <cstdint>

#include "../../hal/i2c.hpp"

namespace hq {

class HostI2cBus final : public I2cBus {
public:
    static constexpr int kMaxDevices = 4;

    // False when the address is taken or the bus is full.
    bool attach(uint8_t address, I2cBus& device) {
        if (find(address) != nullptr || count_ == kMaxDevices) return false;
        devices_[count_++] = {address, &device};
        return true;
    }
    bool write(uint8_t address, uint8_t reg, const uint8_t* data, size_t n) override {
        I2cBus* d = find(address);
        return d != nullptr && d->write(address, reg, data, n);
    }
    bool read(uint8_t address, uint8_t reg, uint8_t* data, size_t n) override {
        I2cBus* d = find(address);
        return d != nullptr && d->read(address, reg, data, n);
    }

private:
    struct Slot {
        uint8_t address;
        I2cBus* device;
    };
    I2cBus* find(uint8_t address) const {
        for (int i = 0; i < count_; ++i) {
            if (devices_[i].address == address) return devices_[i].device;
        }
        return nullptr;
    }
    Slot devices_[kMaxDevices] = {};
    int count_ = 0;
};

}  // namespace hq
