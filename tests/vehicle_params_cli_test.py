"""A vehicle file as the firmware's geometry parameters (``heliquad params from-vehicle``,
sim/plant/rotor_geometry.py, docs/vehicle-geometry.md): the .params file it writes holds the
file's rotors and weight as the CA_* parameters, each value exactly the single-precision
float the board keeps; the firmware's allocation, given those values, builds the
effectiveness the Python reference computes from the file; a vehicle file or a vehicle the
firmware cannot take is one line, exit 2, no file written.
"""

from __future__ import annotations

import pathlib
import re
import subprocess
import sys

import numpy as np
import pytest

from heliquad import _firmware as fw
from heliquad.host.acquire.param_protocol import FILE_VALUE_TOLERANCE, value_text
from heliquad.host.records.params_file import read_params_file
from heliquad.sim.base import firmware_facts as facts
from heliquad.sim.base.errors import InputError
from heliquad.sim.plant.rotor_geometry import (RANGES, UNUSED_ROTOR, effectiveness,
                                               firmware_geometry, geometry_params, range_of,
                                               rotor_names)
from heliquad.sim.plant.vehicle import GRAVITY_M_S2
from heliquad.sim.plant.vehicle_params import load_params

from params_cli_test import ParamBoard

ROOT = pathlib.Path(__file__).resolve().parent.parent
SHIPPED = ROOT / "sim" / "plant" / "vehicle.toml"
DATA = ROOT / "tests" / "data"
#: A [[rotors]] table's first line.
TABLE = re.compile(r"^\[\[rotors\]\]$", re.M)
#: MAV_PARAM_TYPE of whole-number and real parameters.
INT32, REAL32 = 6, 9
#: The firmware's effectiveness (float32 throughout) against the reference (double), relative
#: to each row's largest entry: a few float ulps (1.2e-7 each) of a cross product's terms
#: (measured: at most 1.4e-7, the made-up vehicle; 7.5e-8 the others).
EFFECTIVENESS_RTOL = 1e-6
#: A made-up six-rotor vehicle: rotors above and below the centre of mass, of different
#: thrusts, moment ratios and cants, spinning both ways.
MADE_UP_SIX = [
    ((0.0, 0.0, -0.04), (0.0, 0.0, -1.0), 1, 30.0, 0.02),
    ((0.3, 0.05, 0.02), (0.1, -0.2, -0.9746794), -1, 8.0, 0.008),
    ((0.1, 0.32, -0.01), (0.2, 0.05, -0.9785192), 1, 7.5, 0.009),
    ((-0.28, 0.12, 0.03), (-0.05, 0.25, -0.9669540), -1, 8.5, 0.007),
    ((-0.12, -0.3, 0.0), (-0.22, -0.1, -0.9703608), 1, 9.0, 0.0075),
    ((0.15, -0.27, 0.05), (0.0, 0.0, -1.0), -1, 6.0, 0.011),
]


def heliquad(*args, cwd=None):
    return subprocess.run([sys.executable, "-m", "heliquad.host.cli.parser", *map(str, args)],
                          capture_output=True, text=True, timeout=120, cwd=cwd)


def rotors_toml(rotors) -> str:
    """[[rotors]] tables for (position, axis, spin, max thrust, moment ratio) rows."""
    out = []
    for position, axis, spin, thrust, ratio in rotors:
        out.append(f"[[rotors]]\nposition_m = {list(position)}\nthrust_axis = {list(axis)}\n"
                   f"spin = {spin}\nmax_thrust_n = {thrust}\nmax_speed_rad_s = 2930.0\n"
                   f"torque_per_thrust_m = {ratio}\nrotor_inertia_kg_m2 = 1.2e-5\n"
                   f"time_constant_s = 0.03\n")
    return "\n".join(out)


