"""Logging sessions (heliquad log) and .tlog reading past damage (heliquad tlog)."""

import subprocess
import sys

import pytest

from heliquad.host.acquire.log_session import summarise_tlog


def heliquad(*args, **kw):
    return subprocess.run([sys.executable, "-m", "heliquad.host.cli.parser", *map(str, args)],
                          capture_output=True, text=True, timeout=120, **kw)


@pytest.fixture(scope="module")
def session(tmp_path_factory):
    """A 4 s logging session from a free-running simulated board."""
    folder = tmp_path_factory.mktemp("log")
    port, out = folder / "rig", folder / "session.tlog"
    # All its telemetry kept for the reader (--backlog-bytes 0): "0 lost" is asserted, and a
    # reader a loaded machine stalls would lose some past the default bound.
    board = subprocess.Popen([sys.executable, "-m", "heliquad.host.cli.parser", "board", "--telemetry",
                              str(port), "--duration-s", "7", "--backlog-bytes", "0"],
                             stdout=subprocess.PIPE, text=True)
    try:
        assert "board running" in board.stdout.readline()
        res = heliquad("log", "--port", port, "--out", out, "--duration-s", 4)
    finally:
        board.wait(timeout=20)
    return res, out


def test_a_session_from_a_board_loses_no_samples(session):
    res, out = session
    assert res.returncode == 0, res.stderr
    assert "0 lost" in res.stdout
    s = summarise_tlog(str(out))
    assert s["lost"] == 0 and s["damage"] is None
    # Every sample between the first and the last is there. The count depends on the clock
    # (what the board buffered before the log opened, how far a loaded machine runs the board
    # behind real time): only a floor far below 4 s at 200 Hz.
    assert s["samples"] == s["last_seq"] - s["first_seq"] + 1
    assert s["samples"] > 50
    assert s["types"]["ATTITUDE"] >= s["samples"] - 1 and s["types"]["HEARTBEAT"] >= 3


def _record_size(data, pos):
    """Bytes of the .tlog record at ``pos``: stamp, MAVLink 2 header and CRC, payload."""
    return 8 + 12 + data[pos + 9]


def _record_after(data, at):
    """Where the first record at or after byte ``at`` of a well-formed .tlog starts."""
    pos = 0
    while pos < at:
        pos += _record_size(data, pos)
    return pos


def test_truncated_log_is_read_up_to_the_damage(session, tmp_path):
    _, out = session
    data = out.read_bytes()
    # Cut in the middle of the record that starts after half the file: a cut at a fixed byte
    # count would, now and then, fall exactly on a record's end and leave a whole log behind.
    pos = _record_after(data, len(data) // 2)
    cut = tmp_path / "cut.tlog"
    cut.write_bytes(data[:pos + _record_size(data, pos) // 2])
    whole_records = tmp_path / "whole.tlog"
    whole_records.write_bytes(data[:pos])
    s, before = summarise_tlog(str(cut)), summarise_tlog(str(whole_records))
    assert "damaged" in s["damage"] and "skipped in 1 damaged place" in s["damage"]
    # every record before the damaged one is read
    assert before["damage"] is None and before["samples"] > 0
    assert (s["messages"], s["samples"]) == (before["messages"], before["samples"])
    res = heliquad("tlog", cut)
    assert res.returncode == 0 and "Traceback" not in res.stderr
    assert res.stderr.count("\n") == 1 and "is damaged" in res.stderr


def test_a_corrupted_byte_costs_one_message_and_is_reported(session, tmp_path):
    _, out = session
    data = bytearray(out.read_bytes())
    # One flipped byte inside the payload of the record that starts after a third of the file
    # (a flip in a timestamp is not detectable: no checksum covers it).
    pos = _record_after(data, len(data) // 3)
    data[pos + 8 + 10] ^= 0xFF
    bad = tmp_path / "bad.tlog"
    bad.write_bytes(bytes(data))
    s, whole = summarise_tlog(str(bad)), summarise_tlog(str(out))
    assert s["damage"] and f"(the first at byte {pos})" in s["damage"]
    assert s["messages"] == whole["messages"] - 1          # the damaged record alone is lost


@pytest.fixture(scope="module")
def sweep_log(tmp_path_factory):
    """A short SIL sweep's log: two frequencies on the vehicle's roll rig."""
    out = tmp_path_factory.mktemp("sweep") / "roll"
    res = heliquad("sweep", "--axis", "roll", "--sil", "--freqs-hz", 2, 6, "--cycles", 4,
                   "--out", out)
    assert res.returncode == 0, res.stderr
    return out / "sweep.tlog"


def test_single_bit_flips_in_a_sweep_log_are_read_past_and_reported(sweep_log, tmp_path):
    """200 random single-bit flips: at least 99 % of the samples are still read, and every
    flip is reported: in a packet by its CRC, in a timestamp because a simulated session
    stamps each record with its control loop's time."""
    import random

    data = sweep_log.read_bytes()
    whole = summarise_tlog(str(sweep_log))
    assert whole["damage"] is None and whole["samples"] > 1000
    rng, kept, silent = random.Random(7), [], []
    flipped = tmp_path / "flip.tlog"
    for _ in range(200):
        at, bit = rng.randrange(len(data)), rng.randrange(8)
        damaged = bytearray(data)
        damaged[at] ^= 1 << bit
        flipped.write_bytes(bytes(damaged))
        s = summarise_tlog(str(flipped))
        kept.append(s["samples"] / whole["samples"])
        if not s["damage"]:
            silent.append((at, bit))
    assert sum(kept) / len(kept) >= 0.99 and min(kept) >= 0.99
    assert not silent, silent


def test_a_sil_sweeps_log_counts_from_the_start_its_manifest_records(sweep_log):
    # Every record: the run's start (the wall clock, manifest's tlog_start_us) plus its
    # loop's simulated time, so pymavlink's tools date it; the reader finds nothing amiss.
    import datetime
    import json

    from heliquad.host.records.tlog import TlogDamage, read_tlog
    from heliquad.sim.base.dialect import dialect

    manifest = json.loads((sweep_log.parent / "manifest.json").read_text())
    start = manifest["tlog_start_us"]
    damage = TlogDamage()
    samples = [(t, m) for t, m in read_tlog(str(sweep_log), dialect(), damage=damage)
               if m.get_type() == "HQ_SYSID_SAMPLE"]
    assert not damage and len(samples) > 1000
    assert {t - m.time_us for t, m in samples} == {start}
    started = datetime.datetime.fromisoformat(manifest["started"]).timestamp()
    assert abs(start * 1e-6 - started) < 600         # the same run (a hang guard's margin)


def test_a_missing_port_is_one_line_exit_2(tmp_path):
    res = heliquad("log", "--port", tmp_path / "nope", "--out", tmp_path / "x.tlog")
    assert res.returncode == 2 and len(res.stderr.strip().splitlines()) == 1
    assert "cannot open" in res.stderr
