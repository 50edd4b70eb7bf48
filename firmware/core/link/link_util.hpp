// What the GcsLink's files share: field sizes, and the conversions between MAVLink's fields
// and the core's numbers.
#pragma once

#include <cmath>
#include <cstdint>

#include "../../hal/clock.hpp"
#include "../params.hpp"

#include <hq_mavlink.hpp>

namespace hq {

// STATUSTEXT.text, NUL-terminated when shorter.
constexpr size_t kStatusTextLen = MAVLINK_MSG_STATUSTEXT_FIELD_TEXT_LEN;
// A set of parameters, one bit per index (PARAM_VALUEs to send).
class ParamBits {
public:
    void set_all() {
        for (uint32_t& w : w_) w = ~0u;
        w_[kWords - 1] = kParamCount % 32 == 0 ? ~0u : (1u << (kParamCount % 32)) - 1;
    }
    void set(int i) { w_[i >> 5] |= 1u << (i & 31); }
    void clear(int i) { w_[i >> 5] &= ~(1u << (i & 31)); }
    bool test(int i) const { return (w_[i >> 5] >> (i & 31)) & 1u; }
    // The lowest index in the set, -1 when empty.
    int first() const {
        for (int k = 0; k < kWords; ++k) {
            if (w_[k] != 0) return 32 * k + __builtin_ctz(w_[k]);
        }
        return -1;
    }

private:
    static constexpr int kWords = (kParamCount + 31) / 32;
    uint32_t w_[kWords] = {};
};

// A command parameter that carries a whole number (a mode, a message id, an action): the
// number, or kNotWhole for anything else (a fraction, a negative, a NaN, a value past 2^24,
// which a float carries inexactly), so no float is ever converted out of range.
constexpr uint32_t kNotWhole = UINT32_MAX;
inline uint32_t whole(float v) {
    if (!(v >= 0.0f && v <= 16777216.0f) || v != std::floor(v)) return kNotWhole;
    return static_cast<uint32_t>(v);
}

// MAVLink's time_boot_ms (wraps after 49.7 days) from the loop's time in microseconds.
inline uint32_t boot_ms(uint64_t now_us) { return static_cast<uint32_t>(divide_time(now_us, 1000u)); }

// The largest encoded length of a message (header, payload, checksum; no signature).
inline uint32_t packet_bytes(uint32_t msgid) {
    const mavlink_msg_entry_t* e = mavlink_get_msg_entry(msgid);
    return (e ? e->max_msg_len : 255u) + MAVLINK_NUM_NON_PAYLOAD_BYTES;
}

}  // namespace hq
