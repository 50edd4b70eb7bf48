"""6-DoF model of the heterogeneous multirotor, free or on a one-axis test rig.

State: position and velocity in NED (m, m/s), attitude quaternion (body FRD -> NED,
w x y z), body rates (rad/s), and the speeds of the vehicle file's rotors (rad/s; rotor 1, the
central rotor, first; 2 to 8 of them). Inputs: one thrust fraction per rotor (0..1); in the
loop, the five the firmware sends.

Physics (docs/vehicle-model.md has the derivation):

* Rotors: first-order speed lag ``dW/dt = (W_cmd - W) / tau``, ``W_cmd = W_max sqrt(u)`` (the
  ESC maps a thrust fraction to speed; thrust is ``k_T W^2``, so ``u`` is the fraction of
  maximum thrust at steady state). Aerodynamic drag torque on each prop ``Q = c_Q T``.
* Geometry, per rotor from the vehicle file: hub position ``r_r`` and thrust axis ``d_r``
  (unit, body). Each rotor's spin axis is ``a_r = spin_r d_r`` (+1: counter-clockwise seen
  from the side the thrust points to).
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

import numpy as np

from heliquad import _simcore

from ..base.dialect import AXES
from ..base.errors import InputError
from .vehicle_params import VehicleParams, load_params

__all__ = ["Vehicle", "RIGS", "GRAVITY_M_S2", "BODY_STATES", "fastest_rate_rad_s", "check_step"]

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
#: The state's values before the rotor speeds: position, velocity, quaternion, rates.
BODY_STATES = 13


def fastest_rate_rad_s(p: VehicleParams) -> float:
    """The fastest mode of the equations, 1/s: the rotors' lags, the rate damping (hinge,
    gusts) and the smoothed hinge friction over the smallest inertia, the drag over the mass,
    and the rotors' momentum at full speed over the smallest inertia (gyroscopic precession)."""
    inertia = min(p.body.inertia_kg_m2)
    momentum = sum(r.rotor_inertia_kg_m2 * r.max_speed_rad_s for r in p.rotors)
    damping = (p.rig.hinge_damping_n_m_s_rad + p.turbulence.rotational_damping_n_m_s_rad
               + p.rig.hinge_friction_n_m / FRICTION_SMOOTH_RAD_S)
    return max(*(1 / r.time_constant_s for r in p.rotors), damping / inertia,
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


def _padded(values) -> list:
    """Per-rotor values (a row per rotor) as the simulator core's config holds them: padded
    with zeros to its MAX_ROTORS rows (it uses the first ``rotors``)."""
    rows = np.asarray(values, dtype=float)
    pad = np.zeros((_simcore.MAX_ROTORS - len(rows), *rows.shape[1:]))
    return np.concatenate([rows, pad]).tolist()


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
        rotors = self.p.rotors
        self.rotors = len(rotors)
        self.thrust_dir = np.array([r.thrust_axis for r in rotors])          # (n, 3), body
        self.rotor_pos = np.array([r.position_m for r in rotors])
        spins = np.array([r.spin for r in rotors], dtype=float)
        self.spin_axis = spins[:, None] * self.thrust_dir                    # (n, 3)
        self.k_thrust = np.array([r.thrust_coeff for r in rotors])
        self.c_torque = np.array([r.torque_per_thrust_m for r in rotors])
        self.j_rotor = np.array([r.rotor_inertia_kg_m2 for r in rotors])
        self.tau = np.array([r.time_constant_s for r in rotors])
        self.w_max = np.array([r.max_speed_rad_s for r in rotors])
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
        c.rotors = self.rotors
        c.thrust_dir, c.thrust_moment = _padded(self.thrust_dir), _padded(self.thrust_moment)
        c.spin_axis = _padded(self.spin_axis)
        c.k_thrust, c.c_torque = _padded(self.k_thrust), _padded(self.c_torque)
        c.j_rotor = _padded(self.j_rotor)
        c.tau_s, c.w_max_rad_s = _padded(self.tau), _padded(self.w_max)
        return c

    # --- state ------------------------------------------------------------------------
    @property
    def x(self) -> np.ndarray:
        """The state (13 values and one per rotor, see the module's docstring); a view: writing
        into it sets it."""
        return self.core.x

    @x.setter
    def x(self, value) -> None:
        self.core.x = np.asarray(value, dtype=float)

    def initial_state(self):
        """At rest at the origin, level, rotors stopped (13 + one value per rotor)."""
        x = np.zeros(BODY_STATES + self.rotors)
        x[6] = 1.0                                                  # identity attitude
        return x

    def state(self) -> VehicleState:
        x = self.x
        return VehicleState(x[0:3].copy(), x[3:6].copy(), x[6:10].copy(), x[10:13].copy(),
                            x[BODY_STATES:].copy())

    def set_rotor_speeds(self, speeds_rad_s) -> None:
        self.x[BODY_STATES:] = speeds_rad_s

    def thrusts(self, rotor_speed=None):
        w = self.x[BODY_STATES:] if rotor_speed is None else rotor_speed
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
        h_body = self.inertia @ x[10:13] + (self.j_rotor * x[BODY_STATES:]) @ self.spin_axis
        return rotation_matrix(x[6:10]) @ h_body

    def rotational_energy(self, x=None):
        """Kinetic energy of the body's rotation (rotor spin energy excluded), J."""
        x = self.x if x is None else x
        w = x[10:13]
        return 0.5 * w @ self.inertia @ w
