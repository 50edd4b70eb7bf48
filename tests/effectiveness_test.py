"""Each rotor's control effectiveness from per-rotor injections (host/estimate/effectiveness.py,
docs/effectiveness.md): exact on exact points; on the simulator's rigs flown in closed loop
(tests/effectiveness_rig.py: the C++ vehicle, pid_model.py's cascade, the firmware's
allocation, a multisine on every rotor's command) it finds the vehicle's effectiveness, its
rotors' time constants and honest sigmas, for the default vehicle and for one unlike the
firmware's, and its paths through the allocation are the axis's plant; the geometry fitted to
it is the vehicle's; a rotor no rig moves gets no lag; bad input is refused in one line."""

import math

import numpy as np
import pytest

from effectiveness_rig import allocation_column, fly_rig, other_vehicle, truth
from heliquad.host.estimate.effectiveness import (Rig, RotorPoints, estimate_effectiveness,
                                                  held_paths, rig_from_poles, rig_points,
                                                  rotor_paths)
from heliquad.host.estimate.rotor_geometry import fit_rotor_geometry
from heliquad.host.records.points import FrequencyPoint
from heliquad.sim.base.dialect import AXES
from heliquad.sim.base.errors import InputError
from heliquad.sim.base.firmware_facts import LOOP_PERIOD_S, LOOP_RATE_HZ
from heliquad.sim.plant.vehicle import Vehicle
from heliquad.sim.plant.vehicle_params import load_params
from heliquad.sim.plant.vehicle_plant import VehiclePlant

#: The runs: a multisine of 1000 samples (5 s) on every rotor's own odd lines, 9 periods
#: (the first fills the filter), peak 0.01 of thrust command on each rotor (at 0.03 the
#: rotors' quadratic thrust already bends the points by 2 %), gyro noise 0.002 rad/s per
#: sample (the MPU6050's 7e-4 rad/s at the vehicle file's noise density, and as much again
#: for the motors' vibration).
PERIOD, PERIODS, AMPLITUDE, GYRO_NOISE_RAD_S, SEED = 1000, 9, 0.01, 0.002, 3
#: The acceptance: every entry within 5 % of the largest of its row, every time constant
#: within 10 %, and the errors over their sigmas of RMS 0.5 to 2.
ENTRY_TOLERANCE, TIME_CONSTANT_TOLERANCE, RMS_Z = 0.05, 0.10, (0.5, 2.0)


def rig_records(params, axes=("roll", "pitch", "yaw")):
    """Every rotor's points from the rigs ``axes`` flown, and the rigs."""
    records, rigs = [], {}
    for axis in axes:
        run = fly_rig(params, axis, PERIOD, PERIODS, AMPLITUDE, GYRO_NOISE_RAD_S, SEED)
        inertia = params.body.inertia_kg_m2[AXES[axis]]
        rigs[axis] = Rig(axis, tuple(allocation_column(axis)),
                         params.rig.hinge_damping_n_m_s_rad / inertia)
        records += rig_points(run.excitation, run.rate, run.command, LOOP_RATE_HZ, PERIOD,
                              run.orders, axis)
    return records, rigs


@pytest.fixture(scope="module")
def default_vehicle():
    """The default vehicle, its rigs' records and rigs, and the estimate from them."""
    params = load_params()
    records, rigs = rig_records(params)
    return params, (records, rigs), estimate_effectiveness(records, rigs, 5, LOOP_PERIOD_S)


def figures(est, params):
    """(largest error over its row's largest entry, largest relative time-constant error,
    RMS of the errors over their sigmas) of the estimate against the vehicle's truth."""
    true_e = truth(Vehicle(params, rig="roll"))
    true_t = np.array([r.time_constant_s for r in params.rotors])
    err = est.effectiveness_rad_s2 - true_e
    entry = np.max(np.abs(err) / np.max(np.abs(true_e), axis=1, keepdims=True))
    t_err = np.max(np.abs(est.time_constant_s - true_t) / true_t)
    z = np.concatenate([(err / est.effectiveness_sigma_rad_s2).ravel(),
                        (est.time_constant_s - true_t) / est.time_constant_sigma_s])
    return entry, t_err, math.sqrt(float(np.mean(z ** 2)))


