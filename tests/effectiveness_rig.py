"""Per-rotor injections on a one-axis rig, without the firmware: the data the per-rotor runs
will give.

The simulator's vehicle on its rig (the C++ equations through heliquad._simcore) flown by the
firmware's cascade as pid_model.py writes it in z (angle PI and derivative on the
measurement, then the rate loop's), through the firmware's allocation (its bindings, with the
geometry the firmware believes: the default), plus a multisine added to every rotor's thrust
command after the allocation, each rotor on lines of its own (interleaved harmonics of one
base period). The gyro reads the rate one sample late with white noise; the angle is the true
one, one sample late. Logged per sample: each rotor's injection, the measured rate and the
axis's torque command.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from heliquad import _firmware as fw
from heliquad.sim.base.dialect import AXES
from heliquad.sim.base.firmware_facts import LOOP_PERIOD_S
from heliquad.sim.plant.pid_model import pid_z_coeffs
from heliquad.sim.plant.vehicle import BODY_STATES, Vehicle
from heliquad.sim.plant.vehicle_params import VehicleParams
from heliquad.sim.plant.vehicle_plant import mixer_layout

__all__ = ["RigRecord", "fly_rig", "interleaved_lines", "truth", "allocation_column", "other_vehicle"]

#: The collective the rigs fly at (VehiclePlant's trim).
TRIM_COLLECTIVE = 0.4
#: Samples by which the gyro and the angle lag (the vehicle file's DMP latency).
LATENCY_SAMPLES = 1


@dataclasses.dataclass(frozen=True)
class RigRecord:
    axis: str
    excitation: np.ndarray        # samples x rotors: each rotor's injection
    rate: np.ndarray              # the measured rate, rad/s
    command: np.ndarray           # the axis's normalised torque command
    period: int
    orders: tuple                 # per rotor, its lines (harmonics of the base period)


class _Filter:
    """One discrete transfer function ``num/den`` (descending powers of z, den[0] = 1),
    stepped sample by sample (transposed direct form II)."""

    def __init__(self, num, den):
        n = max(len(num), len(den))
        self.b = np.concatenate([np.zeros(n - len(num)), num]) / den[0]
        self.a = np.concatenate([den, np.zeros(n - len(den))]) / den[0]
        self.state = np.zeros(n - 1)

    def __call__(self, x: float) -> float:
        y = self.b[0] * x + (self.state[0] if self.state.size else 0.0)
        for i in range(self.state.size):
            nxt = self.state[i + 1] if i + 1 < self.state.size else 0.0
            self.state[i] = self.b[i + 1] * x - self.a[i + 1] * y + nxt
        return y


def _pid(gains):
    """(C_PI, D_m) of the firmware's PID with these gains, as filters."""
    c_pi, d_m = pid_z_coeffs(gains.kc, gains.tau_i_s, gains.tau_d_s, gains.derivative_filter_n,
                             LOOP_PERIOD_S)
    return _Filter(*c_pi), _Filter(*d_m)


def interleaved_lines(rotors: int, per_rotor: int, highest: int = 7) -> tuple:
    """Each rotor's harmonics, odd ones only: rotor ``i`` takes ``2 (i + rotors m) + 1`` for
    up to ``per_rotor`` values of ``m`` from 0 to ``highest``, spaced on a log scale. The
    rotors' thrust is quadratic in their speed: a sum or difference of two odd lines is even
    and lands on no rotor's line."""
    steps = np.unique(np.round(np.geomspace(1, highest + 1, per_rotor)).astype(int) - 1)
    return tuple(tuple(int(2 * (i + rotors * m) + 1) for m in steps) for i in range(rotors))


def _multisine(period: int, orders, amplitude: float, rng) -> np.ndarray:
    """One period of a multisine on ``orders``, random phases, peak about ``amplitude``."""
    k = np.arange(period)
    x = sum(np.cos(2 * np.pi * l * k / period + rng.uniform(0, 2 * np.pi)) for l in orders)
    return amplitude * x / np.max(np.abs(x))


