// RC input, as the loop sees it. Channels are pulse widths in microseconds (1000..2000;
// 0 = no signal on that channel); age_us is the time since the receiver's last valid frame
// (0xFFFFFFFF: never). The backend decides what "frame" means for its receiver (the Teensy's
// PWM capture: the oldest of the four stick channels' last pulses; the host build: the
// simulator's sensor frame).
#pragma once

#include <cstdint>

namespace hq {

constexpr int kRcChannels = 8;

struct RcInput {
    uint16_t channel_us[kRcChannels] = {0, 0, 0, 0, 0, 0, 0, 0};
    uint32_t age_us = 0xFFFFFFFFu;
};

}  // namespace hq
