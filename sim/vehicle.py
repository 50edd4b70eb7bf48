"""6-DoF model of the heterogeneous multirotor, free or on a one-axis test rig.

State: position and velocity in NED (m, m/s), attitude quaternion (body FRD -> NED,
w x y z), body rates (rad/s), and the five rotor speeds (rad/s; central first, then arms
front, right, back, left). Inputs: the five thrust fractions the firmware sends (0..1).

Physics (docs/vehicle-model.md has the derivation):

* Rotors: first-order speed lag ``dW/dt = (W_cmd - W) / tau``, ``W_cmd = W_max sqrt(u)`` (the
  ESC maps a thrust fraction to speed; thrust is ``k_T W^2``, so ``u`` is the fraction of
  maximum thrust at steady state). Aerodynamic drag torque on each prop ``Q = c_Q T``.
* Thrust directions: central along -z; arm rotor i along
  ``d_i = -cos(delta) z - spin_c sin(delta) t_i`` with ``t_i`` the tangential unit vector at
  its azimuth, so the lateral thrust's yaw moment opposes the central rotor's reaction torque.
  Each rotor's spin axis is ``a_r = spin_r d_r`` (counter-clockwise seen from the thrust side).
* Rotation: total angular momentum ``H = I w + sum J_r W_r a_r`` obeys
  ``I dw/dt = M_thrust - sum Q_r a_r - sum J_r dW_r/dt a_r - w x H + M_dist``: reaction
  torques, spin-up reaction and gyroscopic precession of the big central rotor all follow.
* Translation: ``m dv/dt = R F_body + m g e_z - c_d v + F_dist`` (free flight only).
* Rigs (SPEC.md: the vehicle held on its thrust line with one axis free): position fixed,
  body rates other than the free axis held at zero by the rig, plus hinge damping and
  (smoothed) Coulomb friction on the free axis.

Integration: classical Runge-Kutta 4 with ``substeps`` steps per call.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from .params import VehicleParams, load_params

__all__ = ["Vehicle", "RIGS", "GRAVITY_M_S2"]

GRAVITY_M_S2 = 9.80665
RIGS = ("roll", "pitch", "yaw", "free")
#: Coulomb friction is smoothed as F tanh(w / FRICTION_SMOOTH_RAD_S) so the ODE stays smooth.
FRICTION_SMOOTH_RAD_S = 0.01
N_ROTORS = 5


def _quat_mul(a, b):
    aw, ax, ay, az = a
    bw, bx, by, bz = b
    return np.array([aw * bw - ax * bx - ay * by - az * bz, aw * bx + ax * bw + ay * bz - az * by,
                     aw * by - ax * bz + ay * bw + az * bx, aw * bz + ax * by - ay * bx + az * bw])


def _cross(a, b):
    """3-vector cross product (np.cross's axis handling costs more than the arithmetic)."""
    return np.array([a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]])


def rotation_matrix(q):
    """Body FRD -> NED rotation of the unit quaternion ``q`` (w, x, y, z)."""
    w, x, y, z = q
    return np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
                     [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
                     [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)]])


@dataclasses.dataclass
class VehicleState:
    position_m: np.ndarray
    velocity_m_s: np.ndarray
    quaternion: np.ndarray
    rates_rad_s: np.ndarray
    rotor_speed_rad_s: np.ndarray


