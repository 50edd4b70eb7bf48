// The fuzz input as the firmware's libFuzzer targets read it: a stream of choices (every
// target's; fuzz_input.hpp adds what the targets on the core share).
#pragma once

#include <cstddef>
#include <cstdint>
#include <cstring>

namespace hqfuzz {

// The fuzz input as a stream of choices; reads past the end give zeros.
class Reader {
public:
    Reader(const uint8_t* data, size_t size) : data_(data), size_(size) {}
    bool done() const { return pos_ >= size_; }
    uint8_t u8() { return pos_ < size_ ? data_[pos_++] : 0; }
    uint16_t u16() { return static_cast<uint16_t>(u8() | (u8() << 8)); }
    uint32_t u32() { return u16() | (static_cast<uint32_t>(u16()) << 16); }
    uint64_t u64() { return u32() | (static_cast<uint64_t>(u32()) << 32); }
    float f32() {
        const uint32_t bits = u32();
        float f;
        std::memcpy(&f, &bits, sizeof f);
        return f;
    }
    // Up to n bytes into out (the rest zero); how many came from the input.
    size_t bytes(uint8_t* out, size_t n) {
        size_t got = 0;
        for (; got < n && pos_ < size_; ++got) out[got] = data_[pos_++];
        for (size_t i = got; i < n; ++i) out[i] = 0;
        return got;
    }

private:
    const uint8_t* data_;
    size_t size_;
    size_t pos_ = 0;
};

}  // namespace hqfuzz
