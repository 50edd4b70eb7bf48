// Host backend of the HAL serial port (hal/serial.hpp): a pseudo-terminal.
#pragma once

#include <cstddef>
#include <cstdint>
#include <string>

#include "../../hal/serial.hpp"
#include "pty_backlog.hpp"

namespace hq {

// One end of a pseudo-terminal, the stand-in for a UART or USB serial port. The firmware owns
// the master side and publishes the slave device under a stable name (a symlink), which the
// peer opens like any serial port. Writes go through a user-space buffer flushed without
// blocking; a message that does not fit is refused whole (the caller counts it as dropped).
class PtySerial final : public SerialPort {
public:
    static constexpr size_t kBufferSize = 1 << 16;

    // Creates the pty and the symlink `link_path` -> slave device. Returns false with a
    // message in error() on failure.
    bool open(const std::string& link_path);
    void close();
    ~PtySerial() { close(); }

    size_t read(uint8_t* data, size_t n) override;
    size_t write(const uint8_t* data, size_t n) override;

    // Push buffered bytes to the pty without blocking. Returns false if the pty failed.
    // With a backlog bound (bound_backlog), the oldest bytes go first when no reader keeps up.
    bool flush();
    // Bound what waits for a reader (in the pty and in this buffer together) to `bytes`, as
    // a board's USB or UART buffer is bounded: when nobody reads, the oldest bytes are
    // dropped, so a reader that opens late gets at most `bytes` of the past, then the
    // present. 0 (the default): unbounded, for the lockstep simulator, which reads every
    // loop's telemetry however far it runs ahead of real time. At most kMaxPtyBacklogBytes,
    // what the pty's line discipline holds in sight of TIOCINQ (pty_backlog.hpp).
    void bound_backlog(size_t bytes) {
        backlog_limit_ = bytes < kMaxPtyBacklogBytes ? bytes : kMaxPtyBacklogBytes;
    }
    // Bytes dropped by the backlog bound so far.
    size_t discarded() const { return discarded_; }
    size_t buffered() const { return count_; }
    // Block until input arrives here or timeout_us passes; false on timeout. `also`, if
    // given, is polled in the same call and told whether it has input (see read()).
    bool wait_readable_us(long timeout_us, PtySerial* also = nullptr);
    // False when the last poll found no input (read() then returns 0 without a system call).
    bool input_pending() const { return maybe_input_; }
    // Write all of data, waiting as needed (the sim link: lockstep, the peer is reading).
    bool write_all(const uint8_t* data, size_t n, int timeout_ms);

    int fd() const { return master_; }
    const std::string& slave_path() const { return slave_path_; }
    const std::string& error() const { return error_; }

private:
    int master_ = -1, slave_ = -1;
    std::string link_path_, slave_path_, error_;
    bool maybe_input_ = true;     // false: the last poll found nothing, read() skips the call
    uint8_t buf_[kBufferSize];
    size_t head_ = 0, count_ = 0;
    size_t backlog_limit_ = 0, discarded_ = 0;
    void drop_oldest();
};

}  // namespace hq
