"""The 6-DoF vehicle model (sim/plant/vehicle.py) and its parameter file (sim/plant/vehicle_params.py)."""

import dataclasses
import math

import numpy as np
import pytest

from heliquad import _firmware as fw
from heliquad.sim.base.errors import InputError
from heliquad.sim.plant.vehicle import GRAVITY_M_S2, Vehicle
from heliquad.sim.plant.vehicle_params import load_params

PARAMS = load_params()


from heliquad.sim.plant.rotor_geometry import firmware_geometry, geometry_params


def without_central_drag(params):
    """``params`` with the central rotor's drag torque off."""
    central = dataclasses.replace(params.rotors[0], torque_per_thrust_m=0.0)
    return dataclasses.replace(params, rotors=(central, *params.rotors[1:]))


def settled(vehicle, u):
    """Put the rotors at the speeds the commands settle to (no spin-up transient)."""
    vehicle.set_rotor_speeds(vehicle.w_max * np.sqrt(np.asarray(u)))


# --- parameter file -------------------------------------------------------------------------

def edited(tmp_path, old, new):
    text = open(_default_path()).read()
    assert old in text
    path = tmp_path / "v.toml"
    path.write_text(text.replace(old, new, 1))
    return str(path)


def _default_path():
    import importlib.resources
    return str(importlib.resources.files("heliquad.sim.plant").joinpath("vehicle.toml"))


def test_default_file_loads_with_the_papers_figures():
    assert PARAMS.body.mass_kg == 0.930
    front = PARAMS.rotors[1]
    assert front.position_m == (0.3048, 0.0, 0.0)
    assert math.degrees(math.acos(-front.thrust_axis[2])) == pytest.approx(20.0, abs=1e-12)


@pytest.mark.parametrize("old, new, match", [
    ("mass_kg = 0.930", "mass_kg = -0.930", "body.mass_kg must be positive"),
    ("mass_kg = 0.930", "mass_g = 930", "unknown key body.mass_g .*expected body.mass_kg"),
    ("time_constant_s = 0.15", "", "missing key rotors\\[1\\].time_constant_s"),
    ("spin = 1 ", "spin = 2 ", "rotors\\[1\\].spin must be 1 or -1"),
    ("inertia_kg_m2 = [0.0118, 0.0118, 0.0226]", "inertia_kg_m2 = [0.0118, 0.0118]",
     "body.inertia_kg_m2 must be a list of 3"),
    ("[rig]", "[rigg]", "missing section \\[rig\\]"),
    ("span_m = 0.74", "span_m = 0", "turbulence.span_m must be positive"),
    ("mass_kg = 0.930", "mass_kg = = 0.930", "not valid TOML"),
])
def test_parameter_errors_name_the_key(tmp_path, old, new, match):
    with pytest.raises(InputError, match=match):
        load_params(edited(tmp_path, old, new))


def test_the_firmwares_default_geometry_is_the_shipped_vehicle():
    # The firmware flies its CA_* parameters' defaults (params.hpp, GeometryParams); the
    # simulator's vehicle is sim/plant/vehicle.toml. They are the same vehicle: the rotors'
    # places, thrust axes and largest thrusts and the central rotor's torque ratio to float
    # precision, the weight to the 5 digits the firmware writes. The arm rotors' own torque
    # ratios are in the file but not in the defaults (KM 0: the mixer did not use them; they
    # cancel in pairs at equal thrust).
    flown = fw.params_geometry()
    shipped = firmware_geometry({g.name: g.value for g in geometry_params(PARAMS)})
    assert flown.count == shipped.count == 5
    for i, (f, s) in enumerate(zip(flown.rotors, shipped.rotors)):
        np.testing.assert_allclose(f.position_m, s.position_m, rtol=0, atol=1e-7)
        np.testing.assert_allclose(f.axis, s.axis, rtol=0, atol=1e-7)
        assert f.max_thrust_n == s.max_thrust_n
        assert f.moment_ratio_m == (s.moment_ratio_m if i == 0 else 0.0)
    assert flown.rotors[0].spin == shipped.rotors[0].spin
    assert flown.hover_thrust_n == pytest.approx(shipped.hover_thrust_n, rel=1e-5)


@pytest.mark.parametrize("axis", range(3))
def test_the_firmware_mixers_rotor_layout_is_the_vehicles(axis):
    # The firmware's mixer (its default geometry) and the vehicle model place the rotors alike:
    # 0.1 of one axis's command at hover is a moment about that axis alone, of 0.1 of the
    # mixer's unit; within 1.5 % (the canted arms' prop drag torques, which the mixer leaves
    # out, add ~1 % to roll and pitch).
    v, mixer = Vehicle(PARAMS, rig="free"), fw.Mixer()
    command = [0.0, 0.0, 0.0]
    command[axis] = 0.1
    hover = PARAMS.body.mass_kg * GRAVITY_M_S2 / mixer.max_vertical_thrust_n
    u = np.array(mixer.mix(fw.MixerCommand(hover, *command)).motor)
    settled(v, u)
    moment = v.derivative(v.x, u)[10:13] * np.array(PARAMS.body.inertia_kg_m2)
    unit = mixer.yaw_torque_unit_nm if axis == 2 else mixer.roll_pitch_torque_unit_nm
    assert moment[axis] == pytest.approx(0.1 * unit, rel=0.015)
    assert np.all(np.abs(np.delete(moment, axis)) < 1e-6 * abs(moment[axis]))


# --- physics ------------------------------------------------------------------------------