def with_rotors(path, rotors_text: str, mass_kg: float | None = None) -> pathlib.Path:
    """The shipped vehicle file with its [[rotors]] tables replaced (and its mass), at path."""
    text = SHIPPED.read_text()
    start, end = TABLE.search(text).start(), text.index("\n[rig]")
    text = text[:start] + rotors_text + "\n" + text[end:]
    if mass_kg is not None:
        text = re.sub(r"^mass_kg = \S+", f"mass_kg = {mass_kg!r}", text, flags=re.M)
    path.write_text(text)
    return path


def from_vehicle(vehicle, tmp_path):
    """Run the command; its file's parameters as {name: (value, type)}, each value as the
    board reads it (single precision; what the protocol carries)."""
    out = tmp_path / "vehicle.params"
    res = heliquad("params", "from-vehicle", vehicle, "--out", out)
    assert res.returncode == 0, res.stderr
    assert res.stderr == "" and res.stdout.startswith(f"wrote 66 parameters to {out}")
    return {line.name: (f32(line.value), line.type) for line in read_params_file(out)}


def f32(x) -> float:
    return float(np.float32(x))


# --- the file the command writes ----------------------------------------------------------

def test_the_shipped_vehicle_as_parameters(tmp_path):
    params = from_vehicle(SHIPPED, tmp_path)
    vehicle = load_params(str(SHIPPED))
    assert params["CA_ROTOR_COUNT"] == (5, INT32)
    assert params["CA_HOVER_THRUST"] == (f32(0.930 * 9.80665), REAL32)
    assert GRAVITY_M_S2 == 9.80665                    # standard gravity, the brief's weight
    # rotor 0 is the file's first table, the central rotor, turning counter-clockwise (KM > 0)
    assert [params[n][0] for n in rotor_names(0)] == [0, 0, 0, 0, 0, -1, 25, f32(0.017)]
    # the front arm (spin 1) and the right arm (spin -1): KM signed by the spin
    front = [0.3048, 0, 0, 0, -0.3420201433256687, -0.9396926207859084, 9, 0.0076]
    right = [0, 0.3048, 0, 0.3420201433256687, 0, -0.9396926207859084, 9, -0.0076]
    assert [params[n][0] for n in rotor_names(1)] == [f32(v) for v in front]
    assert [params[n][0] for n in rotor_names(2)] == [f32(v) for v in right]
    for index, rotor in enumerate(vehicle.rotors):
        km = params[f"CA_ROTOR{index}_KM"][0]
        assert km == f32(rotor.spin * rotor.torque_per_thrust_m)
    # the slots past the count: unused rotors
    for index in range(5, fw.MAX_ROTORS):
        assert [params[n][0] for n in rotor_names(index)] == list(UNUSED_ROTOR.values())
    assert all(t == REAL32 for name, (_, t) in params.items() if name != "CA_ROTOR_COUNT")


@pytest.mark.parametrize("vehicle", [SHIPPED, DATA / "six_rotors.toml",
                                     DATA / "eight_rotors.toml"])
def test_every_value_is_the_float_the_board_keeps(vehicle, tmp_path):
    # Each value as the board reads it (single precision) is the computation's, rounded
    # once; and it is written as the shortest decimal of that float, so the board's value,
    # written again (heliquad params save), is the same text.
    params = from_vehicle(vehicle, tmp_path)
    want = {g.name: g.value for g in geometry_params(load_params(str(vehicle)))}
    assert list(params) == sorted(want)               # QGroundControl's file, by name
    lines = {line.name: line for line in read_params_file(tmp_path / "vehicle.params")}
    text = (tmp_path / "vehicle.params").read_text()
    for name, (value, ptype) in params.items():
        assert value == want[name], name
        assert f"\t{name}\t{value_text(value, ptype)}\t" in text, name
        assert abs(lines[name].value - value) <= FILE_VALUE_TOLERANCE, name
    assert "heliquad params from-vehicle" in text.splitlines()[2]
    assert re.search(r"^1\t1\tCA_ROTOR0_AZ\t-1\t9$", text, re.M)


