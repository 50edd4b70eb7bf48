// Seven RC channels from a PWM receiver (FrSky V8FR-II: one servo pulse per channel, every
// 18-20 ms), captured on FTM3 channels 0-6, both edges, in the FTM3 interrupt.
//
//   RC channel  1 roll   2 pitch  3 throttle  4 yaw   5 arm    6 mode    7 program
//   FTM3        CH0      CH1      CH2         CH3     CH4      CH5       CH6
//   pin         2 (PTD0) 14 (PTD1) 7 (PTD2)   8 (PTD3) 35 (PTC8) 36 (PTC9) 37 (PTC10)
//
// FTM3 runs free at bus / 32 = 1.875 MHz (0.533 us per count, wrapping every 35 ms); a pulse
// is the falling edge's count minus the rising edge's, modulo 2^16. Only pulses of
// 800..2200 us are taken. A channel with no valid pulse for kChannelTimeoutUs reads 0 (no
// signal); age_us is the time since the oldest of the four stick channels' last pulse, so
// the RC link counts as lost when any stick channel stops.
#pragma once

#include <cstdint>

#include "../../hal/rc_input.hpp"

namespace hq::teensy {

class Ftm3RcInput {
public:
    static constexpr int kChannels = 7;
    static constexpr uint32_t kChannelTimeoutUs = 100000;   // 5 receiver frames
    static constexpr uint16_t kMinPulseUs = 800, kMaxPulseUs = 2200;

    void begin();
    // The channels as of now. The time is taken together with the captures, so a pulse that
    // ends during the call can never look newer than "now" (and read as no signal).
    RcInput read() const;
    uint32_t rejected() const;
};

}  // namespace hq::teensy
