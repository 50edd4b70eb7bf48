"""The paper's rig day with no computer on the rig, on the Teensy image in the emulated chip:
``heliquad program set`` stores a roll sweep on the board; then the board flies the simulated
rig with nobody on its telemetry port (the pty is never opened) while the simulated pilot
arms, raises the throttle and holds channel 7 high: the program runs from the board's own
flash and the board logs it on its SD card; after the disarm, ``heliquad logs download``
and MAVProxy's ``log list`` / ``log download`` fetch the same bytes, and the log holds the
program's every step and says it finished; ``heliquad identify`` on the .BIN gives the model a
sweep of the same design driven by the host gives (docs/sd-card.md, docs/safety.md).

Every wait is for a condition (frames of the emulated time, a tool's exit or output), bounded
by a guard against a hang."""

from __future__ import annotations

import os
import subprocess
import sys

import numpy as np
import pytest

from fat32_image import Fat32Image
from ground_stations_test import MavProxy
from heliquad.sim.base.firmware_facts import MAX_PTY_BACKLOG_BYTES
from heliquad.sim.rig.driver import Rig
from heliquad.sim.rig.rc_script import parse_rc_script
from heliquad.sim.rig.setup import LOOP_RATE_HZ, SilConfig, make_plant
from identify_bin_test import assert_models_agree
from onboard_log_test import log_records
from tool_runs import running_board

#: A guard against a hang, never a measure.
GUARD_S = 600.0
#: The program: a roll dwell at the mixer over the plant's band, few cycles (a short test).
FREQS_HZ = (0.5, 1.0, 2.0, 4.0, 8.0)
CYCLES = 4
AMPLITUDE = 0.1
DESIGN = ("--axis", "roll", "--freqs-hz", *FREQS_HZ, "--cycles", CYCLES, "--amplitude", AMPLITUDE)
#: The pilot: armed with channel 7 low, the throttle up, then channel 7 high (its edge
#: starts the program) and held; the arm switch down at DISARM_S.
PROGRAM_START_S = 1.0
DISARM_S = 40.0
SCRIPT = f"0.2 5=2000 7=1000\n0.4 3=1400\n{PROGRAM_START_S} 7=2000\n{DISARM_S} 5=1000 3=1000\n"
#: Frames flown after the disarm: the log's end reaches the card in the loop's spare time.
AFTER_DISARM_S = 1.5


def heliquad(*args):
    return subprocess.run([sys.executable, "-m", "heliquad.host.cli.parser", *map(str, args)],
                          capture_output=True, text=True, timeout=GUARD_S)


def _program_duration_s(show: str) -> float:
    """The stored program's length from ``heliquad program show``'s lines: each step's
    measured cycles and two fades at its frequency."""
    total = 0.0
    for line in show.splitlines():
        words = line.split()
        if "sine" not in words:
            continue
        f = float(words[words.index("sine") + 1])
        cycles = int(words[words.index("cycles,") - 1])
        fade = int(words[words.index("fade") + 1])
        total += (cycles + 2 * fade) / f
    return total


def _fly_with_no_host(store, card, seconds: float) -> None:
    """The Teensy image on the roll rig (the transfer-function plant) for ``seconds`` of
    emulated time with the pilot's SCRIPT; its telemetry pty is made and never opened (what
    nobody reads is dropped past a board's buffer, as ``heliquad board`` has it)."""
    cfg = SilConfig(firmware="teensy35")
    script = parse_rc_script(SCRIPT)
    frames = int(round(seconds * LOOP_RATE_HZ))
    with Rig(lambda dt_s: make_plant(cfg, dt_s), "teensy35", params_file=str(store),
             sd_image=str(card), telemetry_backlog_bytes=MAX_PTY_BACKLOG_BYTES) as rig:
        for frame in range(1, frames + 1):     # one at a time: each asks for its sensor
            rig.advance(1, script.rows(frame, 1, LOOP_RATE_HZ))
        assert rig.reply is not None and not rig.reply.armed


@pytest.fixture(scope="module")
def rig_day(tmp_path_factory):
    """The program stored over a disarmed board, flown with no host, the log downloaded by
    heliquad logs: (folder, card, the program's show text)."""
    tmp = tmp_path_factory.mktemp("rigday")
    store, card = tmp / "board.params", tmp / "card.img"
    with running_board(tmp, "--firmware", "teensy35", "--disarmed",
                       "--param-store", store) as board:
        res = heliquad("program", "--port", board, "set", *DESIGN)
        assert res.returncode == 0, res.stdout + res.stderr
        show = heliquad("program", "--port", board, "show")
        assert show.returncode == 0, show.stdout + show.stderr
    assert (tmp / "board.params.program").stat().st_size == 8192    # its two flash sectors
    assert _program_duration_s(show.stdout) < DISARM_S - PROGRAM_START_S - 1.0
    _fly_with_no_host(store, card, DISARM_S + AFTER_DISARM_S)
    with running_board(tmp, "--firmware", "teensy35", "--disarmed", "--sd-image", card) as board:
        res = heliquad("logs", "--port", board, "list")
        assert res.returncode == 0, res.stdout + res.stderr
        res = heliquad("logs", "--port", board, "download", 1, "--out", tmp / "got.BIN")
        assert res.returncode == 0, res.stdout + res.stderr
    return tmp, card, show.stdout


