#include "plant/vehicle_model.hpp"

#include <algorithm>
#include <cmath>
#include <stdexcept>

namespace hqsim {
namespace {

// Coulomb friction is smoothed as F tanh(w / kFrictionSmoothRadS) so the ODE stays smooth.
constexpr double kFrictionSmoothRadS = 0.01;

using V3 = Vec3;

V3 cross(const V3& a, const V3& b) {
    return {a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]};
}

}  // namespace

VehicleModel::VehicleModel(const VehicleConfig& cfg) : cfg_(cfg) {
    if (cfg.mass_kg <= 0 || cfg.substeps < 1 || cfg.free_axis < -1 || cfg.free_axis > 2 ||
        cfg.rotors < 1 || cfg.rotors > kMaxRotors) {
        throw std::invalid_argument(
            "VehicleModel: mass > 0, substeps >= 1, free_axis -1..2, rotors 1..8");
    }
    for (double i : cfg.inertia_kg_m2) {
        if (i <= 0) throw std::invalid_argument("VehicleModel: inertia must be positive");
    }
    for (int r = 0; r < cfg.rotors; ++r) {
        if (cfg.tau_s[r] <= 0) throw std::invalid_argument("VehicleModel: tau_s must be positive");
    }
    x.fill(0.0);
    x[6] = 1.0;
}

State VehicleModel::derivative(const State& s, const double* u, const double* force_ned,
                               const double* moment_body) const {
    const VehicleConfig& c = cfg_;
    const double* q = &s[6];
    const V3 w{s[10], s[11], s[12]};
    State dx{};
    V3 h_rotor{0, 0, 0}, moment{0, 0, 0}, f_body{0, 0, 0};
    for (int r = 0; r < c.rotors; ++r) {
        const double speed = s[kBodyStates + r];
        const double w_cmd = c.w_max_rad_s[r] * std::sqrt(std::clamp(u[r], 0.0, 1.0));
        const double speed_dot = (w_cmd - speed) / c.tau_s[r];
        const double thrust = c.k_thrust[r] * speed * speed;
        dx[kBodyStates + r] = speed_dot;
        for (int k = 0; k < 3; ++k) {
            h_rotor[k] += c.j_rotor[r] * speed * c.spin_axis[r][k];
            moment[k] += thrust * c.thrust_moment[r][k]                       // thrust's arm
                         - c.c_torque[r] * thrust * c.spin_axis[r][k]         // drag torque
                         - c.j_rotor[r] * speed_dot * c.spin_axis[r][k];      // spin-up
            f_body[k] += thrust * c.thrust_dir[r][k];
        }
    }
    const V3 h{c.inertia_kg_m2[0] * w[0] + h_rotor[0], c.inertia_kg_m2[1] * w[1] + h_rotor[1],
               c.inertia_kg_m2[2] * w[2] + h_rotor[2]};
    const V3 gyro = cross(w, h);                                                // w x H
    for (int k = 0; k < 3; ++k) {
        moment[k] -= gyro[k];
        if (moment_body) moment[k] += moment_body[k];
    }
    if (c.free_axis < 0) {
        const V3 f = rotate(rotation(q), f_body);
        for (int k = 0; k < 3; ++k) {
            double force = f[k] - c.drag_n_s_m * s[3 + k] + (force_ned ? force_ned[k] : 0.0);
            if (k == 2) force += c.mass_kg * c.gravity_m_s2;
            dx[k] = s[3 + k];
            dx[3 + k] = force / c.mass_kg;
            dx[10 + k] = moment[k] / c.inertia_kg_m2[k];
        }
    } else {
        const int k = c.free_axis;
        const double hinge = -c.hinge_damping_n_m_s_rad * w[k] -
                             c.hinge_friction_n_m * std::tanh(w[k] / kFrictionSmoothRadS);
        dx[10 + k] = (moment[k] + hinge) / c.inertia_kg_m2[k];
    }
    // q' = q (x) (0, w) / 2
    dx[6] = 0.5 * (-q[1] * w[0] - q[2] * w[1] - q[3] * w[2]);
    dx[7] = 0.5 * (q[0] * w[0] + q[2] * w[2] - q[3] * w[1]);
    dx[8] = 0.5 * (q[0] * w[1] - q[1] * w[2] + q[3] * w[0]);
    dx[9] = 0.5 * (q[0] * w[2] + q[1] * w[1] - q[2] * w[0]);
    return dx;
}

