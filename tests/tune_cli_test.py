"""``heliquad tune`` from the command line: the files it writes (tune.json as verify reads
it, tuned.params as params load, QGroundControl and MAVProxy read it, tune.png), what it
prints, and exit code 1 with the sweep band it needs when a band forbids the spec."""

import json
import subprocess
import sys

import numpy as np
import pytest

from heliquad.host.records.params_file import read_params_file
from heliquad.host.records.tune import read_tune

from tune_models import ROLL, ROLL_SECOND, YAW, YAW_SECOND, write_models


def heliquad(*args, cwd):
    return subprocess.run([sys.executable, "-m", "heliquad.host.cli.parser", *map(str, args)],
                          capture_output=True, text=True, cwd=cwd, timeout=300)


@pytest.fixture(scope="module")
def tuned(tmp_path_factory):
    """roll and yaw tuned once: ``(folder, the run)``."""
    where = tmp_path_factory.mktemp("tune")
    roll = write_models(where / "roll", "roll", ROLL, ROLL_SECOND)
    yaw = write_models(where / "yaw", "yaw", YAW, YAW_SECOND)
    res = heliquad("tune", roll, yaw, "--out", where / "out", cwd=where)
    return where, res


def test_tune_writes_its_files_and_says_current_against_tuned(tuned):
    where, res = tuned
    assert res.returncode == 0, res.stderr
    doc = read_tune(where / "out" / "tune.json")
    assert set(doc.axes) == {"roll", "yaw"}
    assert doc.spec["phase_margin_deg"] == 45 and doc.spec["gain_margin_db"] == 6
    for axis, entry in doc.axes.items():
        assert entry["meets_spec"]
        loops = entry["tuned"]["loops"]
        assert set(loops) == ({"rate"} if axis == "yaw" else {"rate", "angle", "input"})
        for lp in loops.values():
            assert lp["phase_margin_deg"] - lp["uncertainty"]["phase_margin_deg"] >= 45
    assert (where / "out" / "tune.png").read_bytes()[:4] == b"\x89PNG"
    for words in ("current", "tuned", "rate crossover (rad/s)", "step rise 10-90 % (s)",
                  "rate PM (deg)"):
        assert words in res.stdout


def test_tuned_params_hold_the_tuned_gains_and_only_theirs(tuned):
    where, _ = tuned
    doc = read_tune(where / "out" / "tune.json")
    lines = read_params_file(where / "out" / "tuned.params")
    assert all(line.type == 9 for line in lines)                    # REAL32, QGC's layout
    read = {line.name: line.value for line in lines}
    want = {**doc.axes["roll"]["params"], **doc.axes["yaw"]["params"]}
    assert set(read) == {"RATE_RLL_KC", "RATE_RLL_TI", "RATE_RLL_TD", "ANG_RLL_KC",
                         "ANG_RLL_TD", "RATE_YAW_KC", "RATE_YAW_TI", "RATE_YAW_TD"}
    for name, value in read.items():
        assert np.float32(value) == np.float32(want[name])
    gains = doc.axes["roll"]["tuned"]["gains"]
    assert np.float32(read["RATE_RLL_KC"]) == np.float32(gains["rate"][0])
    assert np.float32(read["ANG_RLL_TD"]) == np.float32(gains["angle"][1])


def test_mavproxy_layout_loads_in_pymavlinks_reader(tmp_path):
    from pymavlink import mavparm

    yaw = write_models(tmp_path / "yaw", "yaw", YAW, YAW_SECOND)
    res = heliquad("tune", yaw, "--out", tmp_path / "out", "--mavproxy", cwd=tmp_path)
    assert res.returncode == 0, res.stderr
    held = mavparm.MAVParmDict()
    assert held.load(str(tmp_path / "out" / "tuned.params"))
    params = json.loads((tmp_path / "out" / "tune.json").read_text())["axes"]["yaw"]["params"]
    assert set(held) == set(params)
    for name, value in params.items():
        assert abs(held[name] - value) <= 5e-7


def test_a_band_too_low_for_the_asked_crossover_exits_1_with_the_band_and_writes_nothing(
        tmp_path):
    yaw = write_models(tmp_path / "yaw", "yaw", YAW, YAW_SECOND, band=(0.94, 3.0))
    res = heliquad("tune", yaw, "--out", tmp_path / "out", "--min-crossover", 8, cwd=tmp_path)
    assert res.returncode == 1, (res.stdout, res.stderr)
    assert "the band forbids it" in res.stdout and "--freqs-hz from" in res.stdout
    top_hz = float(res.stdout.split("up to ")[-1].split(")")[0])
    assert top_hz * 2 * np.pi >= 8                       # the proposed band reaches 8 rad/s
    assert not (tmp_path / "out" / "tuned.params").exists()
    assert not (tmp_path / "out" / "tune.json").exists()