def test_hover_trim_from_the_firmware_mixer_holds_still():
    v = Vehicle(PARAMS, rig="free")
    mixer = fw.Mixer()
    collective = PARAMS.body.mass_kg * GRAVITY_M_S2 / mixer.max_vertical_thrust_n
    u = mixer.mix(fw.MixerCommand(collective, 0, 0, 0)).motor
    settled(v, u)
    dx = v.derivative(v.x, np.array(u))
    # float32 mixer: thrust fractions to ~1e-7, so accelerations to ~1e-4
    assert np.all(np.abs(dx[3:6]) < 2e-3), dx[3:6]
    assert np.all(np.abs(dx[10:13]) < 2e-3), dx[10:13]
    assert np.all(np.abs(dx[13:18]) < 1e-2)


def test_thrust_above_hover_accelerates_up_by_the_excess():
    v = Vehicle(PARAMS, rig="free")
    mixer = fw.Mixer()                    # the shipped vehicle's (test above)
    m = PARAMS.body.mass_kg
    collective = 1.2 * m * GRAVITY_M_S2 / mixer.max_vertical_thrust_n
    u = mixer.mix(fw.MixerCommand(collective, 0, 0, 0)).motor
    settled(v, u)
    az = v.derivative(v.x, np.array(u))[5]
    assert az == pytest.approx(-0.2 * GRAVITY_M_S2, rel=1e-3)      # NED: up is negative


def test_torque_free_gyrostat_conserves_momentum_and_energy():
    # Gravity off, no prop drag torque, central rotor held at 400 rad/s, body tumbling:
    # no external moment, so the total angular momentum (in NED) and the body's rotational
    # energy are constants of motion, while the rates precess.
    params = without_central_drag(PARAMS)
    v = Vehicle(params, rig="free", gravity_m_s2=0.0, substeps=4)
    speed = 400.0
    u = np.array([(speed / v.w_max[0]) ** 2, 0, 0, 0, 0])
    v.set_rotor_speeds([speed, 0, 0, 0, 0])
    v.x[10:13] = [0.5, -0.3, 0.2]
    h0, e0, w0 = v.angular_momentum_ned(), v.rotational_energy(), v.x[10:13].copy()
    for _ in range(1000):                                            # 5 s at 5 ms
        v.step(u, 0.005)
    assert np.linalg.norm(v.angular_momentum_ned() - h0) < 1e-7 * np.linalg.norm(h0)
    assert v.rotational_energy() == pytest.approx(e0, rel=1e-7)
    assert np.linalg.norm(v.x[10:12] - w0[:2]) > 0.1                  # it does precess


def test_gyroscopic_coupling_of_the_central_rotor():
    # A pitch rate with the central rotor spinning gives a roll moment -(w x h):
    # w = (0, q, 0), h = (0, 0, -J W) for a counter-clockwise rotor -> M_x = J W q.
    params = without_central_drag(PARAMS)
    v = Vehicle(params, rig="free", gravity_m_s2=0.0)
    speed = 400.0
    v.set_rotor_speeds([speed, 0, 0, 0, 0])
    v.x[11] = 0.5
    u = np.array([(speed / v.w_max[0]) ** 2, 0, 0, 0, 0])
    p_dot = v.derivative(v.x, u)[10]
    J = params.rotors[0].rotor_inertia_kg_m2
    assert p_dot == pytest.approx(J * speed * 0.5 / params.body.inertia_kg_m2[0], rel=1e-9)


@pytest.mark.parametrize("rig, axis", [("roll", 0), ("pitch", 1), ("yaw", 2)])
def test_each_rig_frees_exactly_one_axis(rig, axis):
    v = Vehicle(PARAMS, rig=rig)
    mixer = fw.Mixer()                    # the shipped vehicle's (test above)
    u = mixer.mix(fw.MixerCommand(0.35, 0.02, -0.02, 0.05)).motor     # moments on all axes
    settled(v, u)
    for _ in range(200):
        v.step(u, 0.005)
    s = v.state()
    others = [k for k in range(3) if k != axis]
    assert abs(s.rates_rad_s[axis]) > 1e-3
    assert np.all(s.rates_rad_s[others] == 0.0)
    assert np.all(s.position_m == 0.0) and np.all(s.velocity_m_s == 0.0)
    q = s.quaternion                                                 # a rotation about the axis only
    assert np.all(np.abs(q[1 + np.array(others)]) < 1e-12)


def test_roll_rig_acceleration_is_the_roll_moment_over_inertia():
    params = dataclasses.replace(PARAMS, rig=dataclasses.replace(
        PARAMS.rig, hinge_damping_n_m_s_rad=0.0, hinge_friction_n_m=0.0))
    v = Vehicle(params, rig="roll")
    mixer = fw.Mixer()
    u = np.array(mixer.mix(fw.MixerCommand(0.35, 0.03, 0, 0)).motor)
    settled(v, u)
    t = v.thrusts()
    right, left = params.rotors[2], params.rotors[4]
    l, d, cq = right.position_m[1], math.acos(-right.thrust_axis[2]), right.torque_per_thrust_m
    sigma = params.rotors[0].spin
    thrust_moment = -l * math.cos(d) * (t[2] - t[4])
    # The canted right and left props' spin axes lean along -/+x (by sin(delta)), so their
    # drag torques -Q a have a roll part too (~1 % here; the mixer does not model it).
    drag_moment = -cq * (t[2] * right.spin * sigma * math.sin(d) - t[4] * left.spin * sigma * math.sin(d))
    expected = (thrust_moment + drag_moment) / params.body.inertia_kg_m2[0]
    assert v.derivative(v.x, u)[10] == pytest.approx(expected, rel=1e-6)
    assert abs(drag_moment) < 0.02 * abs(thrust_moment)
    # and the mixer's normalised command maps to the thrust moment
    assert thrust_moment == pytest.approx(0.03 * mixer.roll_pitch_torque_unit_nm, rel=1e-4)
