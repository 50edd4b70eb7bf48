// I2C bus interface (master side). Contract:
// - write(): START, address+W, reg, data[0..n-1], STOP. read(): START, address+W, reg,
//   repeated START, address+R, n bytes (NACK on the last), STOP.
// - Both return false on a NACK or a bus timeout and never block longer than the backend's
//   timeout (the Teensy backend: 1 ms per byte).
// - Registers auto-increment inside the device as the MPU6050 does; FIFO_R_W does not.
#pragma once

#include <cstddef>
#include <cstdint>

namespace hq {

class I2cBus {
public:
    virtual bool write(uint8_t address, uint8_t reg, const uint8_t* data, size_t n) = 0;
    virtual bool read(uint8_t address, uint8_t reg, uint8_t* data, size_t n) = 0;

protected:
    ~I2cBus() = default;     // not deleted through the interface: no heap on the target
};

}  // namespace hq
