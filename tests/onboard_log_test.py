"""The SIL logs on board, end to end (docs/sd-card.md, docs/dataflash-log.md): ``heliquad sil
--sd-image`` leaves LOGS/00000001.BIN on the card, ``heliquad logs download`` over a
``heliquad board --sd-image`` of the same card reads it out, DFReader opens it and its
samples are the run's HQ_SYSID_SAMPLE stream in the .tlog, sample for sample; the card is
clean to fsck.fat; a second arming makes 00000002.BIN. A card that holds busy for 250 ms
every second costs log records (HQGP gap records, counted), never a late loop. No card, a
write-protected and a full card: the vehicle flies a sweep and the log protocol lists no
logs."""

from __future__ import annotations

import math
import shutil
import subprocess
import sys

import pytest
from pymavlink import DFReader

from heliquad import _firmware as fw
from heliquad.host.acquire.experiment import run_sil
from heliquad.host.records.tlog import read_tlog
from heliquad.sim.base.dialect import dialect
from heliquad.sim.base.firmware_image import teensy35_image
from heliquad.sim.chip.pil.board import PilBoard
from heliquad.sim.rig.lockstep import PilFirmware
from heliquad.sim.rig.setup import SilConfig
from fat32_image import Fat32Image
from tool_runs import running_board

#: A guard against a hang, never a measure.
GUARD_S = 600.0
#: The run: a 2 Hz roll sine at the mixer, short.
SIL_ARGS = ("--freq-hz", 2, "--amplitude", 0.05, "--cycles", 4)
#: A card busy for a quarter second once a second (the host card's faults, docs/sd-card.md).
BUSY_FAULTS = {"busy_every_us": 1_000_000, "busy_for_us": 250_000}
#: The records of one loop's sample: SIDD, HQSD and HQMT, kept or dropped together.
SAMPLE_RECORDS = 3

needs_fsck = pytest.mark.skipif(shutil.which("fsck.fat") is None, reason="no fsck.fat")


def heliquad(*args, cwd=None):
    return subprocess.run([sys.executable, "-m", "heliquad.host.cli.parser", *map(str, args)],
                          capture_output=True, text=True, timeout=GUARD_S, cwd=cwd)


def log_records(path) -> list:
    log = DFReader.DFReader_binary(str(path))
    out = []
    while (m := log.recv_msg()) is not None:
        out.append(m)
    return out


def of(records, kind: str) -> list:
    return [m for m in records if m.get_type() == kind]


def telemetry_samples(tlog) -> dict:
    """The run's armed HQ_SYSID_SAMPLEs, by seq."""
    return {m.seq: m for _, m in read_tlog(str(tlog), dialect(), only=("HQ_SYSID_SAMPLE",))
            if m.armed}


def assert_samples_are_the_telemetry(records, samples: dict) -> list:
    """Every sample the log holds (SIDD, HQSD and HQMT of a loop) is the telemetry's of the
    same loop, field for field; the log's loops, in order."""
    hqsd, hqmt, sidd = of(records, "HQSD"), of(records, "HQMT"), of(records, "SIDD")
    assert len(hqsd) == len(hqmt) == len(sidd) > 0
    for h, m, d in zip(hqsd, hqmt, sidd):
        s = samples[h.Seq]
        assert h.TimeUS == m.TimeUS == d.TimeUS == s.time_us
        assert (h.Axis, h.Inj, h.ESt, h.Arm, h.Mode, h.Sat) == (
            s.axis, s.injection, s.exc_state, s.armed, s.mode, s.saturation)
        assert (h.Exc, h.ASP, h.RSP, h.Rate, h.Ang, h.Cmd) == (
            s.excitation, s.angle_sp, s.rate_sp, s.rate, s.angle, s.axis_cmd)
        assert [getattr(m, f"M{i}") for i in range(1, 6)] == list(s.motor[:5])
        assert s.motor_count == 5 and not any(s.motor[5:])      # five rotors: no HQMX
        assert d.Targ == s.excitation
        assert d.Gx == pytest.approx(math.degrees(s.rate), rel=1e-6, abs=1e-9)
    return [h.Seq for h in hqsd]