def assert_accepted(est, params):
    entry, t_err, rms_z = figures(est, params)
    assert entry < ENTRY_TOLERANCE, entry
    assert t_err < TIME_CONSTANT_TOLERANCE, t_err
    assert RMS_Z[0] < rms_z < RMS_Z[1], rms_z
    assert 0.3 < est.chi2_dof < 3.0, est.chi2_dof
    # the delay is the gyro's one sample (the hold is in the model)
    np.testing.assert_allclose(est.delay_s, LOOP_PERIOD_S, atol=1e-3)


def test_the_three_rigs_find_the_default_vehicle(default_vehicle):
    params, _, est = default_vehicle
    assert_accepted(est, params)


def test_the_rotors_paths_through_the_allocation_are_the_axis_plant(default_vehicle):
    # sum_j a_kj P_j is what the axis sweep identifies: the simulator's truth of the torque
    # command to the rate (sampled, with the sensor's latency) within 3 % and 2 deg.
    params, (_, rigs), est = default_vehicle
    omega = np.geomspace(1.0, 100.0, 8)
    for axis, rig in rigs.items():
        _, p_c = rotor_paths(est, rig, omega, LOOP_PERIOD_S)
        ratio = p_c / VehiclePlant(axis, axis, LOOP_PERIOD_S, params).truth(omega, "mixer")
        assert np.all(np.abs(np.abs(ratio) - 1) < 0.03), (axis, ratio)
        assert np.all(np.abs(np.angle(ratio, deg=True)) < 2.0), (axis, ratio)


@pytest.fixture(scope="module")
def unlike_firmwares():
    params = other_vehicle(load_params())
    records, rigs = rig_records(params)
    return params, estimate_effectiveness(records, rigs, 5, LOOP_PERIOD_S)


def test_the_three_rigs_find_a_vehicle_unlike_the_firmwares(unlike_firmwares):
    params, est = unlike_firmwares
    assert_accepted(est, params)


def test_the_geometry_that_explains_the_effectiveness_is_the_vehicles(unlike_firmwares):
    # Started from the firmware's default vehicle, the fit finds the other one's cant, its
    # weak rotor, its torque ratios, each within three of its sigmas, which are at most 6 %
    # of the value (the arm rotors' torque ratio is the least seen: their drag torques nearly
    # cancel at equal thrust).
    params, est = unlike_firmwares
    rotors = params.rotors
    fit = fit_rotor_geometry(est.effectiveness_rad_s2, est.effectiveness_covariance,
                             [r.position_m for r in rotors], [r.spin for r in rotors],
                             params.body.inertia_kg_m2, rotors[0].max_thrust_n,
                             (20.0, 0.0076, 0.017, 9.0))
    found = [(fit.cant_deg, fit.cant_sigma_deg, 14.0),
             (fit.arm_torque_ratio_m, fit.arm_torque_ratio_sigma_m, rotors[1].torque_per_thrust_m),
             (fit.central_torque_ratio_m, fit.central_torque_ratio_sigma_m,
              rotors[0].torque_per_thrust_m)]
    found += [(fit.max_thrust_n[i], fit.max_thrust_sigma_n[i], rotors[i].max_thrust_n)
              for i in range(1, 5)]
    for value, sigma, true in found:
        assert abs(value - true) < 3 * sigma < 0.18 * abs(true), (value, sigma, true)
    np.testing.assert_allclose(fit.thrust_axes, [r.thrust_axis for r in rotors], atol=2e-3)
    # 15 entries, 7 parameters: chi-square over 8 degrees of freedom spreads widely (seeds
    # 0 to 5 gave 0.19 to 1.67)
    assert 0.1 < fit.chi2_dof < 3.0, fit.chi2_dof
    with pytest.raises(InputError, match="cannot fit"):
        fit_rotor_geometry(est.effectiveness_rad_s2[:1].repeat(3, 0) * np.nan,
                           est.effectiveness_covariance, [r.position_m for r in rotors],
                           [r.spin for r in rotors], params.body.inertia_kg_m2,
                           rotors[0].max_thrust_n, (20.0, 0.0076, 0.017, 9.0))