class GeometryBoard(ParamBoard):
    """The parameter protocol's fake board (tests/params_cli_test.py) holding the geometry
    parameters in their ranges, each at an unused rotor's value, four rotors, 1 N."""

    def __init__(self):
        super().__init__()
        names = ["CA_ROTOR_COUNT", "CA_HOVER_THRUST"]
        names += [name for n in range(fw.MAX_ROTORS) for name in rotor_names(n)]
        self.names = names
        self.types = {name: INT32 if name == "CA_ROTOR_COUNT" else REAL32 for name in names}
        self.ranges = {name: range_of(name) for name in names}
        self.values = {name: UNUSED_ROTOR[name[-2:]] for name in names[2:]}
        self.values.update(CA_ROTOR_COUNT=4.0, CA_HOVER_THRUST=1.0)


def test_params_load_sets_the_file_on_a_board(tmp_path):
    params = from_vehicle(made_up_six(tmp_path), tmp_path)
    board = GeometryBoard()
    try:
        res = heliquad("params", "--port", board.port, "load", tmp_path / "vehicle.params")
        values = dict(board.values)
    finally:
        board.close()
    assert res.returncode == 0, res.stderr
    # the count, the weight and the six rotors' 48 parameters less the 9 they share with an
    # unused rotor (the central rotor's and the sixth's axes straight up, 3 each; the central
    # rotor's hub at x = y = 0, the fifth's at z = 0); so are the unused slots' 16
    assert "loading 66 parameters" in res.stdout and "41 set, 25 already so, 0 refused" in \
        res.stdout, res.stdout
    assert values == {name: value for name, (value, _) in params.items()}


def test_the_ranges_are_the_firmwares_for_every_rotor():
    table = {p.name: (p.minimum, p.maximum, p.integer) for p in fw.param_table()}
    assert RANGES["CA_ROTOR_COUNT"] == (facts.MIN_ROTORS, facts.MAX_ROTORS)
    for name, (lo, hi) in RANGES.items():
        names = [name.replace("n", str(i), 1) for i in range(fw.MAX_ROTORS)] \
            if "ROTORn" in name else [name]
        for each in names:
            assert table[each][:2] == (pytest.approx(lo), pytest.approx(hi)), each
            assert table[each][2] == (name == "CA_ROTOR_COUNT"), each


def test_a_figure_below_single_precision_is_written_as_zero(tmp_path):
    rotors = [list(r) for r in MADE_UP_SIX]
    rotors[1][0] = (0.3, 1e-40, 0.02)                 # denormal in float32: the board refuses
    params = geometry_params(load_params(str(with_rotors(tmp_path / "v.toml",
                                                         rotors_toml(rotors)))))
    value = {g.name: g.value for g in params}
    assert value["CA_ROTOR1_PY"] == 0.0 and value["CA_ROTOR1_PX"] == f32(0.3)


# --- the firmware's allocation from those values ------------------------------------------

def allocation_of(params) -> fw.Allocation:
    """The firmware's allocation from the parameters {name: (value, type)}."""
    return fw.Allocation(firmware_geometry({name: value for name, (value, _) in params.items()}))


def made_up_six(tmp_path) -> pathlib.Path:
    return with_rotors(tmp_path / "made_up_six.toml", rotors_toml(MADE_UP_SIX), mass_kg=2.1)


@pytest.mark.parametrize("which", ["shipped", "made-up six", "six", "eight"])
def test_the_firmwares_effectiveness_is_the_references(which, tmp_path):
    vehicle = {"shipped": SHIPPED, "six": DATA / "six_rotors.toml",
               "eight": DATA / "eight_rotors.toml"}.get(which) or made_up_six(tmp_path)
    params = from_vehicle(vehicle, tmp_path)
    allocation = allocation_of(params)
    assert allocation.ok, allocation.reason
    got = np.array(allocation.effectiveness)
    want = effectiveness(load_params(str(vehicle)).rotors)
    assert got.shape == want.shape == (4, params["CA_ROTOR_COUNT"][0])
    scale = np.abs(want).max(axis=1, keepdims=True)
    assert np.all(np.abs(got - want) <= EFFECTIVENESS_RTOL * scale), np.abs(got - want) / scale


