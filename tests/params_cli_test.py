"""``heliquad params`` and the MAVLink parameter protocol from the host, against a fake
board that speaks the protocol over a pty (a handful of parameters; it loses some answers
to prove the retries and refuses a value out of its range with a STATUSTEXT), and the
.params files of QGroundControl and MAVProxy."""

from __future__ import annotations

import os
import select
import subprocess
import sys
import threading
import time

import numpy as np
import pytest

from heliquad import _firmware
from heliquad.host.acquire.link import TelemetryLink
from heliquad.host.acquire.param_protocol import (NoAnswer, Param, ParamClient, ParamRefused,
                                                  decode_value, encode_value, value_text)
from heliquad.host.records.params_file import read_params_file, write_params_file
from heliquad.sim.base.dialect import dialect
from heliquad.sim.base.errors import InputError
from heliquad.sim.base.framing import Codec, Framer

MAV = dialect()
REAL32, INT32 = MAV.MAV_PARAM_TYPE_REAL32, MAV.MAV_PARAM_TYPE_INT32
#: name, value, type, accepted range
PARAMS = [("RATE_ROLL_P", 2.422, REAL32, (0.0, 100.0)),
          ("RATE_ROLL_I", 0.439, REAL32, (0.0, 100.0)),
          ("RATE_ROLL_D", 0.051, REAL32, (0.0, 10.0)),
          ("ANGLE_ROLL_P", 1.488, REAL32, (0.0, 50.0)),
          ("LOOP_HZ", 200, INT32, (50, 1000)),
          ("EXC_MAX_CYCLES", 60, INT32, (1, 65535))]
#: The firmware answers the parameter protocol only while the host's heartbeat is fresh.
HEARTBEAT_FRESH_S = 1.5


class ParamBoard:
    """The board's end of a pty, speaking the parameter protocol in a thread.

    ``drop_list``: indices whose PARAM_VALUE it loses the first time it sends the list;
    ``drop_set``: names whose first PARAM_SET answer it loses; ``silent``: answers nothing.
    It counts what it was asked (``asked``: (message, name or index)) and the heartbeats."""

    def __init__(self, drop_list=(), drop_set=(), silent=False):
        self.main, self.side = os.openpty()
        self.port = os.ttyname(self.side)
        import tty
        tty.setraw(self.side)
        self.names = [p[0] for p in PARAMS]
        self.values = {name: float(np.float32(v)) for name, v, _, _ in PARAMS}
        self.types = {name: t for name, _, t, _ in PARAMS}
        self.ranges = {name: r for name, _, _, r in PARAMS}
        self.drop_list, self.drop_set, self.silent = set(drop_list), set(drop_set), silent
        self.asked, self.heartbeats, self.last_heartbeat = [], 0, None
        self.codec = Codec(MAV)
        self.framer = Framer(self.codec)
        self.mav = MAV.MAVLink(None, srcSystem=1, srcComponent=MAV.MAV_COMP_ID_AUTOPILOT1)
        self.stopping = threading.Event()
        self.thread = threading.Thread(target=self._run, daemon=True)
        self.thread.start()

    def _run(self):
        while not self.stopping.is_set():
            if not select.select([self.main], [], [], 0.02)[0]:
                continue
            try:
                data = os.read(self.main, 65536)
            except OSError:
                return
            for msgid, _, payload in self.framer.feed(data):
                self._handle(self.codec.decode(msgid, payload))

    def _send(self, msg):
        os.write(self.main, msg.pack(self.mav))

    def _value(self, name, drop=False):
        if not drop:
            self._send(self.mav.param_value_encode(          # byte-wise, as the firmware
                name.encode(), encode_value(self.values[name], self.types[name]),
                self.types[name], len(self.names), self.names.index(name)))

    def _text(self, text):
        self._send(self.mav.statustext_encode(MAV.MAV_SEVERITY_WARNING, text.encode()))

    def _handle(self, m):
        kind = m.get_type()
        if kind == "HEARTBEAT":
            self.heartbeats += 1
            self.last_heartbeat = time.monotonic()
            return
        if kind not in ("PARAM_REQUEST_LIST", "PARAM_REQUEST_READ", "PARAM_SET"):
            return
        if self.silent or self.last_heartbeat is None or \
                time.monotonic() - self.last_heartbeat > HEARTBEAT_FRESH_S:
            return
        if kind == "PARAM_REQUEST_LIST":
            self.asked.append((kind, None))
            for name in self.names:
                self._value(name, drop=self.names.index(name) in self.drop_list)
            self.drop_list = set()
        elif kind == "PARAM_REQUEST_READ":
            self._read(m)
        else:
            self._set(m)

    def _read(self, m):
        by_index = m.param_index >= 0
        self.asked.append(("PARAM_REQUEST_READ", m.param_index if by_index else m.param_id))
        if by_index:
            if m.param_index < len(self.names):
                self._value(self.names[m.param_index])
        elif m.param_id in self.values:
            self._value(m.param_id)
        else:
            self._text(f"params: no {m.param_id}")

    def _set(self, m):
        name = m.param_id
        self.asked.append(("PARAM_SET", name))
        if name not in self.values:
            self._text(f"params: no {name}")
            return
        lo, hi = self.ranges[name]
        value = decode_value(m.param_value, m.param_type)
        if lo <= value <= hi:
            self.values[name] = value
            self._value(name, drop=name in self.drop_set)
            self.drop_set.discard(name)
        else:                          # refused: the old value, then why
            self._value(name)
            self._text(f"params: {name} {value:g} outside {lo:g}..{hi:g}")

    def close(self):
        self.stopping.set()
        self.thread.join(timeout=10)
        os.close(self.main)
        os.close(self.side)


