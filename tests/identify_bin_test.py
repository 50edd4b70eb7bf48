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

from heliquad.host.campaign.bin_sweep import bin_sweep, log_sweep
from heliquad.host.records.bin_log import BinDamage, BinLog
from heliquad.host.records.manifest import read_manifest
from heliquad.host.records.models import read_models_json
from heliquad.host.records.points import read_points_csv
from heliquad.host.records.tlog import message_dtype
from heliquad.sim.base.dialect import AXES, INJECTIONS, dialect
from heliquad.sim.base.errors import InputError
from fat32_image import Fat32Image

#: A guard against a hang, never a measure.
GUARD_S = 300.0
#: The same samples through the same code: equal but for the last bits of a double.
POINT_REL = 1e-12
#: The recommended models' responses over the band: within these.
MODEL_DB, MODEL_DEG = 0.5, 3.0
#: The sweeps: a short dwell (3 frequencies, 4 cycles), a multisine of 6 lines and a 12 s
#: chirp (its SIDD.F the frequency of each loop, as ArduPilot's).
DWELL = ("--freqs-hz", 2, 4, 8, "--cycles", 4)
MULTISINE = ("--signal", "multisine", "--lines", 6, "--freqs-hz", 1, 8, "--rig-time", 12)
CHIRP = ("--signal", "chirp", "--freqs-hz", 1, 8, "--rig-time", 12)
#: A linearity campaign of two realisations at each of its two peaks.
LINEARITY = ("--signal", "multisine", "--linearity", 2)
#: A card busy for 100 ms once a second: the ring (about 83 ms) overflows for about 17 ms,
#: loops are missing from the log (HQGP), under the 5 % a record may lose wherever the busy
#: spells fall (the 8 Hz dwell's 94 samples can hold one whole spell's losses: 120 ms, with
#: the log's longer header of 118 parameters moving the spells, lost 6 % of them).
BUSY = "busy_every_us=1000000,busy_for_us=100000"
#: The manifest's keys of a measured frequency that the log gives back exactly.
SAME_KEYS = ("freq_hz", "period_samples", "start_us", "end_us", "samples", "status",
             "signal", "orders", "saturated", "collective_limited", "sensor_clipped",
             "stop_hz", "sweep_s", "law", "sweep_samples")


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
    for name, args in (("dwell", DWELL), ("multisine", MULTISINE), ("chirp", CHIRP),
                       ("busy", (*DWELL, "--sd-faults", BUSY)), ("linearity", LINEARITY)):
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


@pytest.mark.parametrize("name", ["dwell", "multisine", "chirp"])
def test_the_bin_gives_the_sweeps_points_and_model(runs, name):
    sweep, board, said = runs[name]
    assert f"in {board}" in said.stdout and not said.stderr
    a, b = read_points_csv(sweep / "points.csv"), read_points_csv(board / "points.csv")
    assert len(a) == len(b) >= {"dwell": 3, "multisine": 6, "chirp": 20}[name]
    for p, q in zip(a, b):
        assert q.omega_rad_s == p.omega_rad_s
        assert abs(q.gain - p.gain) <= POINT_REL * abs(p.gain)
        assert q.sigma == pytest.approx(p.sigma, rel=POINT_REL)
        assert q.coherence == pytest.approx(p.coherence, rel=POINT_REL)
    assert_models_agree(sweep, board)
    models = read_models_json(board / "models.json")
    assert models.gains == read_manifest(sweep / "manifest.json")["gains"]   # from PARM
    assert models.log["skipped_bytes"] == 0


@pytest.mark.parametrize("name", ["dwell", "multisine", "chirp"])
def test_the_log_gives_back_the_manifests_experiment(runs, name):
    """Each measured frequency's window, period and lines (a multisine's, found from its
    logged excitation), or a chirp's ends, sweep and law (from SIDS and SIDD.F), are the
    manifest's."""
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


def test_a_linearity_campaigns_log_is_read_as_the_campaign(runs):
    # its realisations told apart by their phases (read from the logged excitation) and
    # their peaks, none superseded: the verdicts are the telemetry log's, number for number
    sweep, board, said = runs["linearity"]
    want = read_models_json(sweep / "models.json").linearity
    got = read_models_json(board / "models.json").linearity
    assert got is not None and "linearity at peak 0.25" in said.stdout
    assert [level["peak"] for level in got["levels"]] == [1.0, 0.25]
    for a, b in zip(want["levels"], got["levels"]):
        assert b["realisations"] == a["realisations"] == 2
        assert b["distortion_db"] == pytest.approx(a["distortion_db"], rel=POINT_REL)
        assert b["noise_db"] == pytest.approx(a["noise_db"], rel=POINT_REL)
        assert b["flagged"] == a["flagged"]
    manifest = read_manifest(sweep / "manifest.json")
    found, _, _ = bin_sweep(next(board.glob("*.BIN")))
    for e, f in zip(manifest["frequencies"], found["frequencies"]):
        assert (f["level"], f["realisation"]) == (e["level"], e["realisation"])
        assert np.allclose(np.exp(1j * np.array(f["phases_rad"])),
                           np.exp(1j * np.array(e["phases_rad"])), atol=1e-4)


