"""The MAVLink log protocol (firmware/core/link/log_transfer.hpp) and ``heliquad logs``, over
the host build serving the logs of its SD card (``heliquad board --sd-image``), a card image
whose .BIN files the file layer wrote (the bindings' CardFiles), with log 3 lost: the list, downloads equal to the files byte for byte (through a link that loses packets, and
one cut off mid-download that resumes), the defined answers to requests for what is not
there, the refusal while armed, erase; and MAVProxy's log module fetching the same bytes.
What heliquad logs says of a missing log, an armed board and a silent one: the bad-input
corpus (tests/bad_input_test.py, LIVE_LOG_CASES).
Every wait is for a condition, bounded by a guard against a hang."""

from __future__ import annotations

import os
import struct
import subprocess
import sys
import time

import numpy as np
import pytest

from fat32_image import Fat32Image
from ground_stations_test import MavProxy
from heliquad import _firmware as fw
from heliquad.host.acquire.link import TelemetryLink
from heliquad.sim.base.dialect import dialect
from lossy_link_test import DamagingRelay
from tool_runs import running_board

#: A guard against a hang, never a measure.
GUARD_S = 60.0
#: LOG_DATA carries up to this many bytes.
CHUNK = 90
#: The board's logs: a DataFlash log (a format record, then samples), a log of random bytes
#: that ends in a short packet, one whose size is a whole number of packets (log 3 before it
#: lost), and a short one.
SAMPLES = 1500
RANDOM_BYTES = 20_011
WHOLE_PACKETS_BYTES = 100 * CHUNK


def dataflash_log(samples: int) -> bytes:
    """An ArduPilot DataFlash log pymavlink's DFReader reads: the FMT record that describes
    FMT, one describing SAMP (TimeUS, Val), then ``samples`` SAMP records."""
    def fmt(msg_type, length, name, form, columns):
        return b"\xa3\x95\x80" + struct.pack("<BB4s16s64s", msg_type, length, name, form, columns)
    out = [fmt(0x80, 89, b"FMT", b"BBnNZ", b"Type,Length,Name,Format,Columns"),
           fmt(0x81, 15, b"SAMP", b"Qf", b"TimeUS,Val")]
    out += [b"\xa3\x95\x81" + struct.pack("<Qf", 5000 * k, 0.5 * k) for k in range(samples)]
    return b"".join(out)


#: What the file layer's write() takes at once, and how often the tests' writes sync.
WRITE_BYTES = 4096


def card_with_logs(path, logs: dict) -> None:
    """A fresh card image at ``path`` holding ``logs`` ({number: bytes}), each written through
    the file layer as the logger writes it (begun, appended and synced, ended). A number
    skipped is a log lost: LASTLOG.TXT, rewritten in place between logs, says it was begun."""
    assert fw.make_card_image(str(path), fw.MIN_CARD_IMAGE_BYTES) == ""
    last = 0
    for number, data in sorted(logs.items()):
        if number > last + 1:
            _lose_logs_up_to(path, last, number - 1)
        card = fw.CardFiles(str(path))
        assert card.mount() == fw.CardState.OK
        assert card.begin_log() and card.last_log == number
        for at in range(0, len(data), WRITE_BYTES):
            assert card.write(data[at:at + WRITE_BYTES]) == len(data[at:at + WRITE_BYTES])
            card.advance_us(fw.LOG_SYNC_PERIOD_US)
            card.service()
        card.end_log()
        del card                                   # the card let go before the next opens it
        last = number


def _lose_logs_up_to(path, last: int, lost: int) -> None:
    """LASTLOG.TXT says ``lost`` instead of ``last`` (the same number of digits): the logs in
    between were begun and are gone."""
    old, new = f"{last}\r\n".encode(), f"{lost}\r\n".encode()
    assert len(old) == len(new)
    data = bytearray(path.read_bytes())
    at = Fat32Image(path).offset("LASTLOG.TXT")
    assert data[at:at + len(old)] == old
    data[at:at + len(new)] = new
    path.write_bytes(bytes(data))