void VehicleModel::step(const double* u, double dt_s, const double* force_ned,
                        const double* moment_body) {
    const double h = dt_s / cfg_.substeps;
    const int n_states = states();
    State s = x, tmp = x;
    for (int n = 0; n < cfg_.substeps; ++n) {
        const State k1 = derivative(s, u, force_ned, moment_body);
        for (int i = 0; i < n_states; ++i) tmp[i] = s[i] + 0.5 * h * k1[i];
        const State k2 = derivative(tmp, u, force_ned, moment_body);
        for (int i = 0; i < n_states; ++i) tmp[i] = s[i] + 0.5 * h * k2[i];
        const State k3 = derivative(tmp, u, force_ned, moment_body);
        for (int i = 0; i < n_states; ++i) tmp[i] = s[i] + h * k3[i];
        const State k4 = derivative(tmp, u, force_ned, moment_body);
        for (int i = 0; i < n_states; ++i) s[i] += (h / 6.0) * (k1[i] + 2 * k2[i] + 2 * k3[i] + k4[i]);
        const double norm = std::sqrt(s[6] * s[6] + s[7] * s[7] + s[8] * s[8] + s[9] * s[9]);
        for (int i = 6; i < 10; ++i) s[i] /= norm;
    }
    x = s;
}

VehicleRig::VehicleRig(VehicleModel& model, double dt_s, const ImuConfig& imu,
                       double rotational_damping_n_m_s_rad)
    : model_(model), dt_s_(dt_s), imu_(imu), rot_damping_(rotational_damping_n_m_s_rad) {
    if (imu.latency_samples < 0) throw std::invalid_argument("VehicleRig: latency >= 0");
}

std::array<double, 3> VehicleRig::specific_force() const {
    const State& s = model_.x;
    const auto r = rotation(&s[6]);
    V3 accel_ned{0.0, 0.0, 0.0};
    if (model_.config().free_axis < 0) {
        const State dx = model_.derivative(s, last_u_.data(), nullptr, nullptr);
        accel_ned = {dx[3], dx[4], dx[5]};
    }
    accel_ned[2] -= kGravity;
    return rotate_back(r, accel_ned);
}

SensorSample VehicleRig::sensor(const double* noise) {
    const State& s = model_.x;
    SensorSample now;
    now.q = {s[6], s[7], s[8], s[9]};
    now.gyro_rad_s = {s[10], s[11], s[12]};
    now.accel_m_s2 = specific_force();
    if (!imu_.enabled) return now;
    for (int k = 0; k < 3; ++k) {
        now.gyro_rad_s[k] += imu_.gyro_bias_rad_s[k] + (noise ? noise[k] : 0.0);
        now.accel_m_s2[k] += noise ? noise[3 + k] : 0.0;
    }
    delay_.push_back(now);                  // the chip reports the sample `latency` loops old
    if (delay_.size() > static_cast<size_t>(imu_.latency_samples) + 1) delay_.pop_front();
    return delay_.front();
}

void VehicleRig::step(const float motor[kMaxRotors], const double* gust) {
    for (int r = 0; r < rotors(); ++r) last_u_[r] = static_cast<double>(motor[r]);
    if (!gust) {
        model_.step(last_u_.data(), dt_s_, nullptr, nullptr);
        return;
    }
    // Gust velocity through the airframe's linear drag (body, then to NED), gust rates
    // through the rotational damping (sim/plant/dryden.py).
    const double drag = model_.config().drag_n_s_m;
    const V3 force = rotate(rotation(&model_.x[6]), {drag * gust[0], drag * gust[1], drag * gust[2]});
    const double moment[3] = {rot_damping_ * gust[3], rot_damping_ * gust[4], rot_damping_ * gust[5]};
    model_.step(last_u_.data(), dt_s_, force.data(), moment);
}

}  // namespace hqsim
