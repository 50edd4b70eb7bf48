"""Logging sessions (heliquad log) and .tlog reading up to damage (heliquad tlog)."""

import subprocess
import sys
import warnings

import pytest

from heliquad.host.logsession import summarise_tlog


def heliquad(*args, **kw):
    return subprocess.run([sys.executable, "-m", "heliquad.host.cli", *map(str, args)],
                          capture_output=True, text=True, timeout=120, **kw)


@pytest.fixture(scope="module")
def session(tmp_path_factory):
    """A 4 s logging session from a free-running simulated board."""
    folder = tmp_path_factory.mktemp("log")
    port, out = folder / "rig", folder / "session.tlog"
    board = subprocess.Popen([sys.executable, "-m", "heliquad.host.cli", "board", "--telemetry",
                              str(port), "--duration-s", "7"], stdout=subprocess.PIPE, text=True)
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
    assert 0.9 * 200 * 4 < s["samples"] < 1.1 * 200 * 4          # 200 Hz for 4 s
    assert s["types"]["ATTITUDE"] >= s["samples"] - 1 and s["types"]["HEARTBEAT"] >= 3


def test_truncated_log_is_read_up_to_the_damage(session, tmp_path):
    _, out = session
    data = out.read_bytes()
    cut = tmp_path / "cut.tlog"
    cut.write_bytes(data[:len(data) // 2 + 7])
    s = summarise_tlog(str(cut))                 # the warning is captured into "damage"
    assert "damaged or truncated" in s["damage"] and s["samples"] > 100
    res = heliquad("tlog", cut)
    assert res.returncode == 0 and "Traceback" not in res.stderr
    assert res.stderr.count("\n") == 1 and "damaged or truncated" in res.stderr


def test_corrupted_byte_stops_the_read_with_a_warning(session, tmp_path):
    _, out = session
    data = bytearray(out.read_bytes())
    # One flipped byte inside the payload of the record that starts after a third of the file
    # (a flip in a timestamp is not detectable: no checksum covers it).
    pos = 0
    while pos < len(data) // 3:
        pos += 8 + 12 + data[pos + 9]                           # stamp, header + CRC, payload
    data[pos + 8 + 10] ^= 0xFF
    bad = tmp_path / "bad.tlog"
    bad.write_bytes(bytes(data))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        s = summarise_tlog(str(bad))
        whole = summarise_tlog(str(out))
    assert s["damage"] and 0 < s["messages"] < whole["messages"]


def test_a_missing_port_is_one_line_exit_2(tmp_path):
    res = heliquad("log", "--port", tmp_path / "nope", "--out", tmp_path / "x.tlog")
    assert res.returncode == 2 and len(res.stderr.strip().splitlines()) == 1
    assert "cannot open" in res.stderr
