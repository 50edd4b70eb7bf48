// Motor outputs. Contract: set() takes thrust fractions 0..1 for the five motors (central
// first, then arms 1-4: front, right, back, left) and is applied at once; the backend maps a
// thrust fraction f to its ESC signal, min_us + f (max_us - min_us) of that ESC's endpoints
// (anything not finite, or below 0, is 0). disarm() drives every ESC to its stop value (its
// min_us). set_endpoints() replaces the endpoints; the firmware calls it only while disarmed
// (it moves the stop pulse), and a backend keeps its previous endpoints for any ESC whose
// new ones are implausible (outside 800..2200 us, or max <= min).
#pragma once

#include <cstdint>

namespace hq {

struct EscEndpoints {
    // Pulse widths in microseconds: min is the stop pulse, max is full thrust.
    uint16_t min_us[5] = {1000, 1000, 1000, 1000, 1000};
    uint16_t max_us[5] = {2000, 2000, 2000, 2000, 2000};
};

inline bool plausible_endpoints(uint16_t min_us, uint16_t max_us) {
    return min_us >= 800 && max_us <= 2200 && max_us > min_us;
}

class MotorOutputs {
public:
    virtual void set(const float thrust_fraction[5]) = 0;
    virtual void disarm() = 0;
    virtual void set_endpoints(const EscEndpoints& endpoints) = 0;

protected:
    ~MotorOutputs() = default;
};

}  // namespace hq