@pytest.fixture
def board():
    b = ParamBoard()
    yield b
    b.close()


@pytest.fixture
def client(board):
    link = TelemetryLink(board.port)
    yield ParamClient(link)
    link.close()


def heliquad(*args):
    return subprocess.run([sys.executable, "-m", "heliquad.host.cli.parser", *map(str, args)],
                          capture_output=True, text=True, timeout=120)


# --- the protocol ------------------------------------------------------------------------

def test_a_list_with_lost_values_is_completed_by_index():
    # Two PARAM_VALUEs of the list are lost: the client asks for exactly those again by
    # index and returns every parameter in the board's order, values and types as sent.
    board = ParamBoard(drop_list={1, 4})
    link = TelemetryLink(board.port)
    said = []
    try:
        params = ParamClient(link, progress=said.append).fetch_all()
    finally:
        link.close()
        board.close()
    assert [(p.name, p.value, p.type, p.index) for p in params] == [
        (name, float(np.float32(v)), t, i) for i, (name, v, t, _) in enumerate(PARAMS)]
    assert board.asked == [("PARAM_REQUEST_LIST", None), ("PARAM_REQUEST_READ", 1),
                           ("PARAM_REQUEST_READ", 4)]
    assert "  4 of 6 received; asking again for 2 by index" in said and said[-1] == "  6 parameters"
    assert board.heartbeats >= 1                # it answers only with the host's heartbeat


def test_get_and_set_are_checked_against_the_boards_answer(board, client):
    p = client.get("RATE_ROLL_P")
    assert (p.name, p.text(), p.type) == ("RATE_ROLL_P", "2.422", REAL32)
    got = client.set(p, 2.5)
    assert got.value == 2.5 and board.values["RATE_ROLL_P"] == 2.5
    hz = client.set(client.get("LOOP_HZ"), 250)
    assert hz.text() == "250" and board.values["LOOP_HZ"] == 250.0


def test_a_set_whose_answer_is_lost_is_sent_again():
    board = ParamBoard(drop_set={"RATE_ROLL_D"})
    link = TelemetryLink(board.port)
    try:
        client = ParamClient(link, answer_wait_s=0.3)
        got = client.set(client.get("RATE_ROLL_D"), 0.06)
    finally:
        link.close()
        board.close()
    assert got.text() == "0.06"
    assert board.asked.count(("PARAM_SET", "RATE_ROLL_D")) == 2


