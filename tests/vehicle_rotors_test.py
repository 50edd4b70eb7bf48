"""The vehicle file's per-rotor description (sim/plant/vehicle_params.py, sim/plant/vehicle.py).

The shipped file flies as it did when it described one central rotor and four like arm rotors
(tests/data/vehicle_reference.json, recorded from that description: tests/vehicle_reference.py);
the test vehicles of six and eight rotors (tests/data/) get their forces and moments from their
geometry and hover open loop at a trim computed from it; the in-the-loop plant flies them,
one motor per rotor, and the firmware in the loop refuses a vehicle whose rotor count it does
not fly.
"""

import dataclasses
import json
import math
import pathlib

import numpy as np
import pytest

from heliquad import _simcore
from heliquad.sim.base.errors import InputError
from heliquad.sim.plant.vehicle import BODY_STATES, GRAVITY_M_S2, Vehicle
from heliquad.sim.plant.vehicle_params import load_params
from heliquad.sim.plant.vehicle_plant import (VehiclePlant, check_loop_vehicle, flown_allocation,
                                               mixer_layout)
from heliquad.sim.rig.driver import Rig

from vehicle_reference import flights

DATA = pathlib.Path(__file__).resolve().parent / "data"
SIX, EIGHT = str(DATA / "six_rotors.toml"), str(DATA / "eight_rotors.toml")
#: How close the rotor tables fly to the recorded reference, relative to each recorded
#: quantity's largest size: float precision (measured: at most 4.3e-14; the yaw rig's and
#: truth's records are identical). The mixer's formulas put the right, back and left arms
#: 1e-17 m to 6e-17 m off their axes (cos 90 deg in floating point), where the file has 0.
REFERENCE_RTOL = 1e-12
#: The truth records go through the allocation the firmware flies (its default geometry
#: parameters), which rounds in float otherwise than the mixer the reference was recorded
#: with (thrust fractions within 6e-7, tests/allocation_test.py): measured at most 9.6e-9.
TRUTH_RTOL = 1e-7
#: The in-the-loop plant's samples go through the turbulence filter and the IMU model, whose
#: numpy functions (vectorised sin, cos, exp) differ in their last bits between numpy
#: releases and with the CPU's vector width, and 400 steps of feedback through the vehicle
#: carry that along: measured 2.4e-12 with numpy 2.4.6 (OpenBLAS 0.3.31) against the
#: recording. Still float precision, three orders under anything a sweep could see.
PLANT_RTOL = 1e-9


def test_the_shipped_file_flies_as_the_recorded_reference():
    want = json.loads((DATA / "vehicle_reference.json").read_text())
    got = flights()
    assert set(got) == set(want)
    for name, rows in want.items():
        rows = np.array(rows)
        scale = np.abs(rows).max(axis=0)                         # each quantity's size
        off = np.abs(np.array(got[name]) - rows)
        rtol = TRUTH_RTOL if name.startswith("truth") else \
            PLANT_RTOL if name == "plant_samples" else REFERENCE_RTOL
        assert np.all(off <= rtol * scale), (name, float(np.max(off / np.maximum(scale, 1e-300))))


def test_the_shipped_rotors_are_the_papers_layout():
    # The old description's formulas (the firmware mixer's layout: 0.3048 m arms, 20 deg cant
    # against the central rotor's reaction torque) give the file's positions and axes.
    params = load_params()
    positions, axes = mixer_layout(0.3048, 20.0, params.rotors[0].spin)
    np.testing.assert_allclose([r.position_m for r in params.rotors], positions, rtol=0, atol=1e-16)
    np.testing.assert_allclose([r.thrust_axis for r in params.rotors], axes, rtol=0, atol=1e-16)
    assert [r.spin for r in params.rotors] == [1, 1, -1, 1, -1]


def wrench_by_hand(params, u):
    """Force and moment on the body (body FRD, N and N m) of rotors settled at thrust fractions
    ``u``, summed rotor by rotor from the file's geometry: thrust T = u T_max along the axis d
    at r, moment r x T d, drag torque -spin Q/T T d."""
    force, moment = np.zeros(3), np.zeros(3)
    for rotor, fraction in zip(params.rotors, u):
        d, r = np.array(rotor.thrust_axis), np.array(rotor.position_m)
        thrust = fraction * rotor.max_thrust_n
        force += thrust * d
        moment += np.array([r[1] * d[2] - r[2] * d[1], r[2] * d[0] - r[0] * d[2],
                            r[0] * d[1] - r[1] * d[0]]) * thrust
        moment -= rotor.spin * rotor.torque_per_thrust_m * thrust * d
    return force, moment


