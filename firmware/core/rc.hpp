// The pilot's radio: channel map, switch positions and stick scaling. Pure functions of one
// RcInput (hal/rc_input.hpp: pulse widths in us, 0 = no signal on that channel).
//
// Channels (FrSky V8FR-II PWM outputs, Mode 2 transmitter):
//   1 roll stick, 2 pitch stick, 3 throttle, 4 yaw stick, 5 arm switch, 6 mode switch,
//   7 the on-board program's switch (program.hpp).
// Sticks are centred at 1500 us with +/-500 us of travel; the throttle runs 1000..2000 us.
#pragma once

#include <cstdint>

#include "../hal/rc_input.hpp"
#include "types.hpp"

namespace hq {

namespace rc {
constexpr int kRoll = 0, kPitch = 1, kThrottle = 2, kYaw = 3, kArm = 4, kMode = 5, kProgram = 6;
constexpr uint16_t kCenterUs = 1500, kMinUs = 1000, kHalfSpanUs = 500;
}  // namespace rc

// Where the switches and the throttle change meaning (parameters RC_SW_HIGH, RC_SW_LOW,
// RC_THR_LOW). A two-position switch reads about 1000 or 2000 us; "high" needs a clear margin
// above the centre so that a mid-travel or noisy pulse never counts as a deliberate arm or
// rate mode, and "low" a valid pulse clearly below it (no signal is neither). Throttle at
// most 10 % of travel counts as low for arming (sticks rest at 1000 +/- a few us).
struct RcThresholds {
    uint16_t switch_high_us = 1700;
    uint16_t switch_low_us = 1300;
    uint16_t throttle_low_us = 1100;
};

// Largest setpoints the sticks command at full deflection.
struct StickLimits {
    float angle_rad = 0.52359878f;      // 30 deg of roll or pitch (angle mode)
    float rate_rad_s = 3.4906585f;      // 200 deg/s of roll or pitch rate (rate mode)
    float yaw_rate_rad_s = 1.57079637f; // 90 deg/s of yaw rate (both modes; the float
                                        // nearest pi/2, which reads back as 90)
};

// The sticks as setpoints: angles for angle mode, rates for rate mode (yaw is always a rate).
struct Sticks {
    Euler angle{};                  // roll, pitch (yaw unused)
    Vec3 rate{};                    // p, q, r
    float throttle = 0.0f;          // collective, 0..1
};

// -1..1 from a stick channel; 0 when the channel has no signal.
float stick(const RcInput& in, int channel);
// 0..1 from the throttle channel; 0 when it has no signal.
float throttle(const RcInput& in);
Sticks sticks(const RcInput& in, const StickLimits& limits);

inline bool has_signal(const RcInput& in, int channel) { return in.channel_us[channel] != 0; }
inline bool switch_high(const RcInput& in, int channel, const RcThresholds& t) {
    return in.channel_us[channel] > t.switch_high_us;
}
inline bool switch_low(const RcInput& in, int channel, const RcThresholds& t) {
    return has_signal(in, channel) && in.channel_us[channel] < t.switch_low_us;
}

}  // namespace hq