def test_the_reference_is_the_forces_and_moments_by_hand(tmp_path):
    # Rotor by rotor: thrust T along a at r pushes up by -a_z T and turns the body by r x a T
    # less spin km a T; here written out component by component for the made-up vehicle.
    rotors = load_params(str(made_up_six(tmp_path))).rotors
    b = effectiveness(rotors)
    for i, rotor in enumerate(rotors):
        (x, y, z), (ax, ay, az) = rotor.position_m, rotor.thrust_axis
        t, k = rotor.max_thrust_n, rotor.spin * rotor.torque_per_thrust_m
        want = [-az * t, (y * az - z * ay - k * ax) * t, (z * ax - x * az - k * ay) * t,
                (x * ay - y * ax - k * az) * t]
        np.testing.assert_allclose(b[:, i], want, rtol=1e-14, atol=1e-15)
    # the central rotor, straight up and spinning counter-clockwise: its torque turns the body
    # nose right (+yaw), and it lifts with all of its thrust
    assert b[0, 0] == 30.0 and b[3, 0] == pytest.approx(0.02 * 30.0, rel=1e-14)


def test_the_hover_the_firmware_computes_holds_the_weight(tmp_path):
    # With the parameters of the made-up vehicle, the allocation's hover thrust fractions
    # give the reference's vertical force equal to the weight and no moment.
    vehicle = load_params(str(made_up_six(tmp_path)))
    params = from_vehicle(made_up_six(tmp_path), tmp_path)
    allocation = allocation_of(params)
    wrench = effectiveness(vehicle.rotors) @ np.array(allocation.hover_fractions)
    assert wrench[0] == pytest.approx(2.1 * GRAVITY_M_S2, rel=1e-5)
    np.testing.assert_allclose(wrench[1:], 0.0, atol=1e-5)


# --- what is refused ----------------------------------------------------------------------

def rotor_edit(index: int, key: str, value: str):
    """The shipped file with one key of rotors[index] (1 = the central rotor) set to value,
    or removed when value is None."""
    def make(path):
        tables = TABLE.split(SHIPPED.read_text())
        line = re.compile(rf"^{key} = .*$", re.M)
        assert line.search(tables[index])
        tables[index] = line.sub("" if value is None else f"{key} = {value}", tables[index])
        path.write_text("[[rotors]]".join(tables))
        return path
    return make


def rotor_count(n: int):
    def make(path):
        return with_rotors(path, rotors_toml(
            [((0.1 * i, 0.05 * i, 0.0), (0.0, 0.0, -1.0), (-1) ** i, 9.0, 0.01)
             for i in range(n)]))
    return make


def not_toml(path):
    path.write_text("[body\n")
    return path


def mass(kg: float, rotors=MADE_UP_SIX):
    def make(path):
        return with_rotors(path, rotors_toml(rotors), mass_kg=kg)
    return make


#: The shipped vehicle's rotors as rows of rotors_toml.
SHIPPED_ROTORS = [(r.position_m, r.thrust_axis, r.spin, r.max_thrust_n, r.torque_per_thrust_m)
                  for r in load_params(str(SHIPPED)).rotors]


