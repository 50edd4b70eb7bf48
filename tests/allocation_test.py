"""The control allocation from a rotor geometry (firmware/core/allocation.cpp, docs/mixer.md):
with the default geometry parameters it is the mixer (same flags, thrust fractions to float precision)
on the mixer tests' commands, across a saturation grid and on random commands; on a six-
and an eight-rotor vehicle its effectiveness times its allocation is the identity and
achievable commands are met exactly; its flags say which command gave way, in the mixer's
order; geometries without roll, pitch or yaw authority are refused with a reason the link
can send."""

import itertools
import math

import numpy as np
import pytest

from heliquad import _firmware as fw
from mixer_test import (HOVER, ROLL_BEYOND_FULL, ROLL_PITCH_BEYOND_HOVER, SATURATING_COLLECTIVES,
                        SMALL_PITCH, SMALL_ROLL, UNSATURATED, YAW_CASES, wrench)

MIXER = fw.Mixer()
#: The firmware's default geometry parameters (CA_*), as it flies them.
DEFAULT = fw.Allocation(fw.params_geometry())

#: Thrust fractions of the default allocation against the mixer's: the two compute the same
#: exact values by different float roundings (the mixer by its closed form, the allocation
#: through the rounded entries of a pseudo-inverse computed in float and a sum of three
#: products per rotor), each within a few ulps of 1.0 (1.2e-7): measured at most 4.8e-7
#: over the grids below and 6.0e-7 over the random commands. The flags must be equal
#: exactly.
FRACTION_TOL = 1e-6
#: The mixer's flags of saturation.
FLAGS = ("saturated", "torque_limited", "collective_limited")
#: A STATUSTEXT's text field, characters: a refusal's reason must fit one.
STATUSTEXT_CHARS = 50


def flags(out):
    return tuple(getattr(out, f) for f in FLAGS)


def assert_mixer_equal(commands):
    """The default allocation gives the mixer's output for every command; returns how many
    of them saturated the mixer (torque, collective)."""
    saturated = [0, 0]
    for c in commands:
        cmd = fw.MixerCommand(*c)
        mixed, allocated = MIXER.mix(cmd), DEFAULT.allocate(cmd)
        assert flags(allocated) == flags(mixed), c
        np.testing.assert_allclose(allocated.motor[:5], mixed.motor, rtol=0, atol=FRACTION_TOL,
                                   err_msg=str(c))
        assert allocated.motor[5:] == [0.0] * 3
        saturated[0] += mixed.torque_limited
        saturated[1] += mixed.collective_limited
    return saturated


# --- the default geometry is the mixer's vehicle ------------------------------------------

def test_the_default_geometry_is_the_mixers_vehicle():
    rng = np.random.default_rng(1)
    b = np.array(DEFAULT.effectiveness)
    assert b.shape == (4, 5)
    for u in rng.uniform(0, 1, (20, 5)):
        np.testing.assert_allclose(b @ u, wrench(u), rtol=1e-6, atol=1e-6)
    np.testing.assert_allclose(DEFAULT.units, [MIXER.max_vertical_thrust_n,
                                               MIXER.roll_pitch_torque_unit_nm,
                                               MIXER.roll_pitch_torque_unit_nm,
                                               MIXER.yaw_torque_unit_nm], rtol=1e-6)
    arm_hover = MIXER.hover_arm_thrust_n / fw.MixerGeometry().arm_max_thrust_n
    np.testing.assert_allclose(DEFAULT.hover_fractions[1:], [arm_hover] * 4, rtol=1e-6)


def test_the_default_allocation_is_the_mixer_on_the_mixer_tests_commands():
    roll, pitch = ROLL_PITCH_BEYOND_HOVER
    commands = (UNSATURATED + [HOVER, SMALL_ROLL, SMALL_PITCH, ROLL_BEYOND_FULL]
                + [(c, roll, pitch, 0.0) for c in SATURATING_COLLECTIVES]
                + [(c, 0.0, 0.0, y) for c, y, _ in YAW_CASES])
    torque, collective = assert_mixer_equal(commands)
    assert torque >= 1 and collective >= 6


