// The 6-DoF heterogeneous multirotor's equations of motion (sim/plant/vehicle.py documents the
// physics and builds the geometry; docs/vehicle-model.md derives it). This is the one
// implementation of the derivative and the RK4 step: Python's Vehicle calls it, and the
// lockstep engine steps it frame after frame.
#pragma once

#include <array>
#include <deque>

#include "plant/rig_plant.hpp"

namespace hqsim {

constexpr int kBodyStates = 13;   // position NED (3), velocity NED (3), quaternion (4), rates (3)
// The body's states, then one speed per rotor (the vehicle's first `rotors` of kMaxRotors).
constexpr int kStates = kBodyStates + kMaxRotors;
using State = std::array<double, kStates>;

// Everything the equations need, already in SI units and body axes (Python derives it from
// the vehicle file: sim/plant/vehicle.py, Vehicle._geometry).
struct VehicleConfig {
    double mass_kg = 0.93;
    std::array<double, 3> inertia_kg_m2{0.0, 0.0, 0.0};     // principal, body FRD
    double drag_n_s_m = 0.0;
    double gravity_m_s2 = kGravity;
    double hinge_damping_n_m_s_rad = 0.0;
    double hinge_friction_n_m = 0.0;
    int free_axis = -1;                                     // -1: free flight; 0/1/2: rig
    int substeps = 2;                                       // RK4 steps per step()
    int rotors = kMotors;                                   // 1..kMaxRotors; the rows used below
    std::array<std::array<double, 3>, kMaxRotors> thrust_dir{};     // unit vectors, body
    std::array<std::array<double, 3>, kMaxRotors> thrust_moment{};  // r x d, m
    std::array<std::array<double, 3>, kMaxRotors> spin_axis{};      // spin sign x thrust_dir
    std::array<double, kMaxRotors> k_thrust{}, c_torque{}, j_rotor{}, tau_s{}, w_max_rad_s{};
};

class VehicleModel {
public:
    explicit VehicleModel(const VehicleConfig& cfg);

    // d/dt of `x` for thrust fractions `u` (one per rotor); force_ned (N) and moment_body
    // (N m) may be null. The states past the rotors' stay zero.
    State derivative(const State& x, const double* u, const double* force_ned,
                     const double* moment_body) const;
    // Advance the held state by dt_s with u held (zero-order hold).
    void step(const double* u, double dt_s, const double* force_ned, const double* moment_body);
    // The state's values in use: the body's and one per rotor.
    int states() const { return kBodyStates + cfg_.rotors; }

    State x{};
    const VehicleConfig& config() const { return cfg_; }

private:
    VehicleConfig cfg_;
};

// The vehicle on its rig (or free) as a plant: motor lags, gusts as disturbances, and the
// MPU6050 the firmware reads (residual gyro bias, noise given per frame, DMP latency). It
// takes one thrust fraction per rotor of the vehicle, whatever their number.
struct ImuConfig {
    bool enabled = false;                        // false: ideal sensor, no latency
    std::array<double, 3> gyro_bias_rad_s{0.0, 0.0, 0.0};
    int latency_samples = 0;
};

class VehicleRig final : public RigPlant {
public:
    VehicleRig(VehicleModel& model, double dt_s, const ImuConfig& imu,
               double rotational_damping_n_m_s_rad);

    SensorSample sensor(const double* noise) override;
    void step(const float motor[kMaxRotors], const double* gust) override;
    int rotors() const override { return model_.config().rotors; }

    // What an accelerometer at the centre of mass reads now (body FRD, m/s^2).
    std::array<double, 3> specific_force() const;

private:
    VehicleModel& model_;
    double dt_s_;
    ImuConfig imu_;
    double rot_damping_;
    std::array<double, kMaxRotors> last_u_{};
    std::deque<SensorSample> delay_;
};

}  // namespace hqsim
