"""The vehicle's geometry as parameters (CA_ROTOR_COUNT, CA_HOVER_THRUST, CA_ROTORn_*;
docs/parameters.md, docs/mixer.md): their defaults are the mixer's vehicle, so the default
parameters allocate as the mixer did (tests/allocation_test.py runs its saturation grid on
them); over the protocol they change only while disarmed and within range (the ranges:
tests/params_test.py's refused sets), the allocation
is computed again at each change, and a geometry it refuses is said (STATUSTEXT with the
reason) and keeps the motors off: arming is refused until the geometry is one it takes, also
when such a geometry was stored and loaded at start-up."""

from __future__ import annotations

import numpy as np
import pytest

from firmwares import start
from heliquad import _firmware as fw
from params_test import MAV, Client, _stored, client  # noqa: F401  (client: a fixture)

#: The rotor fields, in the order of each rotor's block of parameters (PX4's names).
FIELDS = ("PX", "PY", "PZ", "AX", "AY", "AZ", "CT", "KM")
GEOMETRY_NAMES = (["CA_ROTOR_COUNT", "CA_HOVER_THRUST"]
                  + [f"CA_ROTOR{n}_{f}" for n in range(fw.MAX_ROTORS) for f in FIELDS])
#: The mixer's vehicle built from its own numbers (cos and sin of 20 deg and of the arms'
#: azimuths, each rounded to float) against the parameters' literal defaults: the same to
#: a float's rounding (an azimuth's cosine of 90 deg is -4.4e-8, not 0).
GEOMETRY_TOL = 1e-7


def test_the_geometry_parameters_are_named_as_px4_names_them_and_come_last():
    names = [p.name for p in fw.param_table()]
    assert names[-len(GEOMETRY_NAMES):] == GEOMETRY_NAMES
    assert all(len(n) <= 16 for n in names)


def test_the_default_parameters_are_the_mixers_vehicle():
    params, mixer = fw.params_geometry(), fw.canted_arms_geometry()
    assert params.count == mixer.count == 5
    assert params.hover_thrust_n == mixer.hover_thrust_n
    for p, m in zip(params.rotors, mixer.rotors):
        np.testing.assert_allclose(p.position_m, m.position_m, rtol=0, atol=GEOMETRY_TOL)
        np.testing.assert_allclose(p.axis, m.axis, rtol=0, atol=GEOMETRY_TOL)
        assert p.max_thrust_n == m.max_thrust_n
        assert p.moment_ratio_m == m.moment_ratio_m
    assert params.rotors[0].spin == 1                  # the central torque: nose right


def test_km_signs_the_spin_as_px4s_does():
    g = fw.params_geometry({"CA_ROTOR1_KM": -0.01, "CA_ROTOR2_KM": 0.02})
    assert (g.rotors[1].spin, g.rotors[1].moment_ratio_m) == (-1, pytest.approx(0.01))
    assert (g.rotors[2].spin, g.rotors[2].moment_ratio_m) == (1, pytest.approx(0.02))


def _six_rotors():
    """The default vehicle with a sixth rotor: upright, 9 N, behind and to the right."""
    return {"CA_ROTOR_COUNT": 6, "CA_ROTOR5_PX": -0.2, "CA_ROTOR5_PY": 0.2,
            "CA_ROTOR5_CT": 9.0}


def test_a_sixth_rotor_takes_its_share_of_each_command():
    a = fw.Allocation(fw.params_geometry(_six_rotors()))
    assert a.ok and a.count == 6
    b, alloc = np.array(a.effectiveness), np.array(a.allocation)
    np.testing.assert_allclose(b @ alloc, np.diag(a.units), rtol=0, atol=1e-5 * max(a.units))
    assert abs(alloc[5, 1]) > 0.01 and abs(alloc[5, 2]) > 0.01     # roll and pitch


def test_the_geometry_changes_only_while_disarmed(client):
    client.hover()
    m, _ = client.set("CA_ROTOR1_CT", 8.0)
    assert m.param_value == 9.0
    client.text("CA_ROTOR1_CT changes only while disarmed")


def _arm(client):
    """An arm command from a live station with the arm switch high and the throttle low:
    its COMMAND_ACK's result."""
    client.heartbeat()
    client.rc[4] = 2000
    client.step(20)
    client.heartbeat()
    return client.command(MAV.MAV_CMD_COMPONENT_ARM_DISARM, 1).result


def test_a_geometry_the_allocation_refuses_is_said_and_keeps_the_motors_off(client):
    client.set("CA_ROTOR2_CT", 0.0)                    # the right arm rotor gives no thrust
    client.text("allocation: rotor 2 max thrust not positive")
    assert _arm(client) != MAV.MAV_RESULT_ACCEPTED
    client.text("arming refused: vehicle geometry refused")
    client.set("CA_ROTOR2_CT", 9.0)
    assert _arm(client) == MAV.MAV_RESULT_ACCEPTED


def test_a_vehicle_without_yaw_authority_is_refused(client):
    """Arms straight up and a central rotor without reaction torque: nothing makes yaw."""
    for n in range(1, 5):
        client.set(f"CA_ROTOR{n}_AX", 0.0)
        client.set(f"CA_ROTOR{n}_AY", 0.0)
        client.set(f"CA_ROTOR{n}_AZ", -1.0)
    client.set("CA_ROTOR0_KM", 0.0)
    client.text("allocation: no yaw moment")
    assert _arm(client) != MAV.MAV_RESULT_ACCEPTED


def test_a_stored_geometry_the_allocation_refuses_keeps_the_motors_off_after_a_restart(tmp_path):
    store = _stored(tmp_path, CA_ROTOR3_AZ=0.5)         # an axis no longer of unit length
    with start("host", params_file=str(store)) as board:
        c = Client(board)
        c.text("allocation: rotor 3 axis not a unit vector", frames=20)
        assert _arm(c) != MAV.MAV_RESULT_ACCEPTED
        c.close()