def test_the_default_allocation_is_the_mixer_across_saturation():
    # Every branch of the mixer's saturation: collective outside 0..1, roll and pitch beyond
    # the full differential, the collective giving way, yaw giving way at both ends.
    collectives = [-0.1, 0.0, 0.02, 0.05, 0.1, 0.2, 0.3, 0.35, 0.45, 0.5, 0.6, 0.8, 0.98, 1.0, 1.2]
    tilts = [-20.0, -3.0, -1.0, -0.8, -0.5, 0.0, 0.05, 0.3, 0.6, 1.0, 2.5, 20.0]
    yaws = [-5.0, -3.0, -2.0, -0.9, -0.3, 0.0, 0.2, 1.0, 2.0, 3.0, 6.0]
    commands = list(itertools.product(collectives, tilts, tilts, yaws))
    torque, collective = assert_mixer_equal(commands)
    assert 0.2 * len(commands) < torque < 0.9 * len(commands)
    assert 0.2 * len(commands) < collective < len(commands)


def test_the_default_allocation_is_the_mixer_on_random_commands():
    rng = np.random.default_rng(4)
    commands = rng.uniform([-0.1, -3.0, -3.0, -4.0], [1.1, 3.0, 3.0, 4.0], (20000, 4))
    torque, collective = assert_mixer_equal(commands)
    assert torque > 1000 and collective > 5000


# --- other geometries: the pseudo-inverse and the saturation rules -----------------------

def eight_rotors():
    """A central rotor and seven arm rotors at 0.25 m, canted 15 deg, 0.02 m above the
    centre of mass, spinning alternately with a moment ratio of their own."""
    cant, arm = math.radians(15.0), 0.25
    rotors = [fw.RotorGeometry((0.0, 0.0, -0.05), (0.0, 0.0, -1.0), 30.0, 0.02, 1)]
    for i in range(7):
        psi = 2 * math.pi * i / 7 + 0.2
        tangential = (-math.sin(psi), math.cos(psi))
        axis = (-math.sin(cant) * tangential[0], -math.sin(cant) * tangential[1],
                -math.cos(cant))
        rotors.append(fw.RotorGeometry((arm * math.cos(psi), arm * math.sin(psi), -0.02), axis,
                                       7.0, 0.012, 1 if i % 2 else -1))
    return fw.AllocationGeometry(rotors, hover_thrust_n=14.0)


GEOMETRIES = {
    "default": fw.canted_arms_geometry(),
    "six": fw.canted_arms_geometry(fw.MixerGeometry(), arms=5),
    "eight": eight_rotors(),
}


def physical_effectiveness(geometry):
    """B from docs/mixer.md's equations, in numpy: per unit thrust fraction, the vertical
    force and the moment r x a T - spin km T a."""
    columns = []
    for r in geometry.rotors:
        a, pos = np.array(r.axis), np.array(r.position_m)
        moment = (np.cross(pos, a) - r.spin * r.moment_ratio_m * a) * r.max_thrust_n
        columns.append([-a[2] * r.max_thrust_n, *moment])
    return np.array(columns).T


@pytest.fixture(params=sorted(GEOMETRIES))
def geometry(request):
    return GEOMETRIES[request.param]


def test_the_effectiveness_is_the_rotors_forces_and_moments(geometry):
    allocation = fw.Allocation(geometry)
    assert allocation.ok and allocation.reason == "" and allocation.count == geometry.count
    np.testing.assert_allclose(allocation.effectiveness, physical_effectiveness(geometry),
                               rtol=1e-5, atol=1e-6)


def test_effectiveness_times_allocation_is_the_identity(geometry):
    allocation = fw.Allocation(geometry)
    normalised = np.array(allocation.effectiveness) / np.array(allocation.units)[:, None]
    np.testing.assert_allclose(normalised @ np.array(allocation.allocation), np.eye(4),
                               atol=2e-6)