def model_wrench(vehicle, params, u):
    """The model's force and moment at rest, level, rotors settled at ``u`` (gravity off)."""
    vehicle.x = vehicle.initial_state()
    vehicle.set_rotor_speeds(vehicle.w_max * np.sqrt(u))
    dx = vehicle.derivative(vehicle.x, u)
    assert np.all(dx[BODY_STATES:] == 0.0)                     # settled: no spin-up reaction
    return params.body.mass_kg * dx[3:6], np.array(params.body.inertia_kg_m2) * dx[10:13]


@pytest.mark.parametrize("path", [SIX, EIGHT, None])
def test_the_models_force_and_moment_are_the_geometrys(path):
    params = load_params(path)
    vehicle = Vehicle(params, rig="free", gravity_m_s2=0.0)
    n = len(params.rotors)
    assert vehicle.x.shape == (BODY_STATES + n,)
    rng = np.random.default_rng(n)
    for _ in range(5):
        u = rng.uniform(0.05, 0.95, n)
        force, moment = model_wrench(vehicle, params, u)
        want_force, want_moment = wrench_by_hand(params, u)
        np.testing.assert_allclose(force, want_force, rtol=1e-12, atol=1e-12)
        np.testing.assert_allclose(moment, want_moment, rtol=1e-12, atol=1e-12)
    # one rotor alone, by closed form: rotor 2 of the test vehicles at full thrust
    u = np.zeros(n)
    u[1] = 1.0
    force, moment = model_wrench(vehicle, params, u)
    rotor = params.rotors[1]
    assert force == pytest.approx(rotor.max_thrust_n * np.array(rotor.thrust_axis), abs=1e-12)
    assert np.linalg.norm(force) == pytest.approx(rotor.max_thrust_n, rel=1e-12)


def hover_trim(params):
    """The thrust fractions that hold the vehicle still: the least-norm solution of "the rotors'
    wrench is the weight's opposite", from the rotors' unit wrenches (wrench_by_hand)."""
    n = len(params.rotors)
    columns = [np.concatenate(wrench_by_hand(params, np.eye(n)[i])) for i in range(n)]
    weight = np.array([0.0, 0.0, -params.body.mass_kg * GRAVITY_M_S2, 0.0, 0.0, 0.0])
    # rcond: the symmetric rings' lateral force and tilt are nearly one direction; drop it
    u = np.linalg.pinv(np.array(columns).T, rcond=1e-3) @ weight
    assert np.abs(np.array(columns).T @ u - weight).max() < 1e-9
    return u


@pytest.mark.parametrize("path, rotors", [(SIX, 6), (EIGHT, 8)])
def test_six_and_eight_rotors_hover_open_loop_at_the_computed_trim(path, rotors):
    params = load_params(path)
    assert len(params.rotors) == rotors
    u = hover_trim(params)
    assert np.all((u > 0.01) & (u < 0.9)), u
    vehicle = Vehicle(params, rig="free")
    vehicle.set_rotor_speeds(vehicle.w_max * np.sqrt(u))
    for _ in range(400):                                         # 2 s at 5 ms
        vehicle.step(u, 0.005)
    s = vehicle.state()
    # (falling, it would be 20 m down; the file's 9-digit geometry leaves ~1e-8 m)
    assert np.abs(s.position_m).max() < 1e-6 and np.abs(s.velocity_m_s).max() < 1e-6
    assert np.abs(s.rates_rad_s).max() < 1e-6 and np.abs(s.quaternion[1:]).max() < 1e-6
    # and 10 % more on every rotor climbs at 0.1 g
    vehicle.x = vehicle.initial_state()
    vehicle.set_rotor_speeds(vehicle.w_max * np.sqrt(1.1 * u))
    assert vehicle.derivative(vehicle.x, 1.1 * u)[5] == pytest.approx(-0.1 * GRAVITY_M_S2, rel=1e-6)


def test_a_rotor_spins_its_own_way():
    # Spin +1 turns counter-clockwise seen from above for an upward rotor: its drag torque
    # turns the body nose right (+z), and its momentum points up (-z) for the gyroscopic terms.
    params = load_params(EIGHT)
    vehicle = Vehicle(params, rig="free", gravity_m_s2=0.0)
    u = np.zeros(8)
    u[0] = 0.5
    _, moment = model_wrench(vehicle, params, u)
    assert moment[2] == pytest.approx(0.5 * 25.0 * 0.017, rel=1e-12) and params.rotors[0].spin == 1
    u = np.zeros(8)
    u[5] = 0.5                                                   # a small rotor, spin -1
    _, moment = model_wrench(vehicle, params, u)
    assert moment[2] == pytest.approx(-0.5 * 6.0 * 0.006, rel=1e-12)
    assert vehicle.angular_momentum_ned()[2] == pytest.approx(
        -(-1) * 8.0e-6 * vehicle.w_max[5] * math.sqrt(0.5), rel=1e-12)


