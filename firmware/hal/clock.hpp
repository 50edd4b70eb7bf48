// Time source. Contract: micros() is monotonic, microseconds since boot, wrapping after
// 2^64 us. On the host target it is set only by the simulator (lockstep): the firmware never
// reads a wall clock. delay_us() is for device start-up waits only, never in the control loop;
// on the host target it returns at once (the emulated devices are ready immediately).
#pragma once

#include <cstdint>

namespace hq {

// A 64-bit count of time divided by a 32-bit unit (cycles a microsecond, microseconds a
// millisecond): in 32 bits while the count fits, one instruction on the Cortex-M4, where a
// 64-bit division is a library call of some fifty. The same quotient either way.
inline uint64_t divide_time(uint64_t count, uint32_t unit) {
    return count <= UINT32_MAX ? static_cast<uint32_t>(count) / unit : count / unit;
}

class Clock {
public:
    virtual uint64_t micros() const = 0;
    virtual void delay_us(uint32_t us) = 0;

protected:
    ~Clock() = default;
};

}  // namespace hq
