"""``heliquad effectiveness`` end to end on the simulated rigs (host/campaign/effectiveness.py):
per-rotor runs (``heliquad sweep --inject motors``) on the roll, pitch and yaw rigs of the
default vehicle, the axis sweeps' models to start the rigs' hinges from, then the estimate
(the hinges fitted with it, the same without the models): every
entry within 5 % of its row's largest of the simulator's truth, every time constant within
10 %, the errors over their sigmas of RMS 0.5 to 2; the fitted geometry is the vehicle's and
its geometry.params is one the firmware takes (a board loads it with heliquad params load);
too few runs and a folder that is not a
per-rotor run are refused in one line.

Runtime (2-core machine, niced): the six SIL runs and three identifies about 20 s, an
estimate 2 to 4 s; the yaw rig flown rotor by rotor (five more runs) 12 s; the whole file
about 45 s."""

import json
import math
import subprocess
import sys

import numpy as np
import pytest

from effectiveness_rig import truth
from heliquad import _firmware
from heliquad.host.records.params_file import read_params_file
from heliquad.sim.plant.vehicle import Vehicle
from heliquad.sim.plant.vehicle_params import load_params
from tool_runs import running_board

AXES = ("roll", "pitch", "yaw")
#: The acceptance: every entry within 5 % of its row's largest, every time constant within
#: 10 %, the errors over their sigmas of RMS 0.5 to 2.
ENTRY_TOLERANCE, TIME_CONSTANT_TOLERANCE, RMS_Z = 0.05, 0.10, (0.5, 2.0)


def heliquad(*args):
    return subprocess.run([sys.executable, "-m", "heliquad.host.cli.parser", *map(str, args)],
                          capture_output=True, text=True, timeout=600)


def _ok(r):
    assert r.returncode == 0, r.stdout + r.stderr
    return r


@pytest.fixture(scope="module")
def runs(tmp_path_factory):
    """Per rig: the per-rotor run folder, and the axis sweep's models.json."""
    root = tmp_path_factory.mktemp("rigs")
    out = {}
    for axis in AXES:
        rotors, sweep = root / f"{axis}-rotors", root / f"{axis}-sweep"
        _ok(heliquad("sweep", "--axis", axis, "--sil", "--inject", "motors", "--out", rotors))
        _ok(heliquad("sweep", "--axis", axis, "--sil", "--signal", "multisine", "--out", sweep))
        _ok(heliquad("identify", sweep))
        out[axis] = (rotors, sweep / "models.json")
    return out


@pytest.fixture(scope="module")
def estimate(runs, tmp_path_factory):
    out = tmp_path_factory.mktemp("est") / "effectiveness"
    r = _ok(heliquad("effectiveness", *(runs[a][0] for a in AXES), "--out", out,
                     "--axis-models", *(runs[a][1] for a in AXES)))
    return out, json.loads((out / "effectiveness.json").read_text()), r.stdout


def test_the_three_rigs_runs_find_the_vehicles_effectiveness_and_lags(estimate):
    _, doc, _ = estimate
    params = load_params()
    true_e = truth(Vehicle(params, rig="roll"))
    true_t = np.array([r.time_constant_s for r in params.rotors])
    e = np.array(doc["effectiveness_rad_s2"], dtype=float)
    sigma = np.array(doc["effectiveness_sigma_rad_s2"], dtype=float)
    t = np.array(doc["time_constant_s"], dtype=float)
    t_sigma = np.array(doc["time_constant_sigma_s"], dtype=float)
    entry = np.max(np.abs(e - true_e) / np.max(np.abs(true_e), axis=1, keepdims=True))
    assert entry < ENTRY_TOLERANCE, entry
    assert np.max(np.abs(t - true_t) / true_t) < TIME_CONSTANT_TOLERANCE, t
    z = np.concatenate([((e - true_e) / sigma).ravel(), (t - true_t) / t_sigma])
    assert RMS_Z[0] < math.sqrt(float(np.mean(z ** 2))) < RMS_Z[1], z
    # the flown geometry (the firmware's default CA_*) has the arm rotors' drag torques at 0:
    # its yaw row differs from the vehicle's, which the estimate shows
    flown = np.array(doc["flown_geometry_rad_s2"])
    assert np.max(np.abs(flown[2] - true_e[2])) > 10 * np.max(sigma[2])


