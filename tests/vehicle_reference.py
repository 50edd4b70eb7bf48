"""The reference flights of the shipped vehicle: what tests/data/vehicle_reference.json holds.

:func:`flights` flies the shipped vehicle file free and on each rig under varying rotor
commands and disturbances, runs the in-the-loop plant in turbulence with its IMU, and takes
the linearised truth of each axis. tests/data/vehicle_reference.json is what it gave with the
vehicle built from an arm length and a cant (0.3048 m, 20 deg) by the firmware mixer's formulas
(``mixer_layout`` in sim/plant/vehicle_plant.py) rather than from rotor tables;
tests/vehicle_rotors_test.py checks that the shipped rotor tables give the same to float
precision.
"""

import math

from heliquad.sim.base.dialect import AXES
from heliquad.sim.plant.vehicle import RIGS, Vehicle
from heliquad.sim.plant.vehicle_plant import VehiclePlant

DT_S = 0.005
STEPS = 400                  # 2 s
EVERY = 20                   # record every 0.1 s
TRUTH_RAD_S = [1.0, 5.0, 20.0]


def commands(k: int):
    """The five thrust fractions of step ``k``: each rotor on its own sine."""
    t = k * DT_S
    return [0.45 + 0.05 * math.sin(2 * math.pi * 1.3 * t)] + [
        0.3 + 0.1 * math.sin(2 * math.pi * (1.0 + 0.7 * r) * t + r) for r in range(1, 5)]


def disturbances(k: int):
    """(force NED N, moment body N m) of step ``k``, each on some steps only."""
    t = k * DT_S
    force = [0.2 * math.sin(3 * t), -0.1, 0.3 * math.cos(2 * t)] if k % 3 == 0 else None
    moment = [0.01 * math.cos(5 * t), 0.005, -0.008 * math.sin(t)] if k % 5 == 0 else None
    return force, moment


def flights(params=None) -> dict:
    """The reference runs' records (lists of floats, as JSON keeps them)."""
    out = {}
    for rig in RIGS:
        v = Vehicle(params, rig=rig)
        states = []
        for k in range(STEPS):
            v.step(commands(k), DT_S, *disturbances(k))
            if k % EVERY == EVERY - 1:
                states.append([float(s) for s in v.x])
        out[rig] = states
    plant = VehiclePlant("roll", "free", DT_S, params, turbulence="moderate", seed=4)
    samples = []
    for k in range(STEPS):
        q, gyro, accel = plant.sensor_sample()
        plant.step_motors(commands(k))
        if k % EVERY == EVERY - 1:
            samples.append([float(s) for s in (*q, *gyro, *accel)])
    out["plant_samples"] = samples
    for axis in AXES:
        h = VehiclePlant(axis, axis, DT_S, params, ideal_sensor=True).truth(TRUTH_RAD_S)
        out[f"truth_{axis}"] = [[float(z.real), float(z.imag)] for z in h]
    return out
