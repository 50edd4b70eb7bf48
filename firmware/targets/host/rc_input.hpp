// Host backend of the RC input (hal/rc_input.hpp): the channels the simulator sends in each
// HQ_SENSOR_FRAME. A frame with a pulse on any channel is a live receiver frame (age 0);
// a frame with none means the receiver is silent (age "never"), which the firmware treats as
// RC lost once the RC timeout has passed since the last live frame.
#pragma once

#include <cstdint>

#include "../../hal/rc_input.hpp"

namespace hq {

inline RcInput rc_from_sim_frame(const uint16_t (&rc_us)[kRcChannels]) {
    RcInput in;
    bool any = false;
    for (int c = 0; c < kRcChannels; ++c) {
        in.channel_us[c] = rc_us[c];
        any = any || rc_us[c] != 0;
    }
    in.age_us = any ? 0u : 0xFFFFFFFFu;
    return in;
}

}  // namespace hq