def test_a_refused_value_is_one_line_quoting_the_board(board, client):
    # The board keeps the old value and says why in a STATUSTEXT (after its PARAM_VALUE).
    p = client.get("RATE_ROLL_P")
    with pytest.raises(ParamRefused, match='^the board refused RATE_ROLL_P = 1000 and kept '
                                           '2.422: it says "params: RATE_ROLL_P 1000 outside '
                                           '0..100"$'):
        client.set(p, 1000)
    assert board.values["RATE_ROLL_P"] == float(np.float32(2.422))


def test_an_unknown_name_and_a_value_the_type_cannot_take(board, client):
    with pytest.raises(InputError, match='^the board has no parameter NOPE \\(it says '
                                         '"params: no NOPE"\\)$'):
        client.get("NOPE")
    with pytest.raises(InputError, match="^LOOP_HZ takes whole numbers \\(INT32\\), not 2.5$"):
        client.set(client.get("LOOP_HZ"), 2.5)
    with pytest.raises(InputError, match="cannot be carried exactly"):
        client.set(client.get("LOOP_HZ"), 2**24 + 1)
    assert not [a for a in board.asked if a[0] == "PARAM_SET"]          # nothing was sent


def test_a_board_that_never_answers_is_given_up_on_in_one_line():
    board = ParamBoard(silent=True)
    link = TelemetryLink(board.port)
    try:
        client = ParamClient(link, answer_wait_s=0.05, retries=2)
        with pytest.raises(NoAnswer, match=f"^no answer to the parameter list request "
                                           f"\\(PARAM_REQUEST_LIST\\) from {board.port} after "
                                           "3 requests"):
            client.fetch_all()
    finally:
        link.close()
        board.close()
    assert board.heartbeats >= 1


def test_a_silent_board_ends_the_command_with_exit_1():
    # The board fell silent: not the user's input (exit 2) but the run that could not do
    # its job (exit 1), one line.
    board = ParamBoard(silent=True)
    try:
        res = heliquad("params", "--port", board.port, "get", "ANGLE_ROLL_P")
    finally:
        board.close()
    assert res.returncode == 1, res.stderr
    assert res.stderr.startswith("heliquad params: error: no answer to reading ANGLE_ROLL_P")
    assert res.stderr.count("\n") == 1


# --- the command ---------------------------------------------------------------------------

def test_list_get_and_set_from_the_command_line(board):
    res = heliquad("params", "--port", board.port, "list")
    assert res.returncode == 0, res.stderr
    lines = res.stdout.splitlines()
    assert lines[0] == f"fetching parameters from {board.port} ..."
    table = lines[lines.index(next(l for l in lines if l.startswith("NAME"))) + 1:]
    assert [l.split() for l in table] == [
        [name, value_text(v, t), "REAL32" if t == REAL32 else "INT32"] for name, v, t, _ in PARAMS]
    res = heliquad("params", "--port", board.port, "set", "ANGLE_ROLL_P", "1.5")
    assert res.returncode == 0 and res.stdout == "ANGLE_ROLL_P: 1.488 -> 1.5\n", res.stderr
    res = heliquad("params", "--port", board.port, "get", "ANGLE_ROLL_P")
    assert res.stdout == "ANGLE_ROLL_P 1.5\n"
    res = heliquad("params", "--port", board.port, "set", "RATE_ROLL_I", "-1")
    # The board refused: exit 1, as a load with a refusal (2: wrong arguments or files).
    assert res.returncode == 1 and res.stderr.count("\n") == 1
    assert res.stderr == ('heliquad params: error: the board refused RATE_ROLL_I = -1 and kept '
                          '0.439: it says "params: RATE_ROLL_I -1 outside 0..100"\n')