def test_the_fitted_geometry_is_the_vehicles_and_the_firmware_takes_it(estimate):
    out, doc, stdout = estimate
    g = doc["geometry"]
    params = load_params()
    arm = params.rotors[1]
    cant = math.degrees(math.acos(-arm.thrust_axis[2]))
    assert abs(g["cant_deg"] - cant) < max(0.5, 4 * g["cant_sigma_deg"])
    assert g["central_torque_ratio_m"] == pytest.approx(params.rotors[0].torque_per_thrust_m,
                                                        rel=0.05)
    assert g["arm_torque_ratio_m"] == pytest.approx(arm.torque_per_thrust_m, rel=0.1)
    np.testing.assert_allclose(g["max_thrust_n"], [r.max_thrust_n for r in params.rotors],
                               rtol=0.02)
    lines = read_params_file(out / "geometry.params")
    values = {p.name: p.value for p in lines}
    allocation = _firmware.Allocation(_firmware.params_geometry(values))
    assert allocation.ok, allocation.reason
    spins = [1 if values[f"CA_ROTOR{i}_KM"] > 0 else -1 for i in range(5)]
    assert spins == [r.spin for r in params.rotors]
    assert (out / "effectiveness.png").stat().st_size > 10_000
    assert "geometry: cant" in stdout


def test_a_board_takes_the_fitted_geometry_with_heliquad_params_load(estimate, tmp_path):
    out, _, _ = estimate
    with running_board(tmp_path, "--disarmed") as port:
        r = _ok(heliquad("params", "--port", port, "load", out / "geometry.params"))
        assert "0 refused" in r.stdout
        got = _ok(heliquad("params", "--port", port, "get", "CA_ROTOR2_KM"))
    want = {p.name: p.value for p in read_params_file(out / "geometry.params")}
    assert float(got.stdout.split()[-1]) == pytest.approx(want["CA_ROTOR2_KM"], rel=1e-6)


def test_the_hinges_come_from_the_runs_themselves_the_axis_models_only_start_them(
        runs, estimate, tmp_path):
    out, doc, _ = estimate
    r = _ok(heliquad("effectiveness", *(runs[a][0] for a in AXES), "--out", tmp_path / "e"))
    free = json.loads((tmp_path / "e" / "effectiveness.json").read_text())
    assert free["axis_models"] == [] and all(
        rig["given_damping_rad_s"] == 0.0 for rig in free["rigs"].values())
    params = load_params()
    for axis, row in zip(AXES, range(3)):
        true = params.rig.hinge_damping_n_m_s_rad / params.body.inertia_kg_m2[row]
        assert doc["rigs"][axis]["damping_rad_s"] == pytest.approx(true, rel=0.3)
        assert free["rigs"][axis]["damping_rad_s"] == pytest.approx(
            doc["rigs"][axis]["damping_rad_s"], abs=1e-4)
    np.testing.assert_allclose(free["effectiveness_rad_s2"], doc["effectiveness_rad_s2"],
                               rtol=0, atol=1e-3)
    assert "geometry: cant" in r.stdout


def test_one_run_per_rotor_on_a_rig_serves_as_its_one_run(runs, tmp_path):
    """The yaw rig flown rotor by rotor (MOTORn, each rotor on every line of its own run)."""
    yaw = []
    for n in range(1, 6):
        yaw.append(tmp_path / f"yaw-motor{n}")
        _ok(heliquad("sweep", "--axis", "yaw", "--sil", "--inject", f"motor{n}", "--out",
                     yaw[-1]))
    _ok(heliquad("effectiveness", runs["roll"][0], runs["pitch"][0], *yaw, "--out",
                 tmp_path / "e"))
    doc = json.loads((tmp_path / "e" / "effectiveness.json").read_text())
    params = load_params()
    true_e = truth(Vehicle(params, rig="roll"))
    true_t = np.array([r.time_constant_s for r in params.rotors])
    e = np.array(doc["effectiveness_rad_s2"], dtype=float)
    assert np.max(np.abs(e - true_e) / np.max(np.abs(true_e), axis=1, keepdims=True)) < \
        ENTRY_TOLERANCE
    t = np.array(doc["time_constant_s"], dtype=float)
    assert np.max(np.abs(t - true_t) / true_t) < TIME_CONSTANT_TOLERANCE


def test_too_few_runs_or_a_folder_that_is_not_a_per_rotor_run_is_refused(runs, tmp_path):
    for folders, why in (([runs["roll"][0]], "every rig"),
                         ([runs["roll"][0], runs["pitch"][0]], "yaw rig"),
                         ([runs["roll"][0], runs["pitch"][0], runs["yaw"][1].parent],
                          "not a per-rotor run")):
        r = heliquad("effectiveness", *folders, "--out", tmp_path / "x")
        assert r.returncode == 2, r.stdout + r.stderr
        assert why in r.stderr and len(r.stderr.strip().splitlines()) == 1, r.stderr
        assert not (tmp_path / "x").exists()
    (tmp_path / "kept").mkdir()
    (tmp_path / "kept" / "earlier.txt").write_text("an earlier record\n")
    r = heliquad("effectiveness", *(runs[a][0] for a in AXES), "--out", tmp_path / "kept")
    assert r.returncode == 2 and "is not empty" in r.stderr, r.stderr
    assert len(r.stderr.strip().splitlines()) == 1