def test_the_same_multisine_flown_again_is_not_a_linearity_campaign():
    from heliquad.host.campaign.bin_sweep import _linearity

    def entry(amplitude, phases):
        return {"status": "ok", "signal": "multisine", "freq_hz": 0.1, "orders": [1, 3],
                "amplitude": amplitude, "phases_rad": phases}

    again = [entry(a, [0.3, 1.2]) for a in (1.0, 0.25, 1.0, 0.25)]
    assert _linearity(again) is None                   # each peak's two are one multisine
    campaign = [entry(1.0, [0.3, 1.2]), entry(0.25, [2.0, 0.1]), entry(1.0, [1.9, 2.5]),
                entry(0.25, [0.7, 3.0])]
    assert _linearity(campaign)["linearity"]["peaks"] == [1.0, 0.25]
    assert [(e["level"], e["realisation"]) for e in campaign] == [(0, 0), (1, 0), (0, 1), (1, 1)]
    assert _linearity(campaign[:3]) is None            # one realisation at the small peak


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


# --- the excitations found in a log, on logs made here -------------------------------------

#: A made log's loop period, us, and the first loop's number.
LOOP_US, FIRST_SEQ = 5000, 100


def made_log(*excitations, idle=20, drop=(), axes=None):
    """A log of ``excitations``, each ``(base Hz, {harmonic: amplitude}, fade loops, full
    loops, end)`` with ``end`` "fade" (faded out) or "stop" (idle at once, half-way), idle
    loops before and after each; the loops at the indexes ``drop`` are missing (a gap)."""
    mav = dialect()
    state = {"idle": mav.HQ_EXCITATION_STATE_IDLE, "fade": mav.HQ_EXCITATION_STATE_FADING,
             "run": mav.HQ_EXCITATION_STATE_RUNNING}
    loops, setups = [], []                  # (state, excitation, time into it s, F)
    for i, (f, lines, fade, full, end) in enumerate(excitations):
        loops += [("idle", 0.0, 0.0, 0.0)] * idle
        period = round(1e6 / LOOP_US / f)
        setups.append({"TimeUS": (FIRST_SEQ + len(loops)) * LOOP_US, "Ax": 10, "Mag": 0.1,
                       "FSt": f * min(lines), "FSp": f * max(lines), "TFin": fade * 5e-3,
                       "TC": full * 5e-3, "TR": (2 * fade + full) * 5e-3,
                       "TFout": fade * 5e-3})
        parts = ["fade"] * fade + ["run"] * (full if end == "fade" else full // 2) + \
            (["fade"] * fade if end == "fade" else [])
        loops += [(p, sum(a * math.sin(2 * math.pi * h * k / period + h)
                          for h, a in lines.items()), k * LOOP_US * 1e-6, f)
                  for k, p in enumerate(parts)]
    loops += [("idle", 0.0, 0.0, 0.0)] * idle
    keep = [k for k in range(len(loops)) if k not in set(drop)]
    rows = np.zeros(len(keep), dtype=message_dtype(mav, "HQ_SYSID_SAMPLE")).view(np.recarray)
    rows.seq = FIRST_SEQ + np.array(keep)
    rows.time_us = rows.seq * LOOP_US
    rows.axis = AXES["roll"] if axes is None else [axes[k % len(axes)] for k in keep]
    rows.injection, rows.armed = INJECTIONS["mixer"], 1
    rows.exc_state = [state[loops[k][0]] for k in keep]
    rows.excitation = [loops[k][1] for k in keep]
    return BinLog(rows, np.array([loops[k][2] for k in keep]),
                  np.array([loops[k][3] for k in keep], dtype=np.float32).astype(float),
                  setups, {}, [], BinDamage(size=1))


def test_an_excitation_stopped_or_measured_again_is_not_used():
    sine = {1: 0.1}
    manifest, _, _ = log_sweep(made_log((4, sine, 100, 200, "fade"), (8, sine, 50, 200, "stop"),
                                        (4, sine, 100, 300, "fade")), "made.BIN")
    first, stopped, again = manifest["frequencies"]
    assert first["status"].startswith("superseded: measured again later")
    assert stopped["status"] == "not whole in the log: it was stopped before its fade-out"
    assert again["status"] == "ok" and again["samples"] == 300 and again["lost"] == 0
    assert (again["freq_hz"], again["period_samples"]) == (4.0, 50) and "orders" not in again
    assert manifest["complete"] is False and manifest["aborted"].startswith("8 Hz not whole")


def test_a_multisines_lines_are_read_from_its_excitation():
    lines = {2: 0.05, 3: 0.04, 5: 0.03, 9: 0.002}
    manifest, _, _ = log_sweep(made_log((1, lines, 200, 800, "fade")), "made.BIN")
    (entry,) = manifest["frequencies"]
    assert entry["signal"] == manifest["signal"] == "multisine"
    assert entry["orders"] == [2, 3, 5, 9] and entry["period_samples"] == 200
    assert entry["fade_samples"] == 200 and entry["samples"] == 800


def test_loops_missing_are_lost_inside_and_at_the_edges_of_the_window():
    """Idle 20 loops, fade-in 100: the window's first loop is loop 120."""
    log = made_log((4, {1: 0.1}, 100, 200, "fade"), drop=(120, 121, 200, 201, 202))
    (entry,) = log_sweep(log, "made.BIN")[0]["frequencies"]
    assert entry["status"] == "ok" and (entry["samples"], entry["lost"]) == (195, 5)
    assert entry["start_us"] == (FIRST_SEQ + 122) * LOOP_US


@pytest.mark.parametrize("log, says", [
    (made_log(), "no excitation in the log"),
    (made_log((4, {1: 0.1}, 100, 200, "fade"), axes=(AXES["roll"], AXES["pitch"])),
     "identify takes one axis"),
])
def test_a_log_with_no_or_more_than_one_axis_excited_is_refused(log, says):
    with pytest.raises(InputError, match=says):
        log_sweep(log, "made.BIN")