def assert_fsck_clean(image) -> None:
    run = subprocess.run(["fsck.fat", "-n", str(image)], capture_output=True, text=True)
    assert run.returncode == 0, run.stdout + run.stderr


@pytest.fixture(scope="module")
def flown(tmp_path_factory):
    """Two `heliquad sil` runs on one card (a fresh image made by the first), the first's
    log read out with `heliquad logs download` over a board of that card."""
    tmp = tmp_path_factory.mktemp("onboard")
    card = tmp / "card.img"
    for run in ("first", "second"):
        res = heliquad("sil", *SIL_ARGS, "--sd-image", card, "--out", tmp / run)
        assert res.returncode == 0, res.stdout + res.stderr
    with running_board(tmp, "--disarmed", "--sd-image", card) as board:
        res = heliquad("logs", "--port", board, "download", 1, "--out", tmp / "got.BIN")
        assert res.returncode == 0, res.stdout + res.stderr
    return tmp, card


def test_the_sil_leaves_its_log_on_the_card_and_it_is_the_telemetry(flown):
    tmp, card = flown
    assert card.stat().st_size == fw.DEFAULT_CARD_IMAGE_BYTES
    records = log_records(tmp / "got.BIN")
    samples = telemetry_samples(tmp / "first.tlog")
    seqs = assert_samples_are_the_telemetry(records, samples)
    # Every armed loop of the run, from the arming to the last frame (the card served after
    # each step's reply, the log ended as the firmware stops), and the excitation in them.
    assert seqs == sorted(samples) == list(range(seqs[0], seqs[-1] + 1))
    assert not of(records, "HQGP")
    assert any(samples[q].excitation != 0.0 for q in seqs)
    assert of(records, "EV")[0].Id == 10                  # ArduPilot's "armed"


def test_the_download_is_the_file_on_the_card_and_a_second_arming_is_log_2(flown):
    tmp, card = flown
    image = Fat32Image(card)
    assert image.listdir("LOGS") == ["00000001.BIN", "00000002.BIN"]
    assert image.read("LASTLOG.TXT") == b"2\r\n"
    assert (tmp / "got.BIN").read_bytes() == image.read("LOGS/00000001.BIN")
    reader = fw.CardFiles(str(card))
    assert reader.mount() == fw.CardState.OK
    second = reader.read(2, 0, 1 << 24)
    del reader
    path = tmp / "second.BIN"
    path.write_bytes(second)
    assert_samples_are_the_telemetry(log_records(path), telemetry_samples(tmp / "second.tlog"))


@needs_fsck
def test_fsck_finds_the_card_clean(flown):
    assert_fsck_clean(flown[1])