REFUSED = {
    "a rotor missing a key": (rotor_edit(3, "max_thrust_n", None),
                              "missing key rotors[3].max_thrust_n"),
    "two rotors in one place": (rotor_edit(4, "position_m", "[0.0, 0.3048, 0.0]"),
                                "rotors[4].position_m is rotors[3]'s"),
    "no thrust": (rotor_edit(2, "max_thrust_n", "0.0"), "rotors[2].max_thrust_n must be positive"),
    "a negative thrust": (rotor_edit(5, "max_thrust_n", "-9.0"),
                          "rotors[5].max_thrust_n must be positive"),
    "a bent axis": (rotor_edit(2, "thrust_axis", "[0.0, -0.5, -1.0]"),
                    "rotors[2].thrust_axis must be a unit vector"),
    "spin 2": (rotor_edit(3, "spin", "2"), "rotors[3].spin must be 1 or -1"),
    "spin 0": (rotor_edit(1, "spin", "0"), "rotors[1].spin must be 1 or -1"),
    "three rotors": (rotor_count(3), "3 [[rotors]] tables: the firmware's allocation flies "
                                     "4 to 8 rotors"),
    "nine rotors": (rotor_count(9), "9 [[rotors]] tables: a vehicle has 2 to 8 rotors"),
    "a hub beyond 2 m": (rotor_edit(5, "position_m", "[0.0, -2.5, 0.0]"),
                         "rotors[5].position_m: -2.5 m is beyond the firmware's CA_ROTOR4_PY "
                         "(-2 to 2 m)"),
    "a thrust beyond 200 N": (rotor_edit(1, "max_thrust_n", "250.0"),
                              "rotors[1].max_thrust_n: 250 N is beyond the firmware's "
                              "CA_ROTOR0_CT (0 to 200 N)"),
    "a moment ratio beyond 0.5 m": (rotor_edit(3, "torque_per_thrust_m", "0.6"),
                                    "rotors[3].torque_per_thrust_m (signed by spin): -0.6 m is "
                                    "beyond the firmware's CA_ROTOR2_KM (-0.5 to 0.5 m)"),
    "too heavy": (mass(60.0), "body.mass_kg (as the weight, mass x g): 588.399 N is beyond "
                              "the firmware's CA_HOVER_THRUST (0.5 to 500 N)"),
    "too light": (mass(0.05), "CA_HOVER_THRUST (0.5 to 500 N)"),
    "not TOML": (not_toml, "not valid TOML"),
    # what the firmware's allocation refuses, in its words
    "rotors in a line": (rotor_count(5), "the firmware cannot fly this geometry (allocation: "
                                         "pitch depends on thrust and roll)"),
    "heavier than its rotors lift": (mass(9.0, SHIPPED_ROTORS), "the firmware cannot fly this "
                                     "geometry (allocation: hover needs rotor 0 beyond 0..1)"),
}


@pytest.mark.parametrize("case", sorted(REFUSED))
def test_a_vehicle_the_firmware_cannot_take_is_one_line(case, tmp_path):
    make, says = REFUSED[case]
    vehicle = make(tmp_path / "bad.toml")
    res = heliquad("params", "from-vehicle", vehicle, "--out", tmp_path / "out.params")
    assert res.returncode == 2, res.stderr
    assert res.stdout == "" and "Traceback" not in res.stderr
    assert res.stderr.count("\n") == 1 and res.stderr.startswith("heliquad params: error: ")
    assert says in res.stderr and str(vehicle) in res.stderr, res.stderr
    assert not (tmp_path / "out.params").exists()
    with pytest.raises(InputError, match=re.escape(says)):       # the library's own word
        geometry_params(load_params(str(vehicle)))


def test_it_never_writes_over_a_file(tmp_path):
    out = tmp_path / "there.params"
    out.write_text("kept\n")
    res = heliquad("params", "from-vehicle", SHIPPED, "--out", out)
    assert res.returncode == 2 and "there.params exists: heliquad never writes over" in res.stderr
    assert out.read_text() == "kept\n"
    res = heliquad("params", "from-vehicle", SHIPPED)
    assert res.returncode == 2 and "--out" in res.stderr


def test_the_board_actions_still_want_a_port():
    res = heliquad("params", "list")
    assert res.returncode == 2 and res.stderr.count("\n") == 1
    assert res.stderr == ("heliquad params: error: the following arguments are required: "
                          "--port (see heliquad params --help)\n")


def test_the_help_names_the_action():
    res = heliquad("params", "--help")
    assert res.returncode == 0 and "from-vehicle VEHICLE.toml --out FILE" in res.stdout
