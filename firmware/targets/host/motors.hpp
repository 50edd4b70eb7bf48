// Host backend of the HAL motor outputs (hal/motors.hpp).
#pragma once

#include <cmath>

#include "../../hal/motors.hpp"

namespace hq {

// Motor outputs: the last thrust fractions set (kMaxRotors of them), sent back to the
// simulator.
class HostMotors final : public MotorOutputs {
public:
    // The rotors past `count` are stopped: 0.
    void set(const float thrust_fraction[kMaxRotors], int count) override {
        for (int i = 0; i < kMaxRotors; ++i) {
            const float f = i < count ? thrust_fraction[i] : 0.0f;
            value_[i] = std::isfinite(f) && f > 0.0f ? (f < 1.0f ? f : 1.0f) : 0.0f;  // NaN, inf: 0
        }
    }
    void disarm() override {
        for (float& v : value_) v = 0.0f;
    }
    // The simulator takes thrust fractions: the endpoints are kept, not used.
    void set_endpoints(const EscEndpoints& endpoints) override { endpoints_ = endpoints; }
    const EscEndpoints& endpoints() const { return endpoints_; }
    const float* values() const { return value_; }

private:
    float value_[kMaxRotors] = {};
    EscEndpoints endpoints_{};
};

}  // namespace hq
