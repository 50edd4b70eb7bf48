"""``heliquad verify`` as a user runs it: on the simulated rig, wrong predictions rejected
with one line per failed loop and the previous gains left in the board's parameter store
(read back by ``heliquad params`` from a ``heliquad board`` on that store); a real-time
board over its port accepting predictions that hold; Ctrl-C restoring the previous gains;
bad input refused in one line."""

from __future__ import annotations

import json
import os
import pathlib
import shutil
import signal
import subprocess
import sys

import pytest

from heliquad.host.records.gains import firmware_gains
from heliquad.host.records.verify import read_verify

from tool_runs import HANG_GUARD_S, Tool, board_process, children, one_line, running_board, wait_for
from tune_fixture import reduced_gains, write_tune_dir

SPEC = {"phase_margin_deg": 30.0, "gain_margin_db": 3.0}


def heliquad(*args, cwd=None):
    return subprocess.run([sys.executable, "-m", "heliquad.host.cli.parser", *map(str, args)],
                          capture_output=True, text=True, cwd=cwd, timeout=HANG_GUARD_S)


def test_wrong_predictions_are_rejected_and_the_board_keeps_its_previous_gains(tmp_path):
    folder = write_tune_dir(tmp_path / "tuned", {"roll": reduced_gains("roll", 0.6)},
                            wrong_gain=2.0, spec=SPEC)
    store = tmp_path / "params.bin"
    res = heliquad("verify", "--sil", folder, "--rig-time", "3", "--param-store", store)
    assert res.returncode == 1, res.stderr
    lines = res.stderr.strip().splitlines()
    assert [line.split(": ")[1] for line in lines] == ["roll rate loop", "roll angle loop",
                                                       "rejected"], lines
    assert lines[-1].endswith("the board holds its previous gains")
    entry = read_verify(folder / "verify.json").axes["roll"]
    assert (entry["verdict"], entry["board_holds"]) == ("rejected", "previous")
    assert (folder / "previous.params").read_text().count("RATE_RLL_KC\t2.422\t") == 1
    with running_board(tmp_path, "--plant", "vehicle", "--param-store", store) as port:
        got = heliquad("params", "--port", port, "get", "RATE_RLL_KC")
    assert got.returncode == 0, got.stderr
    assert got.stdout.split()[-1] == f"{firmware_gains('roll').rate[0]:g}"


def test_a_board_on_its_port_accepts_predictions_that_hold(tmp_path):
    folder = _copy(("yaw",), tmp_path / "tuned")
    with running_board(tmp_path, "--plant", "vehicle", "--axis", "yaw") as port:
        res = heliquad("verify", "--port", port, folder, "--rig-time", "10")
        got = heliquad("params", "--port", port, "get", "RATE_YAW_KC")
    assert res.returncode == 0, res.stderr
    assert res.stdout.strip().splitlines()[-1].startswith("accepted: the tuned yaw gains")
    entry = read_verify(folder / "verify.json").axes["yaw"]
    assert entry["board"] == f"port {port}" and "truth" not in entry["loops"]["rate"]
    assert float(got.stdout.split()[-1]) == pytest.approx(reduced_gains("yaw", 0.6).rate[0],
                                                          rel=1e-6)


def test_ctrl_c_during_a_sweep_restores_the_previous_gains(tmp_path):
    folder = _copy(("roll",), tmp_path / "tuned")
    tool = Tool("verify", "--sil", folder, "--rig-time", "600", tmpdir=tmp_path)
    try:
        wait_for(lambda: "setpoint sweep" in tool.readline(), "the first sweep", tool.proc)
        wait_for(lambda: (folder / "verify/roll/rate/manifest.json").exists(), "its manifest",
                 tool.proc)
        tool.ctrl_c()
        code, _, err = tool.finish()
    finally:
        tool.kill()
    assert code == 130, err
    assert one_line(err) == ("heliquad verify: the sweep stopped: interrupted (Ctrl-C); the "
                             "board holds its previous gains")
    entry = read_verify(folder / "verify.json").axes["roll"]
    assert (entry["verdict"], entry["board_holds"]) == ("unfinished", "previous")
    assert entry["restored"]["RATE_RLL_KC"] == pytest.approx(firmware_gains("roll").rate[0])


#: Tune folders written once for the module (their predictions take seconds), by axes.
_WRITTEN: dict = {}


@pytest.fixture(autouse=True, scope="module")
def _fixtures_folder(tmp_path_factory):
    _WRITTEN["base"] = tmp_path_factory.mktemp("tuned")
    yield
    _WRITTEN.clear()


def _copy(axes: tuple, folder) -> pathlib.Path:
    """A copy of the tune folder for ``axes`` (tuned gains: the paper's rate Kc times 0.6)."""
    if axes not in _WRITTEN:
        _WRITTEN[axes] = write_tune_dir(_WRITTEN["base"] / "-".join(axes),
                                        {a: reduced_gains(a, 0.6) for a in axes}, spec=SPEC)
    shutil.copytree(_WRITTEN[axes], folder)
    return folder