@pytest.fixture
def log_files():
    """The logs the board's card holds, by number."""
    rng = np.random.default_rng(7)
    return {1: dataflash_log(SAMPLES),
            2: rng.integers(0, 256, RANDOM_BYTES, dtype=np.uint8).tobytes(),
            4: rng.integers(0, 256, WHOLE_PACKETS_BYTES, dtype=np.uint8).tobytes(),
            5: b"a short log" * 10 + b"0123456789"}


@pytest.fixture
def card(tmp_path, log_files):
    """The card image of the board, holding :func:`log_files`."""
    path = tmp_path / "card.img"
    card_with_logs(path, log_files)
    return path


def heliquad(*args, cwd=None):
    return subprocess.run([sys.executable, "-m", "heliquad.host.cli.parser", *map(str, args)],
                          capture_output=True, text=True, timeout=GUARD_S * 4, cwd=cwd)


def one_line_error(res, code: int, says: str) -> None:
    assert res.returncode == code, res.stdout + res.stderr
    lines = res.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("heliquad") and says in lines[0], res.stderr


# --- heliquad logs ---------------------------------------------------------------------------

def test_list_download_and_erase_through_heliquad_logs(tmp_path, card, log_files):
    with running_board(tmp_path, "--disarmed", "--sd-image", card) as board:
        res = heliquad("logs", "--port", board, "list")
        assert res.returncode == 0, res.stderr
        rows = [line.split() for line in res.stdout.splitlines()[1:-1]]
        sizes = {int(r[0]): int(r[1]) for r in rows}
        assert sizes == {1: len(dataflash_log(SAMPLES)), 2: RANDOM_BYTES,
                         4: WHOLE_PACKETS_BYTES, 5: 120}
        assert rows[0][2:] == ["-"]          # no board clock: the time is unknown
        for log_id in (1, 2, 4):
            out = tmp_path / f"got{log_id}.BIN"
            res = heliquad("logs", "--port", board, "download", log_id, "--out", out)
            assert res.returncode == 0, res.stdout + res.stderr
            assert "[##########] 100 %" in res.stdout
            assert out.read_bytes() == log_files[log_id], log_id
            assert not os.path.exists(f"{out}.part")
        res = heliquad("logs", "--port", board, "download", 1, cwd=tmp_path)  # the card's name
        assert res.returncode == 0 and (tmp_path / "00000001.BIN").exists(), res.stderr
        res = heliquad("logs", "--port", board, "erase")
        assert res.returncode == 0, res.stderr
        assert f"erased 4 logs (1..5, {sum(sizes.values())} bytes)" in res.stdout
        res = heliquad("logs", "--port", board, "list")
        assert res.returncode == 0 and "no logs on the board" in res.stdout, res.stderr
    from pymavlink import DFReader

    log = DFReader.DFReader_binary(str(tmp_path / "got1.BIN"))
    vals = []
    while (m := log.recv_match(type="SAMP")) is not None:
        vals.append(m.Val)
    assert vals == [0.5 * k for k in range(SAMPLES)]


def test_a_download_through_a_link_that_loses_packets_is_whole(tmp_path, card, log_files):
    with running_board(tmp_path, "--disarmed", "--sd-image", card,
                       "--backlog-bytes", 0) as board:
        relay = DamagingRelay(board, drop=0.05, seed=3)
        os.set_blocking(relay.main, False)
        try:
            out = tmp_path / "lossy.BIN"
            res = heliquad("logs", "--port", relay.port, "download", 2, "--out", out)
        finally:
            relay.close()
    assert res.returncode == 0, res.stdout + res.stderr
    assert relay.dropped > 0
    assert out.read_bytes() == log_files[2]


class CuttingRelay(DamagingRelay):
    """A relay that passes the board's packets until ``keep`` LOG_DATA have gone through,
    then nothing more: a link gone mid-download."""

    def __init__(self, board_port, keep: int):
        self.keep, self.passed = keep, 0
        super().__init__(board_port)

    def _damage(self, data: bytes) -> bytes:
        kept = []
        for msgid, packet, _ in self.framer.feed(data):
            if self.passed >= self.keep:
                continue
            self.passed += msgid == dialect().MAVLINK_MSG_ID_LOG_DATA
            kept.append(packet)
        return b"".join(kept)


