#include "allocation.hpp"

#include <cmath>
#include <initializer_list>

namespace hq {

namespace {
float clamp(float x, float lo, float hi) { return x < lo ? lo : (x > hi ? hi : x); }
float fmax_(float a, float b) { return a > b ? a : b; }
float fmin_(float a, float b) { return a < b ? a : b; }
constexpr float kDegToRad = 0.017453292519943295f;
constexpr float kTwoPi = 6.283185307179586f;
// Far outside any command: an unbounded end of a range.
constexpr float kUnbounded = 1e30f;
// Rows: MixerCommand's order.
constexpr int kThrust = 0, kRoll = 1, kPitch = 2, kYaw = 3;
// A thrust axis is a unit vector to within this (float parameters of a few digits).
constexpr float kUnitAxisTolerance = 1e-3f;
// A moment row is none when its norm is below this fraction of the geometry's largest
// moments (sum of max thrust times lever arm and moment ratio): float round-off of the
// positions' sines and cosines is ~1e-7 of it.
constexpr float kNoMoment = 1e-6f;
// A row is independent of those before it when the squared sine of its angle to their span
// exceeds this (0.01 rad): closer than that, the command would need thrusts ~100 times its
// own size.
constexpr float kIndependence = 1e-4f;
// An axis has authority at hover when the arms' hover thrust fractions, weighted by their
// lever arms, average at least this (the default vehicle's arms: 0.035).
constexpr float kMinHoverFraction = 1e-4f;
// Thrust-fraction slack where two rotors' bounds meet exactly (a pair at 0 and 1 at full
// roll: a single collective is left): a few float ulps of 1.0, above the round-off of the
// pseudo-inverse, so that they meet in float too. The bounds themselves have no slack.
constexpr float kSlack = 1e-6f;
// A rotor's collective coefficient counts as zero below this fraction of the largest one;
// two rotors' yaw-to-collective ratios are parallel closer than this relative difference.
constexpr float kTiny = 1e-6f;
constexpr float kParallel = 1e-5f;
// Bisection steps of the roll and pitch scale when the two cannot be kept whole: 2^-20.
constexpr int kScaleSteps = 20;

Vec3 cross(const Vec3& a, const Vec3& b) {
    return Vec3{a.y * b.z - a.z * b.y, a.z * b.x - a.x * b.z, a.x * b.y - a.y * b.x};
}
float norm(const Vec3& v) { return std::sqrt(v.x * v.x + v.y * v.y + v.z * v.z); }
bool finite(const Vec3& v) {
    return std::isfinite(v.x) && std::isfinite(v.y) && std::isfinite(v.z);
}
}  // namespace

AllocationGeometry canted_arms_geometry(const MixerGeometry& g, int arms) {
    AllocationGeometry out;
    out.count = arms + 1;
    out.hover_thrust_n = g.hover_thrust_n;
    const float c0 = g.central_torque_per_thrust_m;
    const float sign_c0 = c0 >= 0.0f ? 1.0f : -1.0f;
    RotorGeometry& central = out.rotor[0];
    central.max_thrust_n = g.central_max_thrust_n;
    central.moment_ratio_m = sign_c0 * c0;
    central.spin = c0 >= 0.0f ? 1 : -1;      // reaction torque c0 T_0 about +z
    const float cos_d = std::cos(g.cant_deg * kDegToRad);
    const float sin_d = std::sin(g.cant_deg * kDegToRad);
    const float tangential = -sign_c0 * sin_d;   // the cant opposes the central torque
    for (int i = 1; i <= arms && i < kMaxRotors; ++i) {
        const float psi = kTwoPi * static_cast<float>(i - 1) / static_cast<float>(arms);
        const float c = std::cos(psi), s = std::sin(psi);
        RotorGeometry& r = out.rotor[i];
        r.position_m = Vec3{g.arm_length_m * c, g.arm_length_m * s, 0.0f};
        r.axis = Vec3{-tangential * s, tangential * c, -cos_d};
        r.max_thrust_n = g.arm_max_thrust_n;
        r.spin = i % 2 == 1 ? -1 : 1;        // alternate; unused with moment ratio 0
    }
    return out;
}

Allocation::Allocation(const AllocationGeometry& geometry) { configure(geometry); }

// The reason: "allocation: " and the text, with '#' replaced by the rotor's number.
[[gnu::noinline]] bool Allocation::refuse(const char* text, int rotor) {
    static const char kPrefix[] = "allocation: ";
    int i = 0;
    for (const char* from : {kPrefix, text})
        for (; *from != '\0' && i < static_cast<int>(sizeof reason_) - 1; ++from, ++i)
            reason_[i] = *from == '#' ? static_cast<char>('0' + rotor) : *from;
    reason_[i] = '\0';
    return false;
}

bool Allocation::configure(const AllocationGeometry& geometry) {
    reason_[0] = '\0';
    n_ = 0;
    float p[kMaxRotors][kAllocationRows];   // the pseudo-inverse of B: needed only here
    return check_rotors(geometry) && effectiveness_from(geometry) && pseudo_inverse(p)
           && units_and_limits(p, geometry.hover_thrust_n);
}

bool Allocation::check_rotors(const AllocationGeometry& g) {
    if (g.count < kMinRotors || g.count > kMaxRotors)
        return refuse("4 to 8 rotors needed");
    if (!(g.hover_thrust_n > 0.0f) || !std::isfinite(g.hover_thrust_n))
        return refuse("hover thrust not positive");
    for (int i = 0; i < g.count; ++i) {
        const RotorGeometry& r = g.rotor[i];
        if (!finite(r.position_m)) return refuse("rotor # position not finite", i);
        if (!finite(r.axis) || !(std::fabs(norm(r.axis) - 1.0f) <= kUnitAxisTolerance))
            return refuse("rotor # axis not a unit vector", i);
        if (!(r.max_thrust_n > 0.0f) || !std::isfinite(r.max_thrust_n))
            return refuse("rotor # max thrust not positive", i);
        if (!(r.moment_ratio_m >= 0.0f) || !std::isfinite(r.moment_ratio_m))
            return refuse("rotor # moment ratio negative", i);
        if (r.spin != 1 && r.spin != -1) return refuse("rotor # spin not +1 or -1", i);
    }
    return true;
}

// B: per unit thrust fraction, the vertical force (up) and the moment r x F of the thrust
// plus the reaction torque, -spin * km * T along the axis.
bool Allocation::effectiveness_from(const AllocationGeometry& g) {
    float moment_scale = 0.0f;
    for (int i = 0; i < g.count; ++i) {
        const RotorGeometry& r = g.rotor[i];
        const float t = r.max_thrust_n;
        const float km = static_cast<float>(r.spin) * r.moment_ratio_m;
        const Vec3 arm = cross(r.position_m, r.axis);
        b_[kThrust][i] = -r.axis.z * t;
        b_[kRoll][i] = (arm.x - km * r.axis.x) * t;
        b_[kPitch][i] = (arm.y - km * r.axis.y) * t;
        b_[kYaw][i] = (arm.z - km * r.axis.z) * t;
        moment_scale += t * (norm(r.position_m) + r.moment_ratio_m);
    }
    n_ = g.count;
    static const char* const kNone[kAllocationRows] = {
        "no upward thrust", "no roll moment",
        "no pitch moment", "no yaw moment"};
    float fz_max = 0.0f;
    for (int i = 0; i < n_; ++i) fz_max += b_[kThrust][i];
    if (!(fz_max > 0.0f)) return refuse(kNone[kThrust]);
    for (int k = kRoll; k <= kYaw; ++k) {
        float sq = 0.0f;
        for (int i = 0; i < n_; ++i) sq += b_[k][i] * b_[k][i];
        if (!(std::sqrt(sq) > kNoMoment * moment_scale)) return refuse(kNone[k]);
    }
    return true;
}

// P = B^T (B B^T)^-1, computed on the rows scaled to unit norm (D B, D diagonal), whose Gram
// matrix is well conditioned when the rows are independent: P = (D B)^T (D B B^T D)^-1 D.
// The Cholesky factor's pivots are the squared sines of each row's angle to the span of the
// rows before it: the rank check.
bool Allocation::pseudo_inverse(float p[kMaxRotors][kAllocationRows]) {
    float d[kAllocationRows], gram[kAllocationRows][kAllocationRows];
    for (int j = 0; j < kAllocationRows; ++j) {
        float sq = 0.0f;
        for (int i = 0; i < n_; ++i) sq += b_[j][i] * b_[j][i];
        d[j] = 1.0f / std::sqrt(sq);
    }
    for (int j = 0; j < kAllocationRows; ++j)
        for (int k = 0; k < kAllocationRows; ++k) {
            float s = 0.0f;
            for (int i = 0; i < n_; ++i) s += b_[j][i] * b_[k][i];
            gram[j][k] = d[j] * d[k] * s;
        }
    static const char* const kDependent[kAllocationRows] = {
        "", "roll depends on the thrust",
        "pitch depends on thrust and roll",
        "yaw depends on thrust, roll, pitch"};
    float l[kAllocationRows][kAllocationRows] = {};
    for (int j = 0; j < kAllocationRows; ++j) {
        float pivot = gram[j][j];
        for (int m = 0; m < j; ++m) pivot -= l[j][m] * l[j][m];
        if (!(pivot > kIndependence)) return refuse(kDependent[j]);
        l[j][j] = std::sqrt(pivot);
        for (int i = j + 1; i < kAllocationRows; ++i) {
            float s = gram[i][j];
            for (int m = 0; m < j; ++m) s -= l[i][m] * l[j][m];
            l[i][j] = s / l[j][j];
        }
    }
    float inv[kAllocationRows][kAllocationRows];   // (L L^T)^-1, a column at a time
    for (int c = 0; c < kAllocationRows; ++c) {
        float y[kAllocationRows];
        for (int i = 0; i < kAllocationRows; ++i) {
            float s = i == c ? 1.0f : 0.0f;
            for (int m = 0; m < i; ++m) s -= l[i][m] * y[m];
            y[i] = s / l[i][i];
        }
        for (int i = kAllocationRows - 1; i >= 0; --i) {
            float s = y[i];
            for (int m = i + 1; m < kAllocationRows; ++m) s -= l[m][i] * inv[m][c];
            inv[i][c] = s / l[i][i];
        }
    }
    for (int i = 0; i < n_; ++i)
        for (int k = 0; k < kAllocationRows; ++k) {
            float s = 0.0f;
            for (int j = 0; j < kAllocationRows; ++j) s += b_[j][i] * d[j] * inv[j][k];
            p[i][k] = s * d[k];
        }
    return true;
}

// The normalised units (docs/mixer.md): collective 1 is every rotor at full thrust's vertical
// force; one unit of roll, pitch or yaw is the moment of the arm rotors' hover thrusts if
// each pushed the way of the moment, sum over i >= 1 of |B_ki| times the hover fraction.
bool Allocation::units_and_limits(const float p[kMaxRotors][kAllocationRows],
                                  float hover_thrust_n) {
    unit_[kThrust] = 0.0f;
    for (int i = 0; i < n_; ++i) unit_[kThrust] += b_[kThrust][i];
    hover_collective_ = hover_thrust_n / unit_[kThrust];
    float hover[kMaxRotors];
    for (int i = 0; i < n_; ++i) {
        hover[i] = p[i][kThrust] * hover_thrust_n;
        if (!(hover[i] >= -kSlack && hover[i] <= 1.0f + kSlack))
            return refuse("hover needs rotor # beyond 0..1", i);
    }
    static const char* const kNoAuthority[kAllocationRows] = {
        "", "no roll authority at hover", "no pitch authority at hover",
        "no yaw authority at hover"};
    for (int k = kRoll; k <= kYaw; ++k) {
        float u = 0.0f, lever = 0.0f;
        for (int i = 1; i < n_; ++i) {
            u += std::fabs(b_[k][i]) * hover[i];
            lever += std::fabs(b_[k][i]);
        }
        if (!(u > kMinHoverFraction * lever)) return refuse(kNoAuthority[k]);
        unit_[k] = u;
    }
    float roll_peak = 0.0f, pitch_peak = 0.0f, c_peak = 0.0f;
    for (int i = 0; i < n_; ++i) {
        for (int k = 0; k < kAllocationRows; ++k) a_[i][k] = p[i][k] * unit_[k];
        roll_peak = fmax_(roll_peak, std::fabs(a_[i][kRoll]));
        pitch_peak = fmax_(pitch_peak, std::fabs(a_[i][kPitch]));
        c_peak = fmax_(c_peak, std::fabs(a_[i][kThrust]));
    }
    // Each of roll and pitch alone may swing a rotor by half its range around mid-thrust.
    roll_max_ = 0.5f / roll_peak;
    pitch_max_ = 0.5f / pitch_peak;
    for (int i = 0; i < n_; ++i) {
        has_c_[i] = std::fabs(a_[i][kThrust]) > kTiny * c_peak;
        inv_c_[i] = has_c_[i] ? 1.0f / a_[i][kThrust] : 0.0f;
        g_[i] = a_[i][kYaw] * inv_c_[i];
    }
    return true;
}

MixerCommand Allocation::achieved(const float motor[]) const {
    float c[kAllocationRows] = {};
    for (int k = 0; k < kAllocationRows; ++k) {
        for (int i = 0; i < n_; ++i) c[k] += b_[k][i] * motor[i];
        c[k] = ok() ? c[k] / unit_[k] : 0.0f;
    }
    return MixerCommand{c[kThrust], c[kRoll], c[kPitch], c[kYaw]};
}

// Each rotor i: 0 <= k_i + a_i c + b_i y <= 1, with k the roll and pitch part,
// c the collective, y the yaw and a, b their allocation columns. A rotor with a collective
// coefficient bounds c between lower_i - g_i y and upper_i - g_i y (g_i = b_i / a_i); the yaw
// range is where every lower bound stays below every upper bound (Fourier-Motzkin
// elimination of c), cut further by the rotors without one.
Allocation::Range Allocation::yaw_range(const float k[]) const {
    constexpr Range kEmpty{1.0f, -1.0f};
    Range r{-kUnbounded, kUnbounded};
    float lower[kMaxRotors] = {}, upper[kMaxRotors] = {};
    for (int i = 0; i < n_; ++i) {
        const float lo = -k[i], hi = 1.0f - k[i];
        if (has_c_[i]) {
            lower[i] = fmin_(lo * inv_c_[i], hi * inv_c_[i]);
            upper[i] = fmax_(lo * inv_c_[i], hi * inv_c_[i]);
            continue;
        }
        const float b = a_[i][kYaw];
        if (b == 0.0f) {
            if (lo > kSlack || hi < -kSlack) return kEmpty;
            continue;
        }
        r.lo = fmax_(r.lo, fmin_(lo / b, hi / b));
        r.hi = fmin_(r.hi, fmax_(lo / b, hi / b));
    }
    for (int i = 0; i < n_; ++i)
        for (int j = 0; j < n_; ++j) {
            if (i == j || !has_c_[i] || !has_c_[j]) continue;
            // lower_i - g_i y <= upper_j - g_j y  <=>  (g_j - g_i) y <= upper_j - lower_i
            const float dg = g_[j] - g_[i], room = upper[j] - lower[i];
            const float slack = kSlack * fmax_(std::fabs(inv_c_[i]), std::fabs(inv_c_[j]));
            if (std::fabs(dg) <= kParallel * fmax_(std::fabs(g_[i]), std::fabs(g_[j]))) {
                if (room < -slack) return kEmpty;
            } else if (dg > 0.0f) {
                r.hi = fmin_(r.hi, room / dg);
            } else {
                r.lo = fmax_(r.lo, room / dg);
            }
        }
    return r;
}

Allocation::Range Allocation::collective_range(const float k[], float yaw) const {
    Range r{-kUnbounded, kUnbounded};
    for (int i = 0; i < n_; ++i) {
        if (!has_c_[i]) continue;
        const float lo = -k[i] - a_[i][kYaw] * yaw;
        const float hi = 1.0f - k[i] - a_[i][kYaw] * yaw;
        r.lo = fmax_(r.lo, fmin_(lo * inv_c_[i], hi * inv_c_[i]));
        r.hi = fmin_(r.hi, fmax_(lo * inv_c_[i], hi * inv_c_[i]));
    }
    return r;
}

// 1 when some collective and yaw carry roll and pitch as they are; else the largest scale
// of both together that they can carry (never needed by the default geometry, whose roll
// and pitch use separate rotors).
float Allocation::roll_pitch_scale(const float k[]) const {
    const Range whole = yaw_range(k);
    if (whole.lo <= whole.hi) return 1.0f;
    float lo = 0.0f, hi = 1.0f, scaled[kMaxRotors];
    for (int step = 0; step < kScaleSteps; ++step) {
        const float mid = 0.5f * (lo + hi);
        for (int i = 0; i < n_; ++i) scaled[i] = mid * k[i];
        const Range r = yaw_range(scaled);
        (r.lo <= r.hi ? lo : hi) = mid;
    }
    return lo;
}

// Today's saturation rules, generalised (docs/mixer.md): roll and pitch each clipped to its
// own limit and kept whole; yaw kept within the range that leaves them whole; the collective
// the nearest that keeps both.
AllocationOutput Allocation::allocate(const MixerCommand& cmd) const {
    AllocationOutput out;
    if (!ok()) {
        out.saturated = out.torque_limited = out.collective_limited = true;
        return out;
    }
    const float roll = clamp(cmd.roll, -roll_max_, roll_max_);
    const float pitch = clamp(cmd.pitch, -pitch_max_, pitch_max_);
    const float collective = clamp(cmd.collective, 0.0f, 1.0f);
    out.torque_limited = roll != cmd.roll || pitch != cmd.pitch;
    out.collective_limited = collective != cmd.collective;
    float k[kMaxRotors], u[kMaxRotors];
    bool inside = true;
    for (int i = 0; i < n_; ++i) {
        k[i] = roll * a_[i][kRoll] + pitch * a_[i][kPitch];
        u[i] = k[i] + collective * a_[i][kThrust] + cmd.yaw * a_[i][kYaw];
        inside = inside && u[i] >= 0.0f && u[i] <= 1.0f;
    }
    if (!inside) {
        const float scale = roll_pitch_scale(k);
        if (scale < 1.0f) {
            for (int i = 0; i < n_; ++i) k[i] *= scale;
            out.torque_limited = true;
        }
        const Range yr = yaw_range(k);
        const float yaw = clamp(cmd.yaw, yr.lo, yr.hi);
        out.torque_limited = out.torque_limited || yaw != cmd.yaw;
        const Range cr = collective_range(k, yaw);
        const float c = cr.lo <= cr.hi ? clamp(collective, cr.lo, cr.hi) : 0.5f * (cr.lo + cr.hi);
        out.collective_limited = out.collective_limited || c != collective;
        for (int i = 0; i < n_; ++i) u[i] = k[i] + c * a_[i][kThrust] + yaw * a_[i][kYaw];
    }
    for (int i = 0; i < n_; ++i) out.motor[i] = clamp(u[i], 0.0f, 1.0f);   // round-off only
    out.saturated = out.torque_limited || out.collective_limited;
    return out;
}

}  // namespace hq