def test_the_sigmas_hold_over_many_runs():
    # Six roll runs of other seeds: the roll entries' and the right and left rotors' time
    # constants' errors over their sigmas, pooled (42 of them), have an RMS near 1 (seeds
    # 10 to 19 gave 0.80 over 70).
    params = load_params()
    true_e = truth(Vehicle(params, rig="roll"))[0]
    true_t = np.array([r.time_constant_s for r in params.rotors])[[2, 4]]
    rig = {"roll": Rig("roll", tuple(allocation_column("roll")),
                       params.rig.hinge_damping_n_m_s_rad / params.body.inertia_kg_m2[0])}
    z = []
    for seed in range(10, 16):
        run = fly_rig(params, "roll", PERIOD, PERIODS, AMPLITUDE, GYRO_NOISE_RAD_S, seed)
        est = estimate_effectiveness(rig_points(run.excitation, run.rate, run.command,
                                                LOOP_RATE_HZ, PERIOD, run.orders, "roll"), rig, 5,
                                     LOOP_PERIOD_S)
        z += list((est.effectiveness_rad_s2[0] - true_e) / est.effectiveness_sigma_rad_s2[0])
        z += list((est.time_constant_s[[2, 4]] - true_t) / est.time_constant_sigma_s[[2, 4]])
    assert 0.6 < math.sqrt(float(np.mean(np.square(z)))) < 1.5


def test_a_rotor_no_rig_moves_has_no_lag(default_vehicle):
    # On the roll rig alone the central, front and back rotors move nothing: their roll
    # entries are zero within their sigmas and their lags are not reported.
    _, (records, rigs), _ = default_vehicle
    roll = [r for r in records if r.axis == "roll"]
    est = estimate_effectiveness(roll, {"roll": rigs["roll"]}, 5, LOOP_PERIOD_S)
    still = [0, 1, 3]
    assert np.all(np.isnan(est.time_constant_s[still]))
    assert np.all(np.isfinite(est.time_constant_s[[2, 4]]))
    row = est.effectiveness_rad_s2[0]
    assert np.all(np.abs(row[still]) < 3 * est.effectiveness_sigma_rad_s2[0][still])
    assert np.all(np.isnan(est.effectiveness_rad_s2[1:]))


def test_samples_lost_on_the_link_cost_only_their_share(default_vehicle):
    # 3 % of the roll rig's samples lost at random: the entries move inside their sigmas,
    # which grow (the holes let the command's slow wander reach the lowest lines) but stay
    # of the same order.
    params, _, _ = default_vehicle
    run = fly_rig(params, "roll", PERIOD, PERIODS, AMPLITUDE, GYRO_NOISE_RAD_S, SEED)
    present = np.random.default_rng(5).uniform(size=run.rate.size) > 0.03
    rig = {"roll": Rig("roll", tuple(allocation_column("roll")))}
    full, lost = (estimate_effectiveness(
        rig_points(run.excitation.sum(axis=1), np.where(mask, run.rate, np.nan),
                   np.where(mask, run.command, np.nan), LOOP_RATE_HZ, PERIOD, run.orders,
                   "roll", present=mask), rig, 5, LOOP_PERIOD_S)
        for mask in (np.ones(run.rate.size, dtype=bool), present))
    sigma = lost.effectiveness_sigma_rad_s2[0]
    moved = np.abs(lost.effectiveness_rad_s2[0] - full.effectiveness_rad_s2[0]) / sigma
    assert np.all(moved < 2.0), moved
    assert np.all((sigma > full.effectiveness_sigma_rad_s2[0])
                  & (sigma < 3 * full.effectiveness_sigma_rad_s2[0])), sigma


