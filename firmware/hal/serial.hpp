// Byte stream (UART0 on the Teensy, a pty on the host). Contract: never blocks. read()
// returns the bytes available now (up to n). write() queues all n bytes, or none when they
// do not fit (returns 0): the caller hands it one whole MAVLink packet at a time, so a full
// link drops whole packets, never a packet's tail; the caller counts what was dropped.
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
