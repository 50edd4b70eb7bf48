"""The 6-DoF vehicle as a plant for the firmware in the loop, and its linearised truth.

:class:`VehiclePlant` wraps :class:`heliquad.sim.plant.vehicle.Vehicle` with the interface the
lockstep runner uses (``fifo``, ``step_motors``, ``frame_inputs``). Its
:meth:`VehiclePlant.truth` states what identification should find for mixer injection: the
model linearised at the rig's trim (rotor speeds at the trim command, body at rest), from the
axis's normalised torque command, through the allocation the firmware flies (its own code),
to the body rate; sampled with the zero-order hold of the loop period as the logged data are.
"""

from __future__ import annotations

import math

import numpy as np

from heliquad import _firmware as fw
from heliquad import _simcore

from ..base.dialect import AXES
from .dryden import Dryden
from .imu_model import ImuModel
from .pid_model import pid_z
from .vehicle import BODY_STATES, Vehicle, check_step
from .rotor_geometry import firmware_geometry, geometry_params
from .vehicle_params import VehicleParams, load_params

__all__ = ["VehiclePlant", "mixer_layout", "flown_allocation", "check_loop_vehicle"]

#: Finite-difference steps for the linearisation (state and normalised command).
EPS_STATE = 1e-6
EPS_COMMAND = 1e-3


def mixer_layout(arm_length_m: float, cant_deg: float, central_spin: int):
    """(positions, thrust axes), 5 x 3 each in body FRD, of the vehicle the firmware's mixer is
    written for (firmware/core/mixer.hpp): the central rotor at the origin along -z, then the
    front, right, back and left arm rotors at ``arm_length_m``, each tilted by ``cant_deg``
    about its arm so that the lateral thrust's yaw moment opposes the central rotor's reaction
    torque: ``d_i = -cos(cant) z - central_spin sin(cant) t_i``, ``t_i`` the tangent at the
    arm's azimuth."""
    cant = math.radians(cant_deg)
    positions, axes = [np.zeros(3)], [np.array([0.0, 0.0, -1.0])]
    for i in range(4):
        psi = math.radians(90.0 * i)
        tangent = np.array([-math.sin(psi), math.cos(psi), 0.0])
        positions.append(arm_length_m * np.array([math.cos(psi), math.sin(psi), 0.0]))
        axes.append(-math.cos(cant) * np.array([0.0, 0.0, 1.0])
                    - central_spin * math.sin(cant) * tangent)
    return np.array(positions), np.array(axes)


def flown_allocation(params: VehicleParams | None = None):
    """The allocation the firmware in the loop flies this vehicle with (the firmware's own
    code, through its bindings): the geometry parameters of ``params`` (a vehicle file given
    to the run, whose CA_* the session sets on the board: host/acquire/session.py), or with
    None the firmware's default parameters (what flies when no file is given: the shipped
    vehicle, as the mixer flew it). InputError for a vehicle the firmware cannot fly (a
    rotor count outside its range, a figure beyond a parameter's, a geometry its allocation
    refuses), naming the file."""
    if params is None:
        return fw.Allocation(fw.params_geometry())
    values = {g.name: g.value for g in geometry_params(params)}
    return fw.Allocation(firmware_geometry(values))


def check_loop_vehicle(params: VehicleParams, dt_s: float) -> None:
    """InputError unless the firmware in the loop can fly this vehicle at this loop period: the
    integrator follows it (:func:`check_step`) and the firmware's allocation takes its
    geometry (:func:`flown_allocation`)."""
    check_step(params, dt_s)
    flown_allocation(params)