@pytest.fixture(scope="module")
def identified(rig_day):
    """heliquad identify on the downloaded .BIN (in a folder of its own), and on a sweep of the
    same design driven by the host on the same rig: (the .BIN's folder, the sweep's)."""
    tmp = rig_day[0]
    board = tmp / "board"
    board.mkdir()
    (board / "00000001.BIN").write_bytes((tmp / "got.BIN").read_bytes())
    res = heliquad("identify", board / "00000001.BIN")
    assert res.returncode == 0, res.stdout + res.stderr
    res = heliquad("sweep", "--sil", "--firmware", "teensy35", "--plant", "tf", *DESIGN,
                   "--out", tmp / "host")
    assert res.returncode == 0, res.stdout + res.stderr
    res = heliquad("identify", tmp / "host")
    assert res.returncode == 0, res.stdout + res.stderr
    return board, tmp / "host"


def test_the_program_ran_from_channel_7_with_no_host_and_the_card_logged_it(rig_day):
    tmp, card, show = rig_day
    steps = [line.split() for line in show.splitlines() if "sine" in line.split()]
    assert [w[w.index("sine") + 1] for w in steps] == [f"{f:g}" for f in FREQS_HZ]
    assert Fat32Image(card).listdir("LOGS") == ["00000001.BIN"]
    records = log_records(tmp / "got.BIN")
    texts = [m.Message for m in records if m.get_type() == "MSG"]
    assert "program started by channel 7" in texts
    assert "program finished: every step ran" in texts
    sids = [m for m in records if m.get_type() == "SIDS"]
    assert [round(m.FSt, 3) for m in sids] == list(FREQS_HZ)
    hqsd = [m for m in records if m.get_type() == "HQSD"]
    seqs = [m.Seq for m in hqsd]
    assert seqs == list(range(seqs[0], seqs[0] + len(seqs))), "a loop missing in the log"
    assert not [m for m in records if m.get_type() == "HQGP"]
    # every step excited the rig: in each SIDS window the roll rate has a line at the step's
    # frequency, five times what it has between harmonics (at 1.5 f)
    starts = [m.TimeUS for m in sids] + [hqsd[-1].TimeUS + 1]
    for f, a, b in zip(FREQS_HZ, starts, starts[1:]):
        window = [(m.TimeUS * 1e-6, m.Rate) for m in hqsd if a <= m.TimeUS < b and m.ESt]
        t, rate = np.array(window).T
        assert _line(t, rate, f) > 5 * _line(t, rate, 1.5 * f), f


def _line(t, x, f_hz) -> float:
    """The amplitude of ``x`` (sampled at ``t``) at ``f_hz``: its projection on a sine and a
    cosine."""
    phase = 2 * np.pi * f_hz * t
    x = x - x.mean()
    return 2 * abs(np.mean(x * np.exp(-1j * phase)))


def test_heliquad_logs_and_mavproxy_fetch_the_bytes_on_the_card(rig_day):
    tmp, card, _ = rig_day
    on_card = Fat32Image(card).read("LOGS/00000001.BIN")
    assert (tmp / "got.BIN").read_bytes() == on_card
    with running_board(tmp, "--firmware", "teensy35", "--disarmed", "--sd-image", card) as board:
        class Port:                                # what MavProxy reads of a board
            device = os.path.realpath(board)
        mp = MavProxy(Port, tmp)
        try:
            mp.expect("Detected vehicle")
            mp.type("log list")
            mp.expect(rf"Log 1\s+numLogs 1 lastLog 1 size {len(on_card)}")
            out = tmp / "mavproxy1.bin"
            mp.type(f"log download 1 {out}")
            mp.expect(rf"Finished downloading {out}")
            assert out.read_bytes() == on_card
        finally:
            mp.close()


def test_identify_on_the_bin_gives_the_model_of_a_host_driven_sweep(identified):
    """The on-board program's log and a host's sweep of the same design on the same rig: the
    recommended models agree within 0.5 dB and 3 deg over the band (two runs, the same
    deterministic rig: they differ by where each excitation starts)."""
    board, host = identified
    worst_db, worst_deg = assert_models_agree(host, board)
    print(f"on-board program against host sweep: {worst_db:.3f} dB, {worst_deg:.2f} deg")
