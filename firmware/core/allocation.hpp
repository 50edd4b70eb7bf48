// Control allocation from a rotor geometry: a central rotor (rotor 0) and up to seven more,
// each given by its position, thrust axis, largest thrust, moment ratio and spin, as an
// autopilot keeps them in parameters. Equations, frames, units and the saturation rules:
// docs/mixer.md, "Allocation from a rotor geometry".
//
// From the geometry, once: the effectiveness matrix B (vertical force and roll, pitch, yaw
// moments per unit of each rotor's thrust fraction), a check that B can produce all four
// independently (rank 4; else a short reason the link can send), the pseudo-inverse of B, the
// normalised command units and the per-axis limits. Per loop: the command (today's
// MixerCommand: collective 0..1, roll, pitch and yaw in units of hover authority) to thrust
// fractions by the pseudo-inverse, with the mixer's saturation priorities (roll and pitch
// kept whole, then yaw, the collective gives way) and its flags. With the default geometry
// (MixerGeometry's vehicle as 5 rotors) it gives the Mixer's outputs to float precision.
//
// No heap, no exceptions: fixed arrays of at most kMaxRotors (types.hpp) rotors, float throughout.
#pragma once

#include <cstdint>

#include "mixer.hpp"
#include "types.hpp"

namespace hq {

constexpr int kMinRotors = 4;       // four independent commands need four rotors at least
constexpr int kAllocationRows = 4;  // vertical force, roll, pitch, yaw: MixerCommand's order

// One rotor, body frame FRD, origin at the vehicle's centre of mass.
struct RotorGeometry {
    Vec3 position_m;                    // where the thrust acts, m
    Vec3 axis{0.0f, 0.0f, -1.0f};       // unit vector the thrust pushes the body along
    float max_thrust_n = 0.0f;          // thrust at fraction 1, N (PX4's CA_ROTORn_CT)
    float moment_ratio_m = 0.0f;        // reaction torque per newton of thrust, m (>= 0)
    int spin = 1;                       // +1 counter-clockwise seen from where the thrust
                                        // points, -1 clockwise (PX4's sign of CA_ROTORn_KM)
};

struct AllocationGeometry {
    RotorGeometry rotor[kMaxRotors];
    int count = 0;                      // rotors in use, rotor[0] the central one
    float hover_thrust_n = 0.0f;        // weight: the vertical force at hover, N
};

// MixerGeometry's vehicle as rotors: the central rotor and `arms` arm rotors evenly spaced
// from azimuth 0 (front), each canted about its arm against the central rotor's torque.
// With arms = 4 this is the Mixer's "+" vehicle; the arms' own reaction torques are not
// used (moment ratio 0), as in the Mixer.
AllocationGeometry canted_arms_geometry(const MixerGeometry& g, int arms = 4);

struct AllocationOutput {
    float motor[kMaxRotors] = {};       // thrust fractions 0..1, rotor order; unused ones 0
    bool saturated = false;             // the same flags as MixerOutput's
    bool torque_limited = false;
    bool collective_limited = false;
};

class Allocation {
public:
    // Computes everything from the geometry; ok() says whether it was taken.
    explicit Allocation(
        const AllocationGeometry& geometry = canted_arms_geometry(MixerGeometry()));
    // A refused geometry leaves the allocation refusing: zero thrust, every flag set.
    bool configure(const AllocationGeometry& geometry);
    bool ok() const { return reason_[0] == '\0'; }
    const char* reason() const { return reason_; }   // why refused, "" when ok
    int count() const { return n_; }

    AllocationOutput allocate(const MixerCommand& command) const;
    // The normalised command these thrust fractions produce (rotor order, count() of them).
    MixerCommand achieved(const float motor[]) const;

    // B: row (MixerCommand's order: vertical force N, roll, pitch, yaw N m) per unit of a
    // rotor's thrust fraction. A: a rotor's thrust fraction per unit of a normalised command.
    float effectiveness(int row, int rotor) const { return b_[row][rotor]; }
    float allocation(int rotor, int column) const { return a_[rotor][column]; }
    // Physical size of one unit of each normalised command: N, then N m.
    float unit(int row) const { return unit_[row]; }
    // A rotor's thrust fraction at hover (weight, no moment).
    float hover_fraction(int rotor) const { return a_[rotor][0] * hover_collective_; }

private:
    struct Range { float lo, hi; };
    bool refuse(const char* text, int rotor = -1);
    bool check_rotors(const AllocationGeometry& g);
    bool effectiveness_from(const AllocationGeometry& g);
    bool pseudo_inverse(float p[kMaxRotors][kAllocationRows]);
    bool units_and_limits(const float p[kMaxRotors][kAllocationRows], float hover_thrust_n);
    Range yaw_range(const float k[]) const;
    Range collective_range(const float k[], float yaw) const;
    float roll_pitch_scale(const float k[]) const;

    int n_ = 0;
    char reason_[48] = "";
    float b_[kAllocationRows][kMaxRotors] = {};   // physical effectiveness
    float a_[kMaxRotors][kAllocationRows] = {};   // normalised allocation
    float unit_[kAllocationRows] = {};
    float hover_collective_ = 0.0f;               // the collective at hover, W / Fz_max
    float roll_max_ = 0.0f, pitch_max_ = 0.0f;    // per-axis limits, normalised units
    // Per rotor, for the saturation bounds: has a collective coefficient, its inverse, and
    // the ratio of its yaw coefficient to it.
    bool has_c_[kMaxRotors] = {};
    float inv_c_[kMaxRotors] = {};
    float g_[kMaxRotors] = {};
};

}  // namespace hq