def test_a_busy_card_costs_log_records_never_a_late_loop(tmp_path):
    card = tmp_path / "card.img"
    faults = ",".join(f"{k}={v}" for k, v in BUSY_FAULTS.items())
    cfg = SilConfig(axis="roll", freq_hz=2.0, amplitude=0.05, cycles=8, sd_image=str(card),
                    sd_faults=faults)
    r = run_sil(cfg, str(tmp_path / "busy"), progress=lambda *_: None)
    assert r.stopped is None and " 0 frames lost" in r.firmware_summary, r.firmware_summary
    status = [m for _, m in read_tlog(r.tlog_path, dialect(), only=("HQ_FW_STATUS",))]
    assert status and status[-1].loop_overruns == 0
    reader = fw.CardFiles(str(card))
    assert reader.mount() == fw.CardState.OK
    path = tmp_path / "busy.BIN"
    path.write_bytes(reader.read(1, 0, 1 << 24))
    del reader
    records = log_records(path)
    samples = telemetry_samples(r.tlog_path)
    seqs = assert_samples_are_the_telemetry(records, samples)
    assert (seqs[0], seqs[-1]) == (min(samples), max(samples))     # the first and last loops
    gaps = of(records, "HQGP")
    # One gap at least for each busy spell the armed flight saw. Every run of loops missing
    # from the log lies inside the gaps' spans (from the first record dropped to the gap
    # record, written with the first record that fits again, up to and including its time:
    # that record may be a link's own message right after the step whose sample did not
    # fit): one gap, or two when a short event record fitted while the next loop's 136 bytes
    # did not yet.
    busy_spells = (seqs[-1] - seqs[0]) // (BUSY_FAULTS["busy_every_us"] * 200 // 1_000_000)
    assert len(gaps) >= busy_spells >= 1
    missing = [(a + 1, b - 1) for a, b in zip(seqs, seqs[1:]) if b != a + 1]
    assert len(gaps) >= len(missing) >= busy_spells
    assert all(g.SinceUS < g.TimeUS for g in gaps)
    for first, last in missing:
        t0, t1 = samples[first].time_us, samples[last].time_us
        spans = [(g.SinceUS, g.TimeUS) for g in gaps if g.SinceUS <= t1 and t0 < g.TimeUS]
        assert spans and min(a for a, _ in spans) <= t0 and t1 <= max(b for _, b in spans)
    missing = [last - first + 1 for first, last in missing]
    # The events: every STATUSTEXT of the run a MSG, and the excitation's start a SIDS; those
    # not in the log are what the gaps counted beyond the samples.
    said = [m.text for _, m in read_tlog(r.tlog_path, dialect(), only=("STATUSTEXT",))]
    logged = [m.Message for m in of(records, "MSG")[1:]]          # the first: the version
    assert all(said.count(text) >= logged.count(text) for text in logged)
    events_dropped = len(said) - len(logged) + 1 - len(of(records, "SIDS"))
    assert sum(g.Dropped for g in gaps) == SAMPLE_RECORDS * sum(missing) + events_dropped
    # Every record but the dropped ones parsed whole: the file is nothing but records.
    assert path.stat().st_size == sum(len(m.get_msgbuf()) for m in records)


def test_the_teensy_image_gets_a_fresh_card_in_its_socket(tmp_path):
    card = tmp_path / "card.img"
    with PilFirmware(sd_image=str(card)) as firmware:
        assert firmware.startup_lines[-1] == "ready"
    assert card.stat().st_size == fw.DEFAULT_CARD_IMAGE_BYTES
    Fat32Image(card)                                 # a FAT32 volume at byte 0
    board = PilBoard(str(teensy35_image("elf")), sd_image=str(card), link="uart")
    assert board.board.sd_card.path == str(card)
    assert PilBoard(str(teensy35_image("elf")), link="uart").board.sd_card is None


@pytest.mark.parametrize("faults", ["no_card", "write_protected", "writable_blocks=1"])
def test_a_card_that_takes_no_log_lets_the_vehicle_fly_a_sweep(tmp_path, faults):
    card = tmp_path / "card.img"
    assert fw.make_card_image(str(card), fw.MIN_CARD_IMAGE_BYTES) == ""
    res = heliquad("sweep", "--sil", "--axis", "roll", "--plant", "tf", "--freqs-hz", 3,
                   "--cycles", 4, "--sd-image", card, "--sd-faults", faults,
                   "--out", tmp_path / "sweep")
    assert res.returncode == 0, res.stdout + res.stderr
    with running_board(tmp_path, "--disarmed", "--sd-image", card, "--sd-faults", faults) \
            as board:
        res = heliquad("logs", "--port", board, "list")
    assert res.returncode == 0 and "no logs on the board" in res.stdout, res.stdout + res.stderr
    image = Fat32Image(card)
    assert "LOGS" not in image.listdir() or image.listdir("LOGS") == []
