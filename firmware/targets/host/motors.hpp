// Host backend of the HAL motor outputs (hal/motors.hpp).
#pragma once

#include <cmath>

#include "../../hal/motors.hpp"

namespace hq {

// Motor outputs: the last thrust fractions set, sent back to the simulator.
class HostMotors final : public MotorOutputs {
public:
    void set(const float thrust_fraction[5]) override {
        for (int i = 0; i < 5; ++i) {
            const float f = thrust_fraction[i];
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
    float value_[5] = {0, 0, 0, 0, 0};
    EscEndpoints endpoints_{};
};

}  // namespace hq