def allocation_column(axis: str) -> np.ndarray:
    """Each rotor's thrust command per unit of the axis's torque command (the firmware's
    default allocation at the trim collective, by central differences)."""
    alloc, step = fw.Allocation(), 1e-3

    def motors(c):
        cmd = [TRIM_COLLECTIVE, 0.0, 0.0, 0.0]
        cmd[1 + AXES[axis]] = c
        return np.array(alloc.allocate(fw.MixerCommand(*cmd)).motor[:5])

    return (motors(step) - motors(-step)) / (2 * step)


def fly_rig(params: VehicleParams, axis: str, period: int, periods: int, amplitude: float,
            gyro_noise_rad_s: float, seed: int) -> RigRecord:
    """The vehicle on the ``axis`` rig, every rotor injected on its own lines."""
    rng = np.random.default_rng(seed)
    vehicle = Vehicle(params, rig=axis)
    n, index = vehicle.rotors, AXES[axis]
    orders = interleaved_lines(n, 7)
    one = np.column_stack([_multisine(period, o, amplitude, rng) for o in orders])
    excitation = np.tile(one, (periods, 1))
    alloc = allocation_column(axis)
    u0 = np.array(fw.Allocation().allocate(fw.MixerCommand(TRIM_COLLECTIVE, 0, 0, 0)).motor[:n])
    x = vehicle.initial_state()
    x[BODY_STATES:] = vehicle.w_max * np.sqrt(u0)
    vehicle.x = x
    gains = fw.CascadeGains.paper_defaults()
    rate_pi, rate_dm = _pid(gains.rate(fw.Axis(index)))
    # yaw flies its rate loop alone (the cascade has no yaw angle loop): setpoint 0
    angle_pi, angle_dm = _pid(gains.angle(fw.Axis(index))) if axis != "yaw" else (None, None)
    frames = excitation.shape[0]
    rate, command = np.zeros(frames), np.zeros(frames)
    noise = rng.normal(0.0, gyro_noise_rad_s, frames)
    past = [(0.0, 0.0)] * LATENCY_SAMPLES
    core = vehicle.core
    for k in range(frames):
        q = vehicle.x
        past.append((float(q[10 + index]), 2 * math.atan2(float(q[7 + index]), float(q[6]))))
        p_true, angle = past.pop(0)
        p = p_true + noise[k]
        setpoint = angle_pi(-angle) + angle_dm(angle) if angle_pi else 0.0
        c = rate_pi(setpoint - p) + rate_dm(p)
        motor = u0 + alloc * c + excitation[k]
        core.step(motor.tolist(), LOOP_PERIOD_S, None, None)
        rate[k], command[k] = p, c
    return RigRecord(axis, excitation, rate, command, period, orders)


def truth(vehicle: Vehicle) -> np.ndarray:
    """The effectiveness the rigs should find, 3 x rotors, rad/s^2 per unit of thrust command:
    each rotor's moment at steady state (its thrust's arm and its drag torque, thrust = max
    thrust x command) over the rig's inertia."""
    max_thrust = vehicle.k_thrust * vehicle.w_max ** 2
    moment = max_thrust[:, None] * (vehicle.thrust_moment
                                    - vehicle.c_torque[:, None] * vehicle.spin_axis)
    return moment.T / np.array(vehicle.p.body.inertia_kg_m2)[:, None]


def other_vehicle(params: VehicleParams) -> VehicleParams:
    """A vehicle unlike the default: arms of 0.25 m canted 14 deg, the right arm rotor 20 %
    weaker, the central rotor's torque ratio 30 % higher, other time constants."""
    positions, axes = mixer_layout(0.25, 14.0, params.rotors[0].spin)
    time_constants = (0.12, 0.025, 0.035, 0.03, 0.04)
    rotors = []
    for i, rotor in enumerate(params.rotors):
        rotors.append(dataclasses.replace(
            rotor, position_m=tuple(positions[i]), thrust_axis=tuple(axes[i]),
            time_constant_s=time_constants[i],
            max_thrust_n=rotor.max_thrust_n * (0.8 if i == 2 else 1.0),
            torque_per_thrust_m=rotor.torque_per_thrust_m * (1.3 if i == 0 else 1.0)))
    return dataclasses.replace(params, rotors=tuple(rotors), source="the other vehicle")