def test_save_then_load_round_trips_and_load_reports_every_refusal(board, tmp_path):
    saved = tmp_path / "rig.params"
    res = heliquad("params", "--port", board.port, "save", saved)
    assert res.returncode == 0 and "wrote 6 parameters" in res.stdout, res.stderr
    text = saved.read_text()
    assert text.startswith("# Onboard parameters for Vehicle 1\n")
    assert "1\t1\tRATE_ROLL_P\t2.422\t9\n" in text and "1\t1\tLOOP_HZ\t200\t6\n" in text
    assert {n: float(np.float32(v)) for n, v, _ in read_params_file(saved)} == board.values
    assert heliquad("params", "--port", board.port, "save", saved).returncode == 2  # kept

    # A MAVProxy-style file: one change, one unchanged, one out of range, one unknown, one
    # whole-number parameter given a fraction: the change is made, the three named.
    edits = tmp_path / "edits.parm"
    edits.write_text("# tuned on the rig\nRATE_ROLL_P 2.6\nRATE_ROLL_I 0.439\n"
                     "RATE_ROLL_D 99   # too much\nNO_SUCH 1\nLOOP_HZ 250.5\n")
    res = heliquad("params", "--port", board.port, "load", edits)
    assert res.returncode == 1, res.stderr
    assert "  RATE_ROLL_P: 2.422 -> 2.6" in res.stdout
    assert "1 set, 1 already so, 3 refused" in res.stdout
    assert 'RATE_ROLL_D 99 outside 0..10' in res.stdout and "NO_SUCH: not set: the board " \
        "has no parameter of that name" in res.stdout and "LOOP_HZ takes whole numbers" in res.stdout
    assert res.stderr == (f"heliquad params: the board refused 3 of 5 parameters from {edits}: "
                          "RATE_ROLL_D, NO_SUCH, LOOP_HZ (why: above)\n")
    assert board.values["RATE_ROLL_P"] == float(np.float32(2.6))
    assert board.values["RATE_ROLL_D"] == float(np.float32(0.051))

    res = heliquad("params", "--port", board.port, "load", saved)    # back as it was
    assert res.returncode == 0 and "1 set, 5 already so, 0 refused" in res.stdout
    assert board.values["RATE_ROLL_P"] == float(np.float32(2.422))


# --- .params files ----------------------------------------------------------------------------

QGC_FILE = """\
# Onboard parameters for Vehicle 1
#
# Stack: ArduPilot
# Vehicle: Multi-Rotor
# Version: 4.5.7
# Git Revision: 0
#
# Vehicle-Id Component-Id Name Value Type
1\t1\tACRO_BAL_PITCH\t1.000000000000000000\t9
1\t1\tACRO_OPTIONS\t0\t2
1\t1\tATC_RAT_RLL_P\t0.135000005364418030\t9
"""


def test_a_qgroundcontrol_file_is_read_with_its_types(tmp_path):
    path = tmp_path / "qgc.params"
    path.write_text(QGC_FILE)
    assert read_params_file(path) == [("ACRO_BAL_PITCH", 1.0, 9), ("ACRO_OPTIONS", 0.0, 2),
                                      ("ATC_RAT_RLL_P", 0.135000005364418030, 9)]


def test_a_file_mavproxy_saved_is_read(tmp_path):
    # pymavlink's own writer (MAVProxy's "param save"): "%-16.16s %f" per parameter.
    from pymavlink import mavparm

    saved = mavparm.MAVParmDict()
    for name, value, _, _ in PARAMS:
        saved[name] = value
    path = tmp_path / "mavproxy.parm"
    saved.save(str(path))
    read = {name: value for name, value, _ in read_params_file(path)}
    assert read == pytest.approx({name: v for name, v, _, _ in PARAMS}, abs=1e-6)


def test_values_written_read_back_as_the_same_single_precision_float(tmp_path):
    rng = np.random.default_rng(3)
    values = np.concatenate([rng.standard_normal(200) * 10.0 ** rng.integers(-12, 12, 200),
                             [0.0, -0.0, 1e-45, 3.4028235e38, 0.1, 1 / 3]]).astype(np.float32)
    params = [Param(f"P{i}", float(v), REAL32, i) for i, v in enumerate(values)]
    params.append(Param("WHOLE", 16777216.0, INT32, len(params)))
    path = tmp_path / "w.params"
    write_params_file(path, params, header="test")
    back = {name: (value, ptype) for name, value, ptype in read_params_file(path)}
    for p in params:
        assert np.float32(back[p.name][0]) == np.float32(p.value) and back[p.name][1] == p.type
    assert "1\t1\tWHOLE\t16777216\t6" in path.read_text()