def test_a_download_cut_off_keeps_its_part_and_resumes(tmp_path, card, log_files):
    out = tmp_path / "cut.BIN"
    want = log_files[2]
    with running_board(tmp_path, "--disarmed", "--sd-image", card,
                       "--backlog-bytes", 0) as board:
        relay = CuttingRelay(board, keep=60)
        os.set_blocking(relay.main, False)
        try:
            res = heliquad("logs", "--port", relay.port, "download", 2, "--out", out)
        finally:
            relay.close()
        one_line_error(res, 1, "run again to resume")
        part = (tmp_path / "cut.BIN.part").read_bytes()
        assert 0 < len(part) <= 60 * CHUNK and want.startswith(part) and not out.exists()
        res = heliquad("logs", "--port", board, "download", 2, "--out", out)
    assert res.returncode == 0, res.stdout + res.stderr
    assert f"resuming log 2 at {len(part)} of {RANDOM_BYTES} bytes" in res.stdout
    assert out.read_bytes() == want and not (tmp_path / "cut.BIN.part").exists()


# --- the firmware's answers, message by message ---------------------------------------------

class Raw:
    """The board's link as a test speaks it: requests sent, answers collected."""

    def __init__(self, port):
        self.link = TelemetryLink(str(port))
        self.mav = self.link.mav

    def ask(self, send, until, only=("LOG_ENTRY", "LOG_DATA", "STATUSTEXT")) -> list:
        """``send()`` once, then what comes of ``only`` until ``until(messages)``."""
        send()
        got, deadline = [], time.monotonic() + GUARD_S
        while time.monotonic() < deadline:
            got += self.link.poll(only=only)
            if until(got):
                return got
            time.sleep(0.005)
        raise AssertionError(f"no answer; got {got}")

    def quiet(self, seconds: float, only=("LOG_ENTRY", "LOG_DATA", "STATUSTEXT")) -> list:
        got, end = [], time.monotonic() + seconds
        while time.monotonic() < end:
            got += self.link.poll(only=only)
            time.sleep(0.01)
        return got


def wait_armed(port) -> None:
    """Until the board's HEARTBEAT says armed (its pilot arms it soon after the start)."""
    raw = Raw(port)
    try:
        armed = dialect().MAV_MODE_FLAG_SAFETY_ARMED
        raw.ask(lambda: None, lambda g: any(m.base_mode & armed for m in g), only=("HEARTBEAT",))
    finally:
        raw.link.close()


def texts(msgs):
    return [m.text for m in msgs if m.get_type() == "STATUSTEXT"]