def synthetic_records(paths, rig, omega):
    """Exact points of rotors with these ``paths`` (rotors x ``omega``) on one rig, in a
    loop closed by a PI on the rate."""
    p_c = np.asarray(rig.allocation) @ paths
    k = 0.3 * (1 + 2.0 / (1j * omega))
    records = []
    for i, p_i in enumerate(paths):
        t_p = p_i / (1 + k * p_c)
        pts = [tuple(FrequencyPoint(omega_rad_s=w, gain=complex(g), sigma=1e-9,
                                    coherence=1.0) for w, g in zip(omega, gains))
               for gains in (t_p, -k * t_p)]
        records.append(RotorPoints(rig.axis, i, *pts, (0j,) * omega.size))
    return records


def test_exact_points_give_the_exact_rotors():
    e, t, tau = np.array([0.0, 150.0, -120.0]), np.array([0.1, 0.03, 0.05]), np.array(
        [0.004, 0.007, 0.01])
    rig = Rig("roll", (0.0, 0.004, -0.005), damping_rad_s=0.3)
    omega = np.geomspace(1, 100, 9)
    s = 1j * omega[None, :]
    paths = (e[:, None] * np.exp(-s * tau[:, None]) / (t[:, None] * s + 1)
             * rig.response(omega)[None, :])
    est = estimate_effectiveness(synthetic_records(paths, rig, omega), {"roll": rig}, 3)
    np.testing.assert_allclose(est.effectiveness_rad_s2[0], e, atol=1e-6)
    np.testing.assert_allclose(est.time_constant_s[1:], t[1:], rtol=1e-6)
    np.testing.assert_allclose(est.delay_s[1:], tau[1:], atol=1e-6)
    assert np.isnan(est.time_constant_s[0])


@pytest.mark.parametrize("damping, stiffness", [(0.0, 0.0), (0.17, 0.0), (0.5, 9.0)])
def test_the_holds_equivalent_is_the_sampled_path(damping, stiffness):
    # The sampled response of hold, path and sampler is the sum of the path's aliases times
    # the hold's (1 - e^{-s h}) / (s h): summed over 4e5 aliases it agrees to 1e-6 (the sum's
    # tail), for a delay of a fraction of a sample and of whole samples.
    h, t = LOOP_PERIOD_S, 0.03
    omega = np.array([1.3, 10.0, 50.0, 99.0])
    s = 1j * (omega[:, None] + 2 * np.pi / h * np.arange(-200_000, 200_001)[None, :])
    for tau in (0.0075, 0.01):
        per_e, per_m = held_paths(omega, h, t, tau, damping, stiffness)
        path = np.exp(-s * tau) / (t * s + 1) * s / (s * s + damping * s + stiffness)
        hold = (1 - np.exp(-s * h)) / (s * h)
        np.testing.assert_allclose(per_e, np.sum(path * hold, axis=1), rtol=1e-6)
        np.testing.assert_allclose(per_m, np.sum(s * path * hold, axis=1), rtol=1e-6)


def test_exact_held_points_give_the_exact_rotors():
    e, t, tau = np.array([10.0, 150.0, -120.0]), np.array([0.1, 0.03, 0.05]), np.array(
        [0.004, 0.007, 0.012])
    spin = np.array([2.0, 0.5, -0.4])
    rig = Rig("yaw", (0.3, 0.004, -0.005), damping_rad_s=0.3)
    omega = np.geomspace(1, 100, 9)
    per_e, per_m = held_paths(omega[None, :], LOOP_PERIOD_S, t[:, None], tau[:, None], 0.3, 0.0)
    paths = e[:, None] * per_e + spin[:, None] * per_m
    records = synthetic_records(paths, rig, omega)
    est = estimate_effectiveness(records, {"yaw": rig}, 3, LOOP_PERIOD_S)
    np.testing.assert_allclose(est.effectiveness_rad_s2[2], e, rtol=1e-6)
    np.testing.assert_allclose(est.spin_up_rad_s[2], spin, rtol=1e-5)
    np.testing.assert_allclose(est.time_constant_s, t, rtol=1e-6)
    np.testing.assert_allclose(est.delay_s, tau, atol=1e-7)