@pytest.mark.parametrize("text, says", [
    ("A 1\nB 2 3\n", "line 2: 3 fields; expected NAME VALUE (MAVProxy) or SYSID COMPID NAME "
                     "VALUE TYPE (QGroundControl)"),
    ("# c\n\nA x\n", "line 3: A's value 'x' is not a number"),
    ("A nan\n", "line 1: A's value nan is not a finite number"),
    ("A 1\nA 2\n", "line 2: A again (first on line 1)"),
    ("ABCDEFGHIJKLMNOPQ 1\n", "line 1: 'ABCDEFGHIJKLMNOPQ' is not a parameter name"),
    ("1\t1\tA\t1\t11\n", "line 1: type 11 is not a MAV_PARAM_TYPE"),
    ("x\t1\tA\t1\t9\n", "line 1: the system id, component id and type must be whole numbers"),
    ("# only a comment\n", "no parameters in it"),
])
def test_a_bad_line_is_one_error_naming_file_and_line(tmp_path, text, says):
    path = tmp_path / "bad.params"
    path.write_text(text)
    with pytest.raises(InputError) as raised:
        read_params_file(path)
    assert str(raised.value).startswith(f"{path}") and says in str(raised.value)
    assert "\n" not in str(raised.value)


# --- the digits a file holds --------------------------------------------------------------

#: pymavlink's mavparm (MAVProxy's `param load`) treats a file value within this of the value
#: it holds as unchanged (MAVParmDict.mindelta, absolute, compared in double).
MAVPROXY_MINDELTA = 1e-6


def _float32_values():
    """Every firmware default, and 300 float32 values spread over each real parameter's
    range with their neighbours one unit in the last place away (fixed seed): the values a
    board can hold."""
    rng = np.random.default_rng(27)
    out = []
    for p in _firmware.param_table():
        ptype = INT32 if p.integer else REAL32
        out.append((p.name, np.float32(p.default), ptype))
        if p.integer:
            continue
        for f in rng.uniform(p.minimum, p.maximum, 100).astype(np.float32):
            for g in (f, np.nextafter(f, np.float32(np.inf)), np.nextafter(f, np.float32(-np.inf))):
                if p.minimum <= g <= p.maximum:
                    out.append((p.name, g, ptype))
    return out


@pytest.mark.parametrize("layout", ["qgc", "mavproxy"])
def test_every_value_a_file_holds_reads_back_as_its_float32_and_mavproxy_sees_no_change(
        tmp_path, layout):
    """`heliquad params save` (both layouts): each value reads back in Python as the same
    float32, and lies within MAVProxy's 1e-6 of it (pymavlink's own mavparm.load, given the
    float32s as MAVProxy holds them, sends no set: an unchanged file loads as unchanged)."""
    from pymavlink import mavparm

    values = _float32_values()
    assert len(values) > 3000
    board = len(_firmware.param_table())
    for start in range(0, len(values), board):         # a file per board's worth of names
        chunk = {name: (v, t) for name, v, t in values[start:start + board]}
        path = tmp_path / f"{layout}-{start}.params"
        params = [Param(n, float(v), t, i) for i, (n, (v, t)) in enumerate(chunk.items())]
        write_params_file(path, params, layout=layout)
        read = {name: value for name, value, _ in read_params_file(path)}
        assert set(read) == set(chunk)
        for name, (v, _) in chunk.items():
            assert np.float32(read[name]) == v, (name, float(v), read[name])
            assert abs(read[name] - float(v)) <= MAVPROXY_MINDELTA / 2, (name, float(v))
        if layout == "mavproxy":
            held = mavparm.MAVParmDict()
            held.update({name: float(v) for name, (v, _) in chunk.items()})
            sent = []

            class Board:                                   # records what a load would send
                def param_set_send(self, name, value, parm_type=None):
                    sent.append((name, value))

                def recv_match(self, **kwargs):
                    return None

            held.load(str(path), mav=Board())
            assert sent == []