class Vehicle:
    """The heterogeneous multirotor.

    Parameters
    ----------
    params : VehicleParams, optional
        Default: the shipped sim/data/vehicle.toml.
    rig : str
        ``roll``, ``pitch``, ``yaw`` (one axis free) or ``free`` (6 DoF).
    gravity_m_s2 : float
        Gravity (0 for the torque-free tests).
    substeps : int
        RK4 steps per :meth:`step`.
    """

    def __init__(self, params: VehicleParams | None = None, rig: str = "free",
                 gravity_m_s2: float = GRAVITY_M_S2, substeps: int = 2):
        if rig not in RIGS:
            raise ValueError(f"rig must be one of {', '.join(RIGS)}")
        self.p = params or load_params()
        self.rig = rig
        self.g = gravity_m_s2
        self.substeps = substeps
        self.inertia = np.diag(self.p.body.inertia_kg_m2)
        self.inertia_inv = np.diag(1.0 / np.array(self.p.body.inertia_kg_m2))
        self._geometry()
        self.free_axis = {"roll": 0, "pitch": 1, "yaw": 2}.get(rig)
        self.x = self.initial_state()

    # --- geometry ---------------------------------------------------------------------
    def _geometry(self):
        c, a = self.p.central_rotor, self.p.arm_rotors
        delta = math.radians(a.cant_deg)
        dirs, pos = [np.array([0.0, 0.0, -1.0])], [np.zeros(3)]
        for i in range(4):
            psi = math.radians(90.0 * i)
            tangent = np.array([-math.sin(psi), math.cos(psi), 0.0])
            dirs.append(-math.cos(delta) * np.array([0.0, 0.0, 1.0]) - c.spin * math.sin(delta) * tangent)
            pos.append(a.arm_length_m * np.array([math.cos(psi), math.sin(psi), 0.0]))
        self.thrust_dir = np.array(dirs)                              # (5, 3), body
        self.rotor_pos = np.array(pos)
        spins = np.array([c.spin] + list(a.spin), dtype=float)
        self.spin_axis = spins[:, None] * self.thrust_dir             # (5, 3)
        self.k_thrust = np.array([c.thrust_coeff] + [a.thrust_coeff] * 4)
        self.c_torque = np.array([c.torque_per_thrust_m] + [a.torque_per_thrust_m] * 4)
        self.j_rotor = np.array([c.rotor_inertia_kg_m2] + [a.rotor_inertia_kg_m2] * 4)
        self.tau = np.array([c.time_constant_s] + [a.time_constant_s] * 4)
        self.w_max = np.array([c.max_speed_rad_s] + [a.max_speed_rad_s] * 4)
        # moment arm of each thrust: r x d (per newton of thrust)
        self.thrust_moment = np.cross(self.rotor_pos, self.thrust_dir)

    # --- state ------------------------------------------------------------------------
    @staticmethod
    def initial_state():
        x = np.zeros(18)
        x[6] = 1.0                                                  # identity attitude
        return x

    def state(self) -> VehicleState:
        x = self.x
        return VehicleState(x[0:3].copy(), x[3:6].copy(), x[6:10].copy(), x[10:13].copy(),
                            x[13:18].copy())

    def set_rotor_speeds(self, speeds_rad_s) -> None:
        self.x[13:18] = speeds_rad_s

    def thrusts(self, rotor_speed=None):
        w = self.x[13:18] if rotor_speed is None else rotor_speed
        return self.k_thrust * w * w

    # --- dynamics -----------------------------------------------------------------------
    def derivative(self, x, u, force_ned=None, moment_body=None):
        """d/dt of the state for thrust fractions ``u`` and optional disturbances."""
        q = x[6:10]
        w = x[10:13]
        speed = x[13:18]
        w_cmd = self.w_max * np.sqrt(np.clip(u, 0.0, 1.0))
        speed_dot = (w_cmd - speed) / self.tau
        thrust = self.k_thrust * speed * speed
        h_rotor = (self.j_rotor * speed) @ self.spin_axis
        moment = (thrust @ self.thrust_moment
                  - (self.c_torque * thrust) @ self.spin_axis
                  - (self.j_rotor * speed_dot) @ self.spin_axis
                  - _cross(w, self.inertia @ w + h_rotor))
        if moment_body is not None:
            moment = moment + moment_body
        dx = np.zeros(18)
        dx[13:18] = speed_dot
        if self.free_axis is None:
            rot = rotation_matrix(q)
            force = rot @ (thrust @ self.thrust_dir) + np.array([0.0, 0.0, self.p.body.mass_kg * self.g])
            force -= self.p.body.drag_n_s_m * x[3:6]
            if force_ned is not None:
                force = force + force_ned
            dx[0:3] = x[3:6]
            dx[3:6] = force / self.p.body.mass_kg
            dx[10:13] = self.inertia_inv @ moment
        else:
            k = self.free_axis
            rig = self.p.rig
            hinge = -rig.hinge_damping_n_m_s_rad * w[k] - rig.hinge_friction_n_m * math.tanh(
                w[k] / FRICTION_SMOOTH_RAD_S)
            dx[10 + k] = (moment[k] + hinge) / self.inertia[k, k]
        dx[6:10] = 0.5 * _quat_mul(q, np.array([0.0, w[0], w[1], w[2]]))
        return dx

    def step(self, u, dt_s: float, force_ned=None, moment_body=None) -> VehicleState:
        """Advance by ``dt_s`` with the thrust fractions ``u`` held (zero-order hold)."""
        u = np.asarray(u, dtype=float)
        h = dt_s / self.substeps
        x = self.x
        for _ in range(self.substeps):
            k1 = self.derivative(x, u, force_ned, moment_body)
            k2 = self.derivative(x + 0.5 * h * k1, u, force_ned, moment_body)
            k3 = self.derivative(x + 0.5 * h * k2, u, force_ned, moment_body)
            k4 = self.derivative(x + h * k3, u, force_ned, moment_body)
            x = x + (h / 6.0) * (k1 + 2 * k2 + 2 * k3 + k4)
            x[6:10] /= np.linalg.norm(x[6:10])
        self.x = x
        return self.state()

    # --- diagnostics for tests -------------------------------------------------------------
    def angular_momentum_ned(self, x=None):
        """Total angular momentum (body and rotors) in NED, kg m^2/s."""
        x = self.x if x is None else x
        h_body = self.inertia @ x[10:13] + (self.j_rotor * x[13:18]) @ self.spin_axis
        return rotation_matrix(x[6:10]) @ h_body

    def rotational_energy(self, x=None):
        """Kinetic energy of the body's rotation (rotor spin energy excluded), J."""
        x = self.x if x is None else x
        w = x[10:13]
        return 0.5 * w @ self.inertia @ w
