// Mixer for the heterogeneous multirotor: one central rotor and four arm rotors canted
// sideways (the paper's vehicle, docs/paper.md). Derivation and figures: docs/mixer.md.
//
// Geometry (body FRD, "+" configuration): arm rotor i sits at distance l on the arm at
// azimuth psi_i = 0, 90, 180, 270 deg (1 front, 2 right, 3 back, 4 left). Each is canted by
// delta about its own arm, so its thrust T_i has a vertical part T_i cos(delta) and a
// tangential part T_i sin(delta) that gives a yaw moment l T_i sin(delta). The cant is the
// same on all four, in the sense that opposes the central rotor's reaction torque
// Q_0 = c0 T_0 (c0 signed: positive is a torque along +z, nose right). With
// Dx = T_2 - T_4, Dy = T_1 - T_3, T_a = mean arm thrust:
//
//     Fz  = T_0 + 4 cos(delta) T_a                 (total vertical thrust, N)
//     tau_x = -l cos(delta) Dx                      (roll moment, N m)
//     tau_y =  l cos(delta) Dy                      (pitch moment, N m)
//     tau_z = c0 T_0 - sign(c0) 4 l sin(delta) T_a  (yaw moment, N m)
//
// Roll and pitch come from differential arm thrust as on a quadrotor; yaw from the canted
// arms' lateral thrust against the central torque; the collective falls mainly on the
// central rotor (the 2 x 2 system for T_0, T_a). The arm rotors' own reaction torques cancel
// in pairs and are not used.
//
// Commands are normalised. Collective in [0, 1] is a fraction of the largest total vertical
// thrust. Roll, pitch and yaw are in units of the vehicle's authority at hover: with T_a,h the
// mean arm thrust at hover (weight = hover_thrust_n, no yaw), 1.0 of roll or pitch is the
// moment of moving the whole hover arm thrust to one side, l cos(delta) 2 T_a,h; 1.0 of yaw is
// the moment of changing the mean arm thrust by T_a,h, 4 l sin(delta) T_a,h. This is what the
// vehicle can do around hover without the collective giving way, and it is what makes the
// paper's auto-tuned gains (whose actuator units are not published) give rate-loop
// crossovers of tens of rad/s on the modelled vehicle; docs/mixer.md has the numbers.
// Larger commands are allowed up to the physical limits. Outputs are thrust fractions of
// each rotor's maximum, central first.
//
// Saturation keeps attitude authority first: roll and pitch are kept whole (each clipped to
// the full differential arm thrust), then yaw, and the collective gives way.
#pragma once

#include <cstdint>

namespace hq {

constexpr int kMotors = 5;   // 0 central, 1 front, 2 right, 3 back, 4 left

struct MixerGeometry {
    float arm_length_m = 0.3048f;         // the paper's table 2: 12 in moment arm
    float cant_deg = 20.0f;               // the paper's table 2: arm rotors' tilt angle
    float central_max_thrust_n = 25.0f;   // estimate: 15x5.5 in prop on a 400 KV motor, 4S
    float arm_max_thrust_n = 9.0f;        // estimate: 5x4x3 prop on a 2205 2300 KV motor, 4S
    float central_torque_per_thrust_m = 0.017f;  // estimate: Q/T = D C_Q / C_T ~ 0.381 * 0.045
    float hover_thrust_n = 9.1202f;       // weight: the paper's table 2, 0.930 kg x 9.80665 m/s^2
};

struct MixerCommand {
    float collective = 0.0f;   // 0..1
    float roll = 0.0f;         // units of hover authority (see above)
    float pitch = 0.0f;
    float yaw = 0.0f;
};

struct MixerOutput {
    float motor[kMotors] = {0, 0, 0, 0, 0};   // thrust fractions 0..1, central first
    bool saturated = false;                     // some command was not met in full:
    bool torque_limited = false;                //   a roll, pitch or yaw torque command
    bool collective_limited = false;            //   the collective (it gave way, or was out of 0..1)
};

class Mixer {
public:
    explicit Mixer(const MixerGeometry& geometry = MixerGeometry());
    MixerOutput mix(const MixerCommand& command) const;

    // The normalised command these thrust fractions actually produce (for tests and
    // telemetry: what the vehicle got, as opposed to what was asked).
    MixerCommand achieved(const float motor[kMotors]) const;

    const MixerGeometry& geometry() const { return g_; }
    // Physical scales of the normalised command (N and N m per unit).
    float max_vertical_thrust_n() const { return fz_max_; }
    float roll_pitch_torque_unit_nm() const { return txy_unit_; }
    float yaw_torque_unit_nm() const { return tz_unit_; }
    float hover_arm_thrust_n() const { return ta_hover_; }

private:
    MixerGeometry g_;
    float cos_d_, sin_d_, sign_c0_, lat_, det_;
    float fz_max_, ta_hover_, txy_unit_, tz_unit_;
};

}  // namespace hq
