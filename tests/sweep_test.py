"""Sweeps and identification end to end (issue 5): heliquad sweep + heliquad identify."""

import json
import math
import subprocess
import sys
import time

import numpy as np
import pytest

from heliquad.host import paper
from heliquad.sim.tf_plant import TfPlant


def heliquad(*args):
    return subprocess.run([sys.executable, "-m", "heliquad.host.cli", *map(str, args)],
                          capture_output=True, text=True, timeout=600)


@pytest.mark.parametrize("axis", ["roll", "pitch", "yaw"])
def test_sil_sweep_and_identify_recover_the_papers_models(axis, tmp_path):
    # The transfer-function plant set to SPEC.md's chosen model of the axis: the sweep over the
    # Table 1 band and identify recover it within 1 dB and 3 deg and recommend the same order.
    out = tmp_path / axis
    res = heliquad("sweep", "--axis", axis, "--sil", "--plant", "tf", "--out", out)
    assert res.returncode == 0, res.stdout + res.stderr
    manifest = json.loads((out / "manifest.json").read_text())
    assert manifest["complete"] and len(manifest["frequencies"]) == 15
    assert all(f["status"] == "ok" and f["samples"] > 0 for f in manifest["frequencies"])
    res = heliquad("identify", out)
    assert res.returncode == 0, res.stderr
    models = json.loads((out / "models.json").read_text())
    chosen = models["models"][models["recommended"]]
    assert tuple(chosen["order"]) == paper.CHOSEN_ORDER[axis]
    num, den = paper.MODELS[axis][paper.CHOSEN_ORDER[axis]]
    lo, hi = paper.BANDS_HZ[axis]
    w = 2 * np.pi * np.logspace(math.log10(lo), math.log10(hi), 100)
    ratio = (np.polyval(chosen["num"], 1j * w) / np.polyval(chosen["den"], 1j * w)) / \
        (np.polyval(num, 1j * w) / np.polyval(den, 1j * w))
    assert np.max(np.abs(20 * np.log10(np.abs(ratio)))) < 1.0
    assert np.max(np.abs(np.degrees(np.angle(ratio)))) < 3.0
    # the points themselves against the sampled-data truth (the loop's zero-order hold)
    pts = np.loadtxt(out / "points.csv", delimiter=",", skiprows=1)
    truth = TfPlant(axis, num, den, 0.005).truth(pts[:, 0])
    g = pts[:, 1] * np.exp(1j * pts[:, 2])
    assert np.max(np.abs(20 * np.log10(np.abs(g / truth)))) < 1.0
    assert np.max(np.abs(np.degrees(np.angle(g / truth)))) < 3.0
    for name in ("points_table.csv", "bode.png", "responses.png", "sweep.tlog"):
        assert (out / name).stat().st_size > 0


def test_sweep_over_a_port_works_against_a_free_running_board(tmp_path):
    port, out = tmp_path / "rig", tmp_path / "sweep"
    board = subprocess.Popen([sys.executable, "-m", "heliquad.host.cli", "board", "--telemetry",
                              str(port), "--duration-s", "20"], stdout=subprocess.PIPE, text=True)
    try:
        assert "board running" in board.stdout.readline()
        res = heliquad("sweep", "--axis", "roll", "--port", port, "--freqs-hz", 3, 4.5,
                       "--cycles", 3, "--out", out)
    finally:
        board.terminate()
        board.wait(timeout=20)
    assert res.returncode == 0, res.stdout + res.stderr
    manifest = json.loads((out / "manifest.json").read_text())
    assert manifest["source"]["kind"] == "port" and manifest["complete"]
    assert [round(f["freq_hz"], 3) for f in manifest["frequencies"]] == [2.985, 4.545]   # 200/67 and 200/44 Hz
    assert all(f["samples"] >= 3 * f["period_samples"] for f in manifest["frequencies"])


def test_a_limit_breach_stops_the_sweep_and_keeps_the_log(tmp_path):
    # A huge mixer amplitude on the vehicle's roll rig swings it past the 80 deg limit.
    out = tmp_path / "breach"
    res = heliquad("sweep", "--axis", "roll", "--sil", "--freqs-hz", 0.5, 1.0, "--amplitude", 3,
                   "--ideal-sensor", "--out", out)
    assert res.returncode == 1
    manifest = json.loads((out / "manifest.json").read_text())
    assert not manifest["complete"] and "limit breached" in manifest["aborted"]
    assert (out / "sweep.tlog").stat().st_size > 0


def test_identify_refuses_a_folder_that_is_not_a_sweep(tmp_path):
    res = heliquad("identify", tmp_path)
    assert res.returncode == 2 and "no manifest.json" in res.stderr
    assert len(res.stderr.strip().splitlines()) == 1


def test_ctrl_c_leaves_a_valid_log_and_manifest(tmp_path):
    import signal

    out = tmp_path / "interrupted"
    # One very slow frequency (0.03 Hz x 54 cycles: 30 min simulated, tens of seconds here),
    # interrupted once the log is being written.
    proc = subprocess.Popen([sys.executable, "-m", "heliquad.host.cli", "sweep", "--axis", "yaw",
                             "--sil", "--ideal-sensor", "--freqs-hz", "0.03", "--cycles", "50",
                             "--out", str(out)],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    tlog = out / "sweep.tlog"
    deadline = time.monotonic() + 30
    while not (tlog.exists() and tlog.stat().st_size > 0) and time.monotonic() < deadline:
        time.sleep(0.1)
    time.sleep(1.0)                                  # well inside the frequency
    proc.send_signal(signal.SIGINT)
    stdout, _ = proc.communicate(timeout=60)
    assert proc.returncode == 1
    assert "interrupted" in stdout
    manifest = json.loads((out / "manifest.json").read_text())
    assert manifest["aborted"] == "interrupted (Ctrl-C)" and not manifest["complete"]
    res = heliquad("tlog", out / "sweep.tlog")
    assert res.returncode == 0 and " 0 lost" in res.stdout and res.stderr == ""
