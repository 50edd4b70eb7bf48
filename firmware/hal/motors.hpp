// Motor outputs. Contract: set() takes thrust fractions 0..1 for the five motors (central
// first, then arms 1-4: front, right, back, left) and is applied at once; the backend maps a
// thrust fraction to its ESC signal (anything not finite, or below 0, is 0). disarm() drives
// every ESC to its stop value.
#pragma once

namespace hq {

class MotorOutputs {
public:
    virtual void set(const float thrust_fraction[5]) = 0;
    virtual void disarm() = 0;

protected:
    ~MotorOutputs() = default;
};

}  // namespace hq