def test_achievable_commands_are_met_exactly(geometry):
    # The commands whose pseudo-inverse thrusts all lie within 0..1: no flag, and what the
    # vehicle gets is what was asked.
    allocation = fw.Allocation(geometry)
    a = np.array(allocation.allocation)
    rng = np.random.default_rng(2)
    met = 0
    for c in rng.uniform([0.0, -1.5, -1.5, -1.5], [0.6, 1.5, 1.5, 1.5], (400, 4)):
        u = a @ c
        if not np.all((u > 1e-4) & (u < 1 - 1e-4)):
            continue
        out = allocation.allocate(fw.MixerCommand(*c))
        assert flags(out) == (False, False, False), c
        np.testing.assert_allclose(out.motor[:geometry.count], u, atol=1e-6)
        got = allocation.achieved(out.motor[:geometry.count])
        np.testing.assert_allclose([got.collective, got.roll, got.pitch, got.yaw], c, atol=1e-5)
        met += 1
    assert met >= 40


def achieved(allocation, out):
    got = allocation.achieved(out.motor[:allocation.count])
    return np.array([got.collective, got.roll, got.pitch, got.yaw])


def test_the_flags_say_what_gave_way(geometry):
    # Over random commands, many beyond the vehicle: thrusts within 0..1; an unflagged
    # torque is met, an unflagged collective is met.
    allocation = fw.Allocation(geometry)
    rng = np.random.default_rng(3)
    seen = set()
    for c in rng.uniform([-0.2, -4.0, -4.0, -4.0], [1.2, 4.0, 4.0, 4.0], (3000, 4)):
        out = allocation.allocate(fw.MixerCommand(*c))
        assert all(0.0 <= m <= 1.0 for m in out.motor)
        got = achieved(allocation, out)
        if not out.torque_limited:
            np.testing.assert_allclose(got[1:], c[1:], atol=1e-4)
        if not out.collective_limited:
            assert got[0] == pytest.approx(c[0], abs=1e-5)
        assert out.saturated == (out.torque_limited or out.collective_limited)
        seen.add(flags(out))
    # met in full, the collective alone gave way, yaw gave way too
    assert {(False, False, False), (True, False, True), (True, True, True)} <= seen


@pytest.mark.parametrize("collective", SATURATING_COLLECTIVES)
def test_roll_and_pitch_are_kept_before_yaw_and_collective(geometry, collective):
    allocation = fw.Allocation(geometry)
    roll, pitch = ROLL_PITCH_BEYOND_HOVER
    out = allocation.allocate(fw.MixerCommand(collective, roll, pitch, 0.5))
    got = achieved(allocation, out)
    assert out.collective_limited
    np.testing.assert_allclose(got[1:3], [roll, pitch], atol=1e-5)
    # yaw is flagged exactly when it was not met
    assert out.torque_limited == (abs(got[3] - 0.5) > 1e-4)


def test_yaw_is_kept_before_the_collective(geometry):
    allocation = fw.Allocation(geometry)
    out = allocation.allocate(fw.MixerCommand(0.05, 0.0, 0.0, 2.0))
    got = achieved(allocation, out)
    assert out.collective_limited and not out.torque_limited
    assert got[3] == pytest.approx(2.0, abs=1e-4)
    assert got[0] > 0.05


def test_roll_beyond_its_limit_is_clipped_to_half_a_rotors_range(geometry):
    allocation = fw.Allocation(geometry)
    out = allocation.allocate(fw.MixerCommand(*ROLL_BEYOND_FULL))
    assert out.torque_limited
    limit = 0.5 / np.max(np.abs(np.array(allocation.allocation)[:, 1]))
    assert achieved(allocation, out)[1] == pytest.approx(limit, rel=1e-5)


