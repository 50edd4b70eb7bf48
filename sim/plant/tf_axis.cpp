#include "plant/tf_axis.hpp"

#include <cmath>
#include <stdexcept>

namespace hqsim {

TfAxis::TfAxis(std::vector<double> a, std::vector<double> b, std::vector<double> c, double dt_s,
               int axis)
    : a_(std::move(a)), b_(std::move(b)), c_(std::move(c)), dt_s_(dt_s), axis_(axis) {
    const size_t n = b_.size();
    if (n == 0 || c_.size() != n || a_.size() != n * n) {
        throw std::invalid_argument("TfAxis: A must be n x n, B and C of length n");
    }
    if (axis < 0 || axis > 2) throw std::invalid_argument("TfAxis: axis must be 0, 1 or 2");
    x_.assign(n, 0.0);
    next_.assign(n, 0.0);
}

double TfAxis::step_command(double u) {
    const size_t n = x_.size();
    double rate = 0.0;
    for (size_t i = 0; i < n; ++i) {
        double v = b_[i] * u;
        for (size_t j = 0; j < n; ++j) v += a_[i * n + j] * x_[j];
        next_[i] = v;
    }
    x_.swap(next_);
    for (size_t i = 0; i < n; ++i) rate += c_[i] * x_[i];   // strictly proper: no feed-through
    angle_ += 0.5 * (rate_ + rate) * dt_s_;
    rate_ = rate;
    return rate;
}

void TfAxis::step(const float motor[kMaxRotors], const double*) {
    const hq::MixerCommand got = mixer_.achieved(motor);
    const float cmd[3] = {got.roll, got.pitch, got.yaw};
    step_command(static_cast<double>(cmd[axis_]));
}

std::array<double, 4> TfAxis::quaternion() const {
    std::array<double, 4> q{std::cos(0.5 * angle_), 0.0, 0.0, 0.0};
    q[1 + axis_] = std::sin(0.5 * angle_);
    return q;
}

std::array<double, 3> TfAxis::rates() const {
    std::array<double, 3> r{0.0, 0.0, 0.0};
    r[axis_] = rate_;
    return r;
}

SensorSample TfAxis::sensor(const double*) { return at_rest(quaternion(), rates()); }

}  // namespace hqsim
