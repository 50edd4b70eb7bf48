// Byte stream (USB CDC serial on the Teensy, a pty on the host). Contract: never blocks.
// read() returns the bytes available now (up to n); write() queues up to n bytes and returns
// how many it took: a full link takes fewer, and the caller drops and counts the rest, as a
// UART would.
#pragma once

#include <cstddef>
#include <cstdint>

namespace hq {

class SerialPort {
public:
    virtual size_t read(uint8_t* data, size_t n) = 0;
    virtual size_t write(const uint8_t* data, size_t n) = 0;

protected:
    ~SerialPort() = default;
};

}  // namespace hq
