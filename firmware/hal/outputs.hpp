// Motor outputs and RC input. Contract: set() takes thrust fractions 0..1 for the five
// motors (central first, then arms 1-4: front, right, back, left) and is applied at once;
// the backend maps thrust fraction to its ESC signal. disarm() drives every ESC to its
// stop value. RC channels are in microseconds (1000..2000, 0 = no signal); age_us is the time
// since the last valid frame.
#pragma once

#include <cstdint>

namespace hq {

constexpr int kRcChannels = 8;

class MotorOutputs {
public:
    virtual void set(const float thrust_fraction[5]) = 0;
    virtual void disarm() = 0;

protected:
    ~MotorOutputs() = default;
};

struct RcInput {
    uint16_t channel_us[kRcChannels] = {0, 0, 0, 0, 0, 0, 0, 0};
    uint32_t age_us = 0xFFFFFFFFu;
};

}  // namespace hq
