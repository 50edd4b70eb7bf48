// Host backend of the HAL clock (hal/clock.hpp).
#pragma once

#include <cstdint>

#include "../../hal/clock.hpp"

namespace hq {

// Lockstep clock: the simulator sets the time with every sensor frame; nothing here reads a
// wall clock. Start-up delays return at once (the emulated devices are ready immediately).
// The HAL's contract is a monotonic clock: a time earlier than the current one is ignored.
class HostClock final : public Clock {
public:
    uint64_t micros() const override { return now_us_; }
    void delay_us(uint32_t) override {}
    void set(uint64_t now_us) {
        if (now_us > now_us_) now_us_ = now_us;
    }

private:
    uint64_t now_us_ = 0;
};

}  // namespace hq
