// Per-axis transfer-function plant (sim/plant/tf_plant.py builds it): the axis's torque command, as
// the firmware's own mixer equations say the motors produce it (hq::Mixer::achieved), through
// G(z) (ZOH at the loop period, state space from python-control) to the body rate; the angle
// is the trapezoid integral of the rate. The vehicle is otherwise held level, as on a rig.
#pragma once

#include <vector>

#include "core/mixer.hpp"
#include "plant/rig_plant.hpp"

namespace hqsim {

class TfAxis final : public RigPlant {
public:
    // a: n x n row-major, b and c: n; axis 0 roll, 1 pitch, 2 yaw.
    TfAxis(std::vector<double> a, std::vector<double> b, std::vector<double> c, double dt_s,
           int axis);

    SensorSample sensor(const double* noise) override;
    void step(const float motor[kMaxRotors], const double* gust) override;
    int rotors() const override { return kMotors; }     // the mixer's, whose achieved() it uses

    double step_command(double u);     // holds u for one period; the rate at its end
    double rate_rad_s() const { return rate_; }
    double angle_rad() const { return angle_; }
    std::array<double, 4> quaternion() const;
    std::array<double, 3> rates() const;

private:
    std::vector<double> a_, b_, c_, x_, next_;
    double dt_s_;
    int axis_;
    double rate_ = 0.0, angle_ = 0.0;
    hq::Mixer mixer_;                  // the firmware's default geometry, as the firmware flies
};

}  // namespace hqsim
