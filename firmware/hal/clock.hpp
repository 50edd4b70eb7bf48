// Time source. Contract: micros() is monotonic, microseconds since boot, wrapping after
// 2^64 us. On the host target it is set only by the simulator (lockstep): the firmware never
// reads a wall clock. delay_us() is for device start-up waits only, never in the control loop;
// on the host target it returns at once (the emulated devices are ready immediately).
#pragma once

#include <cstdint>

namespace hq {

class Clock {
public:
    virtual uint64_t micros() const = 0;
    virtual void delay_us(uint32_t us) = 0;

protected:
    ~Clock() = default;
};

}  // namespace hq