def _two_axes(folder):
    return _copy(("roll", "yaw"), folder)


def _without(axis: str, loop: str):
    """A tune folder whose tune.json lacks the tuned ``loop``'s prediction of ``axis``."""
    def make(folder):
        folder = _copy((axis,), folder)
        doc = json.loads((folder / "tune.json").read_text())
        del doc["axes"][axis]["tuned"]["loops"][loop]
        (folder / "tune.json").write_text(json.dumps(doc))
        return folder
    return make


def _disagreeing(folder):
    folder = _copy(("yaw",), folder)
    path = folder / "tuned.params"
    path.write_text(path.read_text().replace("RATE_YAW_KC\t4.4358", "RATE_YAW_KC\t5"))
    return folder


@pytest.mark.parametrize("make, args, says", [
    (lambda f: f, [], "is not a folder"),
    (lambda f: (f.mkdir(), f)[1], [], "has no tune.json"),
    (_without("yaw", "rate"), [], "tune.json"),
    (_disagreeing, [], "RATE_YAW_KC is 5.0, tune.json says 4.4358"),
    (_without("roll", "angle"), [], "tune.json has no prediction of the tuned roll angle loop"),
    (_two_axes, [], "tunes roll, yaw: give --axis"),
    (_two_axes, ["--axis", "pitch"], "--axis pitch"),
    (_two_axes, ["--axis", "roll", "--port", "/dev/null"], None),
])
def test_bad_input_is_refused_in_one_line(tmp_path, make, args, says):
    folder = make(tmp_path / "tuned")
    where = [] if "--port" in args else ["--sil"]
    if says is None:               # --port and --sil's --param-store together
        args, says = [*args, "--param-store", tmp_path / "p"], "need --sil"
    res = heliquad("verify", *where, folder, *args)
    assert res.returncode == 2, res.stderr
    line = one_line(res.stderr)
    assert line.startswith("heliquad verify: error: ") and says in line, line
    assert not (tmp_path / "tuned" / "verify").exists()


def test_a_board_that_goes_away_mid_sweep_is_said_with_the_gains_it_holds(tmp_path):
    """The board's process killed (a cable pulled): nothing can be restored, and the line
    says the board holds the tuned gains, read back before the sweep."""
    folder = _copy(("yaw",), tmp_path / "tuned")
    with board_process(tmp_path, "--plant", "vehicle", "--axis", "yaw") as board:
        tool = Tool("verify", "--port", tmp_path / "rig", folder, "--rig-time", "600",
                    tmpdir=tmp_path)
        try:
            wait_for(lambda: "setpoint sweep" in tool.readline(), "the sweep", tool.proc)
            for pid in [board.pid, *children(board.pid)]:   # gone at once, its port too
                os.kill(pid, signal.SIGKILL)
            code, _, err = tool.finish()
        finally:
            tool.kill()
    assert code == 1, err
    line = one_line(err)
    assert line.startswith("heliquad verify: ") and line.endswith(
        "; the board holds the tuned gains"), line
    entry = read_verify(folder / "verify.json").axes["yaw"]
    assert (entry["verdict"], entry["board_holds"], entry["restored"]) == \
        ("unfinished", "tuned", None)


def test_a_parameter_the_board_refuses_ends_the_run_with_the_previous_gains_back(tmp_path):
    folder = write_tune_dir(tmp_path / "tuned", {"yaw": reduced_gains("yaw", 8.0)}, spec=SPEC)
    res = heliquad("verify", "--sil", folder)           # RATE_YAW_KC 59: its range ends at 50
    assert res.returncode == 1, res.stderr
    line = one_line(res.stderr)
    assert line.startswith("heliquad verify: error: the board refused RATE_YAW_KC = 59.1") and \
        line.endswith("; the board holds its previous gains"), line
    entry = read_verify(folder / "verify.json").axes["yaw"]
    assert (entry["verdict"], entry["board_holds"]) == ("unfinished", "previous")
    assert entry["restored"]["RATE_YAW_KC"] == pytest.approx(firmware_gains("yaw").rate[0])


def test_sine_dwells_measure_the_loop_as_well(tmp_path):
    folder = _copy(("yaw",), tmp_path / "tuned")
    res = heliquad("verify", "--sil", folder, "--signal", "dwell", "--lines", "6",
                   "--cycles", "6")
    assert res.returncode == 0, res.stderr
    entry = read_verify(folder / "verify.json").axes["yaw"]
    manifest = json.loads((folder / "verify/yaw/rate/manifest.json").read_text())
    assert manifest["signal"] == "dwell" and len(manifest["frequencies"]) == 6
    low, high = entry["band_rad_s"]["rate"]
    predicted = entry["loops"]["rate"]["predicted"]
    assert low == pytest.approx(0.5 * predicted["gain_crossover_rad_s"])
    assert high > predicted["phase_crossover_rad_s"]