def test_the_firmware_answers_what_is_not_there_in_a_defined_way(tmp_path, card, log_files):
    with running_board(tmp_path, "--disarmed", "--sd-image", card) as board:
        raw = Raw(board)
        try:
            # The list: every log, last_log_num the last; a range with none says so.
            got = raw.ask(lambda: raw.link.request_log_list(),
                          lambda g: len([m for m in g if m.get_type() == "LOG_ENTRY"]) == 4)
            entries = [(m.id, m.num_logs, m.last_log_num) for m in got if m.get_type() == "LOG_ENTRY"]
            assert entries == [(1, 4, 5), (2, 4, 5), (4, 4, 5), (5, 4, 5)]
            got = raw.ask(lambda: raw.link.request_log_list(7, 9), lambda g: texts(g))
            assert texts(got) == ["logs: none in the range asked for"]
            # A log that does not exist.
            got = raw.ask(lambda: raw.link.request_log_data(3, 0, 1000), lambda g: texts(g))
            assert texts(got) == ["logs: no log 3"] and all(m.get_type() != "LOG_DATA" for m in got)
            # An offset at and past the end: one empty LOG_DATA there.
            for ofs in (WHOLE_PACKETS_BYTES, WHOLE_PACKETS_BYTES + 5000):
                got = raw.ask(lambda: raw.link.request_log_data(4, ofs, 0xFFFFFFFF),
                              lambda g: any(m.get_type() == "LOG_DATA" for m in g))
                assert [(m.id, m.ofs, m.count) for m in got] == [(4, ofs, 0)]
            # A count of 0 (asks for nothing): the same empty answer at the offset.
            got = raw.ask(lambda: raw.link.request_log_data(2, 100, 0),
                          lambda g: any(m.get_type() == "LOG_DATA" for m in g))
            assert [(m.ofs, m.count) for m in got] == [(100, 0)]
            # A count that ends mid-packet: whole packets, then the rest, then nothing more.
            want = log_files[2]
            got = raw.ask(lambda: raw.link.request_log_data(2, 10, 200),
                          lambda g: sum(m.count for m in g if m.get_type() == "LOG_DATA") >= 200)
            got += raw.quiet(0.5)
            assert [(m.ofs, m.count) for m in got] == [(10, 90), (100, 90), (190, 20)]
            assert b"".join(bytes(m.data[:m.count]) for m in got) == want[10:210]
            # A request for another system is not ours: no answer.
            raw.mav.log_request_list_send(7, 1, 0, 0xFFFF)
            assert raw.quiet(1.0) == []
        finally:
            raw.link.close()


def test_a_new_request_replaces_the_old_and_end_stops_it(tmp_path, card):
    with running_board(tmp_path, "--disarmed", "--sd-image", card) as board:
        raw = Raw(board)
        try:
            raw.link.request_log_data(2, 0, 0xFFFFFFFF)
            got = raw.ask(lambda: raw.link.request_log_data(4, 0, 2 * CHUNK),
                          lambda g: any(m.id == 4 and m.ofs == CHUNK for m in g
                                        if m.get_type() == "LOG_DATA"))
            got += raw.quiet(0.5)
            after = [(m.id, m.ofs) for m in got if m.get_type() == "LOG_DATA"]
            first4 = after.index((4, 0))
            assert after[first4:] == [(4, 0), (4, CHUNK)]     # log 2's stream ended there
            got = raw.ask(lambda: raw.link.request_log_data(2, 0, 0xFFFFFFFF),
                          lambda g: len(g) >= 3, only=("LOG_DATA",))
            raw.link.end_log_transfer()
            time.sleep(0.5)
            raw.link.poll()
            assert raw.quiet(0.5, only=("LOG_DATA",)) == []   # nothing after LOG_REQUEST_END
        finally:
            raw.link.close()


def test_an_armed_board_says_so_once_and_sends_no_log(tmp_path, card):
    with running_board(tmp_path, "--sd-image", card) as board:
        wait_armed(board)
        raw = Raw(board)
        try:
            got = raw.ask(lambda: raw.link.request_log_list(), lambda g: texts(g))
            raw.link.request_log_data(1, 0, 1000)
            got += raw.quiet(1.0)
            assert texts(got) == ["logs: disarm to download"]
            assert all(m.get_type() == "STATUSTEXT" for m in got)
        finally:
            raw.link.close()


# --- a third-party client -------------------------------------------------------------------

def test_mavproxy_lists_and_downloads_the_same_bytes(tmp_path, card, log_files):
    with running_board(tmp_path, "--disarmed", "--sd-image", card) as board:
        class Port:                                # what MavProxy reads of a board
            device = os.path.realpath(board)
        mp = MavProxy(Port, tmp_path)
        try:
            mp.expect("Detected vehicle")
            mp.type("log list")
            mp.expect(rf"Log 1\s+numLogs 4 lastLog 5 size {len(dataflash_log(SAMPLES))}")
            mp.expect(r"Log 5\s+numLogs 4 lastLog 5 size 120")
            for log_id in (2, 4):
                out = tmp_path / f"mavproxy{log_id}.bin"
                mp.type(f"log download {log_id} {out}")
                mp.expect(rf"Finished downloading {out}")
                assert out.read_bytes() == log_files[log_id], log_id
        finally:
            mp.close()
