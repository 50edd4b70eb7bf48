#include "plant/rig_plant.hpp"

namespace hqsim {

Rotation rotation(const double q[4]) {
    const double w = q[0], x = q[1], y = q[2], z = q[3];
    return {1 - 2 * (y * y + z * z), 2 * (x * y - w * z),     2 * (x * z + w * y),
            2 * (x * y + w * z),     1 - 2 * (x * x + z * z), 2 * (y * z - w * x),
            2 * (x * z - w * y),     2 * (y * z + w * x),     1 - 2 * (x * x + y * y)};
}

Vec3 rotate(const Rotation& r, const Vec3& v) {
    return {r[0] * v[0] + r[1] * v[1] + r[2] * v[2], r[3] * v[0] + r[4] * v[1] + r[5] * v[2],
            r[6] * v[0] + r[7] * v[1] + r[8] * v[2]};
}

Vec3 rotate_back(const Rotation& r, const Vec3& v) {
    return {r[0] * v[0] + r[3] * v[1] + r[6] * v[2], r[1] * v[0] + r[4] * v[1] + r[7] * v[2],
            r[2] * v[0] + r[5] * v[1] + r[8] * v[2]};
}

SensorSample at_rest(const std::array<double, 4>& q, const Vec3& rates) {
    SensorSample s;
    s.q = q;
    s.gyro_rad_s = rates;
    s.accel_m_s2 = rotate_back(rotation(q.data()), {0.0, 0.0, -kGravity});
    return s;
}

}  // namespace hqsim