def test_roll_and_pitch_that_cannot_both_be_kept_are_scaled_together():
    # On the eight-rotor vehicle roll and pitch share rotors: each at its own limit, the two
    # together need more than a rotor's range, and both shrink by the same factor.
    allocation = fw.Allocation(GEOMETRIES["eight"])
    a = np.array(allocation.allocation)
    roll_max = 0.5 / np.max(np.abs(a[:, 1]))
    pitch_max = 0.5 / np.max(np.abs(a[:, 2]))
    out = allocation.allocate(fw.MixerCommand(0.5, 20.0, -20.0, 0.0))
    got = achieved(allocation, out)
    assert out.torque_limited and all(0.0 <= m <= 1.0 for m in out.motor)
    scale = got[1] / roll_max
    assert 0.3 < scale < 0.999
    assert -got[2] / pitch_max == pytest.approx(scale, rel=1e-4)


# --- refusals --------------------------------------------------------------------------

def flat_vehicle(arm_moment_ratio=0.0, central_moment_ratio=0.0, arm_spins=(1, -1, 1, -1)):
    """A central rotor and four uncanted arm rotors."""
    rotors = [fw.RotorGeometry((0.0, 0.0, 0.0), (0.0, 0.0, -1.0), 25.0, central_moment_ratio)]
    for i, spin in enumerate(arm_spins):
        psi = math.pi / 2 * i
        rotors.append(fw.RotorGeometry((0.3 * math.cos(psi), 0.3 * math.sin(psi), 0.0),
                                       (0.0, 0.0, -1.0), 9.0, arm_moment_ratio, spin))
    return fw.AllocationGeometry(rotors, hover_thrust_n=9.12)


def canted(**changes):
    g = fw.MixerGeometry()
    for name, value in changes.items():
        setattr(g, name, value)
    return fw.canted_arms_geometry(g)


def with_rotor(geometry, index, **changes):
    rotors = geometry.rotors
    for name, value in changes.items():
        setattr(rotors[index], name, value)
    return fw.AllocationGeometry(rotors, geometry.hover_thrust_n)


REFUSED = {
    "no cant, no moment ratio": (flat_vehicle(), "allocation: no yaw moment"),
    "every rotor the same spin": (flat_vehicle(0.015, 0.015, (1, 1, 1, 1)),
                                  "allocation: yaw depends on thrust, roll, pitch"),
    "three rotors": (fw.AllocationGeometry(fw.canted_arms_geometry().rotors[:3], 9.12),
                     "allocation: 4 to 8 rotors needed"),
    "no central torque to cancel": (canted(central_torque_per_thrust_m=0.0),
                                    "allocation: no roll authority at hover"),
    "heavier than it can lift": (canted(hover_thrust_n=80.0),
                                 "allocation: hover needs rotor 0 beyond 0..1"),
    "a bent axis": (with_rotor(fw.canted_arms_geometry(), 2, axis=(0.0, 0.5, -1.0)),
                    "allocation: rotor 2 axis not a unit vector"),
    "a spin of 2": (with_rotor(fw.canted_arms_geometry(), 3, spin=2),
                    "allocation: rotor 3 spin not +1 or -1"),
    "no thrust": (with_rotor(fw.canted_arms_geometry(), 1, max_thrust_n=0.0),
                  "allocation: rotor 1 max thrust not positive"),
}


@pytest.mark.parametrize("case", sorted(REFUSED))
def test_a_geometry_without_authority_is_refused_with_its_reason(case):
    geometry, reason = REFUSED[case]
    allocation = fw.Allocation(geometry)
    assert not allocation.ok
    assert allocation.reason == reason
    assert len(reason) <= STATUSTEXT_CHARS
    # a refused allocation commands no thrust and says nothing was met
    out = allocation.allocate(fw.MixerCommand(*HOVER))
    assert out.motor == [0.0] * fw.MAX_ROTORS and flags(out) == (True, True, True)


def test_an_allocation_refuses_until_a_good_geometry_comes():
    allocation = fw.Allocation(flat_vehicle())
    assert not allocation.ok
    assert allocation.configure(fw.canted_arms_geometry())
    assert allocation.ok and allocation.reason == ""
    assert flags(allocation.allocate(fw.MixerCommand(*HOVER))) == (False, False, False)