@pytest.mark.parametrize("path, rotors", [(SIX, 6), (EIGHT, 8)])
def test_the_loop_flies_six_and_eight_rotors_with_the_allocation_of_their_geometry(path, rotors):
    params = load_params(path)
    check_loop_vehicle(params, 0.005)
    assert flown_allocation(params).count == rotors


def _hold(plant, u, frames):
    """Hold the thrust fractions ``u`` for ``frames`` frames: the plant's rates and specific
    force then."""
    for _ in range(frames):
        plant.step_motors(u)
    _, gyro, accel = plant.sensor_sample()
    return np.concatenate([gyro, accel])


@pytest.mark.parametrize("path, rotors", [(SIX, 6), (EIGHT, 8)])
def test_a_plant_of_six_or_eight_rotors_responds_to_each_motor(path, rotors):
    # The in-the-loop plant takes the vehicle file's rotor count: one command per rotor, and
    # each rotor's command moves the body (its thrust's force and moment) by itself.
    params = load_params(path)
    plant = VehiclePlant("roll", "free", 0.005, params, ideal_sensor=True)
    assert plant.core.rotors == rotors
    trim = [0.3] * rotors
    rest = _hold(VehiclePlant("roll", "free", 0.005, params, ideal_sensor=True), trim, 20)
    moved = []
    for r in range(rotors):
        u = list(trim)
        u[r] += 0.2
        got = _hold(VehiclePlant("roll", "free", 0.005, params, ideal_sensor=True), u, 20)
        assert np.max(np.abs(got - rest)) > 1e-3, f"rotor {r} moved nothing"
        moved.append(got)
    # Not one response repeated: each motor drives its own rotor.
    assert len({tuple(np.round(m, 9)) for m in moved}) == rotors
    with pytest.raises(ValueError, match=f"{rotors} motor commands expected"):
        plant.step_motors([0.3] * 5)


def test_the_lockstep_engine_says_when_the_firmware_flies_another_rotor_count():
    # Past the session (a plant made directly, no geometry set on the board): the host
    # firmware flies its five rotors, the plant has six. Disarmed nothing spins, so that is
    # allowed (a session sets the geometry then); the first armed reply stops the run.
    params = load_params(SIX)
    disarmed = np.array([[1500, 1500, 1000, 1500, 1000, 1000, 0, 0]] * 20, dtype=np.uint16)
    arming = disarmed.copy()
    arming[:, 4] = 2000
    with Rig(lambda dt_s: VehiclePlant("roll", "roll", dt_s, params)) as rig:
        rig.advance(20, disarmed)
        with pytest.raises(InputError, match=f"the firmware flies {_simcore.FIRMWARE_MOTORS} "
                                             "rotors but the vehicle has 6"):
            rig.advance(20, arming)


def test_a_vehicle_the_allocation_cannot_fly_is_refused_in_the_loop():
    """Arms straight up and no reaction torque on the central rotor: nothing makes yaw. The
    model flies it; the firmware in the loop would not (its allocation refuses it)."""
    params = load_params()
    up = [dataclasses.replace(r, thrust_axis=(0.0, 0.0, -1.0)) for r in params.rotors[1:]]
    central = dataclasses.replace(params.rotors[0], torque_per_thrust_m=0.0)
    arms = [dataclasses.replace(r, torque_per_thrust_m=0.0) for r in up]
    flat = dataclasses.replace(params, rotors=(central, *arms))
    with pytest.raises(InputError, match=r"cannot fly this geometry \(allocation: no yaw moment\)"):
        check_loop_vehicle(flat, 0.005)
    Vehicle(flat).step([0.3] * 5, 0.005)                           # the model flies it
    check_loop_vehicle(params, 0.005)                             # the shipped one flies in the loop


@pytest.mark.parametrize("rotors", [0, _simcore.MAX_ROTORS + 1])
def test_the_core_model_refuses_a_rotor_count_beyond_its_room(rotors):
    c = _simcore.VehicleConfig()
    c.inertia_kg_m2, c.tau_s, c.rotors = [0.01] * 3, [0.03] * _simcore.MAX_ROTORS, rotors
    with pytest.raises(ValueError, match="rotors 1..8"):
        _simcore.VehicleModel(c)


def test_the_core_model_takes_one_command_and_one_speed_per_rotor():
    vehicle = Vehicle(load_params(EIGHT))
    with pytest.raises(ValueError, match="8 rotor commands expected"):
        vehicle.step([0.3] * 5, 0.005)
    with pytest.raises(ValueError, match="the state has 21 values"):
        vehicle.x = np.zeros(18)
