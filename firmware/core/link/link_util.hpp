// What the GcsLink's files share: field sizes, and the conversions between MAVLink's fields
// and the core's numbers.
#pragma once

#include <cmath>
#include <cstdint>

#include "../params.hpp"

#include <heliquad/mavlink.h>

namespace hq {

// STATUSTEXT.text, NUL-terminated when shorter.
constexpr size_t kStatusTextLen = MAVLINK_MSG_STATUSTEXT_FIELD_TEXT_LEN;
// Every parameter, one bit per index (PARAM_VALUEs to send).
constexpr uint64_t kAllParams = (1ull << kParamCount) - 1;

// A command parameter that carries a whole number (a mode, a message id, an action): the
// number, or kNotWhole for anything else (a fraction, a negative, a NaN, a value past 2^24,
// which a float carries inexactly), so no float is ever converted out of range.
constexpr uint32_t kNotWhole = UINT32_MAX;
inline uint32_t whole(float v) {
    if (!(v >= 0.0f && v <= 16777216.0f) || v != std::floor(v)) return kNotWhole;
    return static_cast<uint32_t>(v);
}

// The largest encoded length of a message (header, payload, checksum; no signature).
inline uint32_t packet_bytes(uint32_t msgid) {
    const mavlink_msg_entry_t* e = mavlink_get_msg_entry(msgid);
    return (e ? e->max_msg_len : 255u) + MAVLINK_NUM_NON_PAYLOAD_BYTES;
}

}  // namespace hq
