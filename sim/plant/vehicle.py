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
* Rigs (docs/paper.md: the vehicle held on its thrust line with one axis free): position fixed,
  body rates other than the free axis held at zero by the rig, plus hinge damping and
  Coulomb friction on the free axis, smoothed as F tanh(w / 0.01 rad/s) so the ODE stays
  smooth.

Integration: classical Runge-Kutta 4 with ``substeps`` steps per call.

The equations themselves run in C++ (sim/plant/vehicle_model.cpp, ``heliquad._simcore``):
the lockstep engine steps them every frame, and this class calls the same code, so there is
one implementation. This module owns the parameters and the geometry derived from them.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from heliquad import _simcore

from ..base.dialect import AXES
from ..base.errors import InputError
from .vehicle_params import VehicleParams, load_params

__all__ = ["Vehicle", "RIGS", "GRAVITY_M_S2", "fastest_rate_rad_s", "check_step"]

GRAVITY_M_S2 = _simcore.GRAVITY_M_S2       # standard gravity, the simulator core's
#: One rig per axis (the dialect's HQ_AXIS names), or free flight.
RIGS = (*AXES, "free")
#: RK4 steps per loop period (the lockstep engine's).
SUBSTEPS = 2
#: RK4 is stable while an RK4 step times a mode's rate stays below about 2.8 (on the real
#: and the imaginary axis alike); a vehicle file must keep it below this.
RK4_LIMIT = 2.5
#: The hinge's Coulomb friction is smoothed over this rate (sim/plant/vehicle_model.cpp).
FRICTION_SMOOTH_RAD_S = 0.01


def fastest_rate_rad_s(p: VehicleParams) -> float:
    """The fastest mode of the equations, 1/s: the rotors' lags, the rate damping (hinge,
    gusts) and the smoothed hinge friction over the smallest inertia, the drag over the mass,
    and the rotors' momentum at full speed over the smallest inertia (gyroscopic precession)."""
    inertia = min(p.body.inertia_kg_m2)
    c, a = p.central_rotor, p.arm_rotors
    momentum = (c.rotor_inertia_kg_m2 * c.max_speed_rad_s
                + 4 * a.rotor_inertia_kg_m2 * a.max_speed_rad_s)
    damping = (p.rig.hinge_damping_n_m_s_rad + p.turbulence.rotational_damping_n_m_s_rad
               + p.rig.hinge_friction_n_m / FRICTION_SMOOTH_RAD_S)
    return max(1 / c.time_constant_s, 1 / a.time_constant_s, damping / inertia,
               p.body.drag_n_s_m / p.body.mass_kg, momentum / inertia)


def check_step(p: VehicleParams, dt_s: float) -> None:
    """InputError when the integrator cannot follow the vehicle at this loop period (it would
    diverge, whatever the firmware does)."""
    rate, h = fastest_rate_rad_s(p), dt_s / SUBSTEPS
    if rate * h > RK4_LIMIT:
        raise InputError(f"{p.source}: the vehicle's fastest mode ({rate:.3g} 1/s: rotor lag, "
                         f"damping, friction or rotor momentum against the inertia) is too fast "
                         f"for the simulator's {SUBSTEPS} steps per {1e3 * dt_s:g} ms loop "
                         f"(at most {RK4_LIMIT / h:.3g} 1/s)")


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
        Default: the shipped sim/plant/vehicle.toml.
    rig : str
        ``roll``, ``pitch``, ``yaw`` (one axis free) or ``free`` (6 DoF).
    gravity_m_s2 : float
        Gravity (0 for the torque-free tests).
    substeps : int
        RK4 steps per :meth:`step`.
    """

    def __init__(self, params: VehicleParams | None = None, rig: str = "free",
                 gravity_m_s2: float = GRAVITY_M_S2, substeps: int = SUBSTEPS):
        if rig not in RIGS:
            raise ValueError(f"rig must be one of {', '.join(RIGS)}")
        self.p = params or load_params()
        self.rig = rig
        self.g = gravity_m_s2
        self.substeps = substeps
        self.inertia = np.diag(self.p.body.inertia_kg_m2)
        self.inertia_inv = np.diag(1.0 / np.array(self.p.body.inertia_kg_m2))
        self._geometry()
        self.free_axis = AXES.get(rig)           # the free axis's body index; None when free
        self.core = _simcore.VehicleModel(self._config())

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

    def _config(self):
        """The equations' inputs for the C++ model, in SI units and body axes."""
        c = _simcore.VehicleConfig()
        body, rig = self.p.body, self.p.rig
        c.mass_kg, c.inertia_kg_m2, c.drag_n_s_m = body.mass_kg, list(body.inertia_kg_m2), body.drag_n_s_m
        c.gravity_m_s2, c.substeps = self.g, self.substeps
        c.hinge_damping_n_m_s_rad, c.hinge_friction_n_m = rig.hinge_damping_n_m_s_rad, rig.hinge_friction_n_m
        c.free_axis = -1 if self.free_axis is None else self.free_axis
        c.thrust_dir, c.thrust_moment = self.thrust_dir.tolist(), self.thrust_moment.tolist()
        c.spin_axis = self.spin_axis.tolist()
        c.k_thrust, c.c_torque, c.j_rotor = self.k_thrust.tolist(), self.c_torque.tolist(), self.j_rotor.tolist()
        c.tau_s, c.w_max_rad_s = self.tau.tolist(), self.w_max.tolist()
        return c

    # --- state ------------------------------------------------------------------------
    @property
    def x(self) -> np.ndarray:
        """The state (18 values, see the module's docstring); a view: writing into it sets it."""
        return self.core.x

    @x.setter
    def x(self, value) -> None:
        self.core.x = np.asarray(value, dtype=float)

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
        """d/dt of the state for thrust fractions ``u`` and optional disturbances (force NED
        in N, moment body in N m)."""
        return self.core.derivative(np.asarray(x, dtype=float), list(map(float, u)),
                                    force_ned, moment_body)

    def step(self, u, dt_s: float, force_ned=None, moment_body=None) -> VehicleState:
        """Advance by ``dt_s`` with the thrust fractions ``u`` held (zero-order hold)."""
        self.core.step(list(map(float, u)), dt_s, force_ned, moment_body)
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
