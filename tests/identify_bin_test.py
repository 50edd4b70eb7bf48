"""``heliquad identify`` on a board's on-board log (.BIN): a host-driven SIL sweep flown with
``--sd-image`` leaves its log on the card; identify turns the sweep folder and the .BIN read
from the card into the same points and models (docs/file-formats.md, "A board's log").

The .BIN holds the very loops the sweep's telemetry carried (tests/onboard_log_test.py: field
for field, the same float32 numbers), and identify finds in it the windows, periods and lines
the manifest recorded. So the points must be the same to float precision (``POINT_REL``),
whatever the plant: the same samples through the same code. Where the log misses loops (a
busy card: HQGP gaps), those are lost samples, estimated around as the tlog path does, and
the points then differ by what the missing loops carried. The recommended model is compared
by its response over the identified band (``MODEL_DB``, ``MODEL_DEG``)."""

from __future__ import annotations

import math
import subprocess
import sys

import numpy as np
import pytest

from heliquad.host.campaign.bin_sweep import bin_sweep
from heliquad.host.records.manifest import read_manifest
from heliquad.host.records.models import read_models_json
from heliquad.host.records.points import read_points_csv
from fat32_image import Fat32Image

#: A guard against a hang, never a measure.
GUARD_S = 300.0
#: The same samples through the same code: equal but for the last bits of a double.
POINT_REL = 1e-12
#: The recommended models' responses over the band: within these.
MODEL_DB, MODEL_DEG = 0.5, 3.0
#: The sweeps: a short dwell (3 frequencies, 4 cycles) and a multisine of 6 lines.
DWELL = ("--freqs-hz", 2, 4, 8, "--cycles", 4)
MULTISINE = ("--signal", "multisine", "--lines", 6, "--freqs-hz", 1, 8, "--rig-time", 12)
#: A card busy for 120 ms once a second: the ring (about 83 ms) overflows, loops are missing
#: from the log (HQGP), under the 5 % a record may lose.
BUSY = "busy_every_us=1000000,busy_for_us=120000"
#: The manifest's keys of a measured frequency that the log gives back exactly.
SAME_KEYS = ("freq_hz", "period_samples", "start_us", "end_us", "samples", "status",
             "signal", "orders", "saturated", "collective_limited", "sensor_clipped")


def heliquad(*args):
    res = subprocess.run([sys.executable, "-m", "heliquad.host.cli.parser", *map(str, args)],
                         capture_output=True, text=True, timeout=GUARD_S)
    assert res.returncode == 0, (args, res.stdout[-2000:], res.stderr[-2000:])
    return res


def flown(tmp, name, *args):
    """A SIL sweep with its card; (the sweep folder, a folder holding only the .BIN read
    from the card)."""
    card = tmp / f"{name}.img"
    heliquad("sweep", "--sil", "--axis", "roll", "--plant", "tf", *args, "--sd-image", card,
             "--out", tmp / name)
    board = tmp / f"{name}-board"
    board.mkdir()
    (board / "00000001.BIN").write_bytes(Fat32Image(card).read("LOGS/00000001.BIN"))
    return tmp / name, board


@pytest.fixture(scope="module")
def runs(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("identify_bin")
    out = {}
    for name, args in (("dwell", DWELL), ("multisine", MULTISINE),
                       ("busy", (*DWELL, "--sd-faults", BUSY))):
        sweep, board = flown(tmp, name, *args)
        heliquad("identify", sweep)
        target = board / "00000001.BIN" if name != "multisine" else board   # a file, a folder
        said = heliquad("identify", target)
        out[name] = sweep, board, said
    return out


def response(model, omega):
    s = 1j * np.asarray(omega)
    return np.polyval(model.num, s) / np.polyval(model.den, s) * np.exp(-s * model.delay_s)


def assert_models_agree(a_dir, b_dir):
    """The recommended models of both, over the band their points span."""
    a, b = read_models_json(a_dir / "models.json"), read_models_json(b_dir / "models.json")
    assert a.recommended is not None and b.recommended is not None
    omega = [p.omega_rad_s for p in read_points_csv(a_dir / "points.csv")]
    grid = np.geomspace(min(omega), max(omega), 200)
    ga, gb = response(a.models[a.recommended], grid), response(b.models[b.recommended], grid)
    worst_db = float(np.max(np.abs(20 * np.log10(np.abs(gb / ga)))))
    worst_deg = float(np.max(np.abs(np.degrees(np.angle(gb / ga)))))
    assert worst_db <= MODEL_DB and worst_deg <= MODEL_DEG, (worst_db, worst_deg)
    return worst_db, worst_deg


@pytest.mark.parametrize("name", ["dwell", "multisine"])
def test_the_bin_gives_the_sweeps_points_and_model(runs, name):
    sweep, board, said = runs[name]
    assert f"in {board}" in said.stdout and not said.stderr
    a, b = read_points_csv(sweep / "points.csv"), read_points_csv(board / "points.csv")
    assert len(a) == len(b) >= (3 if name == "dwell" else 6)
    for p, q in zip(a, b):
        assert q.omega_rad_s == p.omega_rad_s
        assert abs(q.gain - p.gain) <= POINT_REL * abs(p.gain)
        assert q.sigma == pytest.approx(p.sigma, rel=POINT_REL)
        assert q.coherence == pytest.approx(p.coherence, rel=POINT_REL)
    assert_models_agree(sweep, board)
    models = read_models_json(board / "models.json")
    assert models.gains == read_manifest(sweep / "manifest.json")["gains"]   # from PARM
    assert models.log["skipped_bytes"] == 0


@pytest.mark.parametrize("name", ["dwell", "multisine"])
def test_the_log_gives_back_the_manifests_experiment(runs, name):
    """Each measured frequency's window, period and lines (a multisine's, found from its
    logged excitation) are the manifest's."""
    sweep, board, _ = runs[name]
    manifest = read_manifest(sweep / "manifest.json")
    found, samples, damage = bin_sweep(next(board.glob("*.BIN")))
    assert not damage and found["axis"] == manifest["axis"]
    assert found["inject"] == manifest["inject"] and found["signal"] == manifest["signal"]
    measured = [e for e in manifest["frequencies"] if e["status"] == "ok"]
    assert len(found["frequencies"]) == len(measured)
    for want, got in zip(measured, found["frequencies"]):
        assert {k: got.get(k) for k in SAME_KEYS} == {k: want.get(k) for k in SAME_KEYS}
        assert got["lost"] == want["lost"] == 0


def test_loops_missing_from_the_log_are_lost_samples(runs):
    """A busy card drops loops from the log (HQGP): identify estimates around them, says
    so, and the points stay within a fraction of a dB and a degree of the sweep's."""
    sweep, board, said = runs["busy"]
    found, _, _ = bin_sweep(board / "00000001.BIN")
    lost = [e["lost"] for e in found["frequencies"]]
    assert any(lost) and all(e["status"] == "ok" for e in found["frequencies"])
    assert "were lost on the link; estimated from the rest" in said.stdout
    a, b = read_points_csv(sweep / "points.csv"), read_points_csv(board / "points.csv")
    assert [p.omega_rad_s for p in a] == [q.omega_rad_s for q in b]
    assert any(q.lost_share > 0 for q in b)
    for p, q in zip(a, b):
        assert abs(20 * math.log10(abs(q.gain) / abs(p.gain))) < 0.5
        assert abs(math.degrees(np.angle(q.gain / p.gain))) < 3.0
    assert_models_agree(sweep, board)