def test_exact_held_points_give_the_rigs_hinge_when_it_is_fitted():
    e, t, tau = np.array([10.0, 150.0, -120.0]), np.array([0.1, 0.03, 0.05]), np.array(
        [0.004, 0.007, 0.012])
    omega = np.geomspace(0.5, 100, 9)
    per_e, per_m = held_paths(omega[None, :], LOOP_PERIOD_S, t[:, None], tau[:, None], 0.3, 0.0)
    records = synthetic_records(e[:, None] * per_e, Rig("yaw", (0.3, 0.004, -0.005), 0.3), omega)
    for start in (0.0, 1.0):                 # a free hinge, and one too damped
        est = estimate_effectiveness(records, {"yaw": Rig("yaw", (0.3, 0.004, -0.005), start)},
                                     3, LOOP_PERIOD_S, fit_hinges=True)
        assert est.hinge_damping_rad_s["yaw"] == pytest.approx(0.3, rel=1e-5)
        np.testing.assert_allclose(est.effectiveness_rad_s2[2], e, rtol=1e-5)
        np.testing.assert_allclose(est.time_constant_s, t, rtol=1e-5)
    held = estimate_effectiveness(records, {"yaw": Rig("yaw", (0.3, 0.004, -0.005), 0.0)}, 3,
                                  LOOP_PERIOD_S)
    assert held.hinge_damping_rad_s is None
    assert np.max(np.abs(held.effectiveness_rad_s2[2] - e)) > 1e-3 * np.max(np.abs(e))


def test_the_rig_comes_from_the_axis_models_slowest_poles():
    assert rig_from_poles("roll", (0.0, 1.0), -0.2) == Rig("roll", (0.0, 1.0), 0.2, 0.0)
    rig = rig_from_poles("pitch", (1.0,), [-0.5 + 3j, -0.5 - 3j])
    assert rig.damping_rad_s == pytest.approx(1.0) and rig.stiffness_rad2_s2 == pytest.approx(9.25)
    # its gain is 1: rate per angular acceleration is 1/s far above the hinge
    assert abs(rig.response(1e4) * 1e4j) == pytest.approx(1.0, rel=1e-6)
    with pytest.raises(InputError, match="stable poles"):
        rig_from_poles("roll", (1.0,), 0.3)


def test_bad_input_is_refused_in_one_line(default_vehicle):
    _, (records, rigs), _ = default_vehicle
    with pytest.raises(InputError, match="no rotor's points"):
        estimate_effectiveness([], rigs, 5)
    with pytest.raises(InputError, match="no rig given for the pitch"):
        estimate_effectiveness(records, {"roll": rigs["roll"]}, 5)
    with pytest.raises(InputError, match="not one of the 4"):
        estimate_effectiveness(records, rigs, 4)
    run = fly_rig(load_params(), "roll", PERIOD, 2, AMPLITUDE, GYRO_NOISE_RAD_S, SEED)
    with pytest.raises(InputError, match="one column per rotor"):
        rig_points(run.excitation, run.rate, run.command, LOOP_RATE_HZ, PERIOD,
                   run.orders[:4], "roll")
    with pytest.raises(InputError, match="no line shared"):
        rig_points(run.excitation, run.rate, run.command, LOOP_RATE_HZ, PERIOD,
                   (run.orders[0],) * 5, "roll")
    few = [RotorPoints(r.axis, r.rotor, r.rate[:1], r.command[:1], r.correlation[:1])
           for r in records if r.axis == "roll"]
    with pytest.raises(InputError, match="cannot fit"):
        estimate_effectiveness(few, {"roll": rigs["roll"]}, 5)
