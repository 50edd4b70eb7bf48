// The RAM ring between the loop's step and the card: the step puts whole log records in, the
// spare-time service takes bytes out to the sink. Fixed size (kBytes, a power of two), no heap.
// One producer (the step) and one consumer (the spare-time service, inside whose card waits
// the step may run nested): the step moves only head_, the service only tail_, so a nested
// step never touches bytes the service is handing to the card.
#pragma once

#include <cstddef>
#include <cstdint>
#include <cstring>

namespace hq {

template <uint32_t kBytes>
class LogRing {
    static_assert(kBytes >= 256 && (kBytes & (kBytes - 1)) == 0, "a power of two");

public:
    static constexpr uint32_t kCapacity = kBytes;

    // All n bytes, or none when they do not fit (false).
    bool push(const uint8_t* data, size_t n) {
        if (n > kBytes - (head_ - tail_)) return false;
        const uint32_t at = head_ & (kBytes - 1);
        const size_t first = n < kBytes - at ? n : kBytes - at;
        std::memcpy(buf_ + at, data, first);
        std::memcpy(buf_, data + first, n - first);
        head_ += static_cast<uint32_t>(n);
        return true;
    }
    // Positions count bytes ever pushed (head) and taken (tail), modulo 2^32.
    uint32_t head() const { return head_; }
    uint32_t tail() const { return tail_; }
    uint32_t used() const { return head_ - tail_; }
    // The bytes from the tail up to `end` (a head position seen earlier) that lie in one piece.
    uint32_t contiguous(uint32_t end, const uint8_t*& data) const {
        const uint32_t at = tail_ & (kBytes - 1);
        const uint32_t to_wrap = kBytes - at;
        const uint32_t n = end - tail_;
        data = buf_ + at;
        return n < to_wrap ? n : to_wrap;
    }
    void consume(uint32_t n) { tail_ += n; }

private:
    uint8_t buf_[kBytes] = {};
    uint32_t head_ = 0, tail_ = 0;
};

}  // namespace hq
