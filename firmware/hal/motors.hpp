// Motor outputs, one per rotor up to kMaxRotors (core/types.hpp), central first. Contract:
// set(f, count) takes thrust fractions 0..1 for the first `count` rotors (the rotor count the
// loop flies) and is applied at once; the backend maps a thrust fraction f to its ESC signal,
// min_us + f (max_us - min_us) of that ESC's endpoints (anything not finite, or below 0, is
// 0). The outputs past `count` get their stop pulse (their min_us), armed or not. disarm()
// drives every ESC to its stop value (its min_us). set_endpoints() replaces the endpoints; the
// firmware calls it only while disarmed (it moves the stop pulse), and a backend keeps its
// previous endpoints for any ESC whose new ones are implausible (outside 800..2200 us, or max
// <= min).
#pragma once

#include <cstdint>

#include "../core/types.hpp"

namespace hq {

struct EscEndpoints {
    // Pulse widths in microseconds: min is the stop pulse, max is full thrust.
    uint16_t min_us[kMaxRotors] = {1000, 1000, 1000, 1000, 1000, 1000, 1000, 1000};
    uint16_t max_us[kMaxRotors] = {2000, 2000, 2000, 2000, 2000, 2000, 2000, 2000};
};

inline bool plausible_endpoints(uint16_t min_us, uint16_t max_us) {
    return min_us >= 800 && max_us <= 2200 && max_us > min_us;
}

class MotorOutputs {
public:
    virtual void set(const float thrust_fraction[kMaxRotors], int count) = 0;
    virtual void disarm() = 0;
    virtual void set_endpoints(const EscEndpoints& endpoints) = 0;

protected:
    ~MotorOutputs() = default;
};

}  // namespace hq