class VehiclePlant:
    """The vehicle on a rig (or free), stepped by the motors' thrust fractions: one per rotor
    of the vehicle file, whatever their number (2 to MAX_ROTORS). Its truth goes through the
    allocation the firmware flies (``flown``: :func:`flown_allocation`, by default the
    firmware's default geometry)."""

    def __init__(self, axis: str, rig: str, dt_s: float, params: VehicleParams | None = None,
                 trim_collective: float = 0.4, turbulence: str | None = None, seed: int = 0,
                 ideal_sensor: bool = False, flown=None):
        if axis not in AXES:
            raise ValueError(f"axis must be one of {', '.join(AXES)}")
        self.params = params or load_params()
        self.axis, self.index = axis, AXES[axis]
        self.rig, self.dt_s = rig, dt_s
        self.vehicle = Vehicle(self.params, rig=rig)
        self.trim_collective = trim_collective
        self.allocation = flown or flown_allocation()
        self.imu = None if ideal_sensor else ImuModel(self.params.imu, seed)
        self.dryden = None
        if turbulence:
            t = self.params.turbulence
            self.dryden = Dryden(turbulence, t.altitude_m, t.span_m, dt_s, seed)
        # The per-frame work (gusts as forces and moments, the step, the IMU's bias and delay
        # line, the specific force) runs in C++ (sim/plant/vehicle_model.cpp); this class
        # draws the random inputs and states the truth.
        imu = self.imu.config() if self.imu else _simcore.ImuConfig()
        self.core = _simcore.VehicleRig(self.vehicle.core, dt_s, imu,
                                        self.params.turbulence.rotational_damping_n_m_s_rad)

    @property
    def rate_rad_s(self) -> float:
        return float(self.vehicle.x[10 + self.index])

    def frame_inputs(self, frames: int):
        """The random inputs of the next ``frames`` frames: (IMU noise, gusts), each
        ``frames`` x 6 or None. Gust velocity acts through the airframe's linear drag, gust
        rates through the rotational damping (sim/plant/dryden.py)."""
        noise = self.imu.noise(frames) if self.imu else None
        gust = self.dryden.block(frames) if self.dryden else None
        return noise, gust

    def step_motors(self, motor) -> float:
        """Hold the motors' thrust fractions for one period (this frame's gust applied)."""
        gust = self.dryden.block(1) if self.dryden else None
        self.core.step_motors(list(map(float, motor)), gust)
        return self.rate_rad_s

    def body_state(self):
        x = self.vehicle.x
        return list(x[6:10]), list(x[10:13])

    def sensor_sample(self):
        """(quaternion, gyro rad/s, accel m/s^2) as the MPU6050 reports them this frame."""
        return self.core.sensor(self._noise())

    def fifo(self, kind: int) -> bytes:
        """This frame's FIFO bytes of the HQ_SENSOR_KIND ``kind``."""
        return self.core.fifo(kind, self._noise())

    def _noise(self):
        """One frame's IMU noise (None for the ideal sensor)."""
        return self.imu.noise(1) if self.imu else None

    @property
    def latency_samples(self) -> int:
        return 0 if self.imu is None else self.params.imu.dmp_latency_samples

    def specific_force(self):
        """What an accelerometer at the centre of mass reads, m/s^2 in body FRD."""
        return np.array(self.core.specific_force())

    # --- truth -------------------------------------------------------------------------------
    def linearise(self):
        """(A, b, C): the model at trim, from the axis's torque command to [rate, angle].

        States: the free axis's angle and rate and the rotor speeds (on a rig the other
        states do not move; in free flight this is the rotational part at hover with the other
        axes held, which is what a one-axis experiment sees to first order). Input: the axis's
        normalised torque command, through the allocation the firmware flies.
        """
        rotors = self.allocation.count

        def motors(cmd):
            c = [0.0, 0.0, 0.0]
            c[self.index] = cmd
            command = fw.MixerCommand(self.trim_collective, *c)
            return np.array(self.allocation.allocate(command).motor[:rotors])

        u0 = motors(0.0)
        v = Vehicle(self.params, rig=self.rig if self.rig != "free" else self.axis)
        x0 = v.initial_state()
        x0[BODY_STATES:] = v.w_max * np.sqrt(u0)
        idx = [10 + self.index] + list(range(BODY_STATES, BODY_STATES + v.rotors))
        n = len(idx)                           # [rate, rotors..., angle]
        f0 = v.derivative(x0, u0)[idx]
        A = np.zeros((n + 1, n + 1))
        for j, k in enumerate(idx):
            x1 = x0.copy()
            x1[k] += EPS_STATE * max(1.0, abs(x0[k]))
            A[:n, j] = (v.derivative(x1, u0)[idx] - f0) / (x1[k] - x0[k])
        A[n, 0] = 1.0                          # d(angle)/dt = rate, small angles at trim
        du = (motors(EPS_COMMAND) - motors(-EPS_COMMAND)) / (2 * EPS_COMMAND)
        b = np.zeros(n + 1)
        b[:n] = (v.derivative(x0, u0 + EPS_COMMAND * du)[idx]
                 - v.derivative(x0, u0 - EPS_COMMAND * du)[idx]) / (2 * EPS_COMMAND)
        C = np.zeros((2, n + 1))
        C[0, 0] = 1.0
        C[1, n] = 1.0
        return A, b, C

    def sampled(self, omega_rad_s):
        """Logged torque command -> logged rate and logged angle at ``omega_rad_s``:
        ``(h_rate, h_angle)``, arrays (ZOH-sampled at the loop period, with the latency)."""
        h_rate, h_angle = self._sampled(np.exp(1j * np.atleast_1d(omega_rad_s) * self.dt_s))
        return h_rate, h_angle

    def _sampled(self, z):
        """Logged torque command -> logged [rate, angle] at the points ``z`` (ZOH, latency)."""
        # scipy.linalg (0.2 s) here: importing the plant (identify's loops, every sil run do)
        # need not wait
        import scipy.linalg

        A, b, C = self.linearise()
        n = A.shape[0]
        M = np.zeros((n + 1, n + 1))
        M[:n, :n], M[:n, n] = A * self.dt_s, b * self.dt_s
        E = scipy.linalg.expm(M)
        Ad, bd = E[:n, :n], E[:n, n]
        return np.array([C @ np.linalg.solve(zk * np.eye(n) - Ad, bd) * zk ** -self.latency_samples
                         for zk in z]).T

    def truth(self, omega_rad_s, inject: str = "mixer", gains=None):
        """What identification should find for this injection point, at ``omega_rad_s``.

        mixer: torque command -> rate, the plant. rate: rate setpoint -> rate, the inner loop
        closed through the firmware's discrete PID. angle: angle setpoint -> angle, the whole
        cascade (the logged angle is the attitude estimate: exact for the DMP path, where it
        is the true attitude ``latency`` loops late; not for the raw path's filter).
        All ZOH-sampled at the loop period, with the sensor's latency.
        """
        z = np.exp(1j * np.atleast_1d(omega_rad_s) * self.dt_s)
        h_rate, h_angle = self._sampled(z)
        if inject == "mixer":
            out = h_rate
        else:
            g = gains or fw.CascadeGains.paper_defaults()
            axis = fw.Axis(self.index)
            c_pi, d_m = pid_z(g.rate(axis), self.dt_s, z)
            inner_den = 1 + h_rate * (c_pi - d_m)
            if inject == "rate":
                out = h_rate * c_pi / inner_den
            elif inject == "angle":
                k_o, d_o = pid_z(g.angle(axis), self.dt_s, z)
                out = h_angle * c_pi * k_o / (inner_den + c_pi * (k_o - d_o) * h_angle)
            else:
                raise ValueError("inject must be mixer, rate or angle")
        return out if np.ndim(omega_rad_s) else out[0]

