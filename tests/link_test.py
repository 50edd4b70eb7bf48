"""The host's telemetry link when the other end goes away, and a session over a port
waiting for the board to be armed."""

import os

import pytest

from heliquad import _firmware
from heliquad.host.acquire.link import TelemetryLink
from heliquad.sim.base.errors import InputError


def test_a_send_on_a_port_that_went_away_is_the_link_lost():
    # A board unplugged (here: the pty's other end closed) under a heartbeat, a command or a
    # stop: one error the tools already say in one line, not pyserial's exception. (A read
    # cannot tell a port gone from no data, VMIN = 0: the sessions' sample timeout sees it.)
    main, side = os.openpty()
    link = TelemetryLink(os.ttyname(side))
    os.close(side)
    try:
        link.heartbeat()                       # reaches the open pty
        os.close(main)
        for send in (link.heartbeat, link.stop_excitation, lambda: link.arm(False)):
            with pytest.raises(InputError, match="^telemetry link lost: "):
                send()
    finally:
        link.close()


class FakeBoard:
    """The board's end of a pty: HQ_SYSID_SAMPLEs written on demand, armed or not."""

    def __init__(self):
        from heliquad.sim.base.dialect import dialect

        self.main, side = os.openpty()
        self.port = os.ttyname(side)
        self.side = side
        self.mav = dialect().MAVLink(None, srcSystem=1, srcComponent=1)
        self.seq = 0

    def send_samples(self, n, armed):
        for _ in range(n):
            self.seq += 1
            msg = self.mav.hq_sysid_sample_encode(self.seq * 5000, self.seq, 0, 0, 0, int(armed),
                                                  0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0,
                                                  5, [0.4] * 5 + [0.0] * 3)
            os.write(self.main, msg.pack(self.mav))

    def close(self):
        os.close(self.main)
        os.close(self.side)


@pytest.fixture
def board_session(tmp_path):
    from heliquad.host.acquire.session import PortSession

    board = FakeBoard()
    session = PortSession(board.port, str(tmp_path / "s.tlog"), poll_s=0.0)
    yield board, session
    session.close()
    board.close()


def test_a_sweep_over_a_port_waits_for_the_pilot_to_arm(board_session):
    # An excitation sent before the board is armed would be refused: the session waits for
    # an armed sample and says once that it is waiting; here the pilot arms when it does.
    board, session = board_session
    board.send_samples(3, armed=False)
    said = []

    def progress(text):
        said.append(text)
        board.send_samples(2, armed=True)

    session.hover(progress)
    assert said == ["waiting for the board to be armed (the pilot's arm switch) ..."]


def test_a_board_already_armed_starts_at_once(board_session):
    board, session = board_session
    board.send_samples(2, armed=True)
    session.hover(lambda text: pytest.fail(text))


def test_a_board_never_armed_or_silent_ends_with_one_line(board_session, monkeypatch):
    from heliquad.host.acquire import session as session_module

    board, session = board_session
    monkeypatch.setattr(session_module, "FIRST_SAMPLE_WAIT_S", 0.0)
    with pytest.raises(InputError, match=f"^no samples from the board in 0 s: is {board.port} "
                                         "its telemetry port, and is it running\\?$"):
        session.hover(print)
    monkeypatch.setattr(session_module, "ARM_WAIT_S", 0.0)
    board.send_samples(1, armed=False)
    with pytest.raises(InputError, match="^the board was not armed within 0 s; arm it, then "
                                         "run the sweep again$"):
        session.hover(lambda text: None)


# --- The link over a network: a forwarder between a board's pty and UDP or TCP -------------

class Relay:
    """What a network forwarder does (MAVProxy's --out, ser2net, a companion computer's
    router): the bytes of a board's serial port (a pty path) to and from a socket, in a
    thread. ``mode``: ``udp`` (listens; sends to whoever sent to it last), ``udp-push``
    (sends to a given port: the client listens), ``tcp`` (listens for one client),
    ``tcp-out`` (connects to a listening client)."""

    def __init__(self, board_port, mode, client_port=None):
        import socket
        import threading

        import serial

        self.board = serial.Serial(str(board_port), timeout=0)     # raw mode, as a reader sets
        self.mode, self.peer, self.conn = mode, None, None
        if mode.startswith("udp"):
            self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
            self.sock.bind(("127.0.0.1", 0))
            if mode == "udp-push":
                self.peer = ("127.0.0.1", client_port)
        elif mode == "tcp":
            self.sock = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
            self.sock.bind(("127.0.0.1", 0))
            self.sock.listen(1)
        else:
            self.sock, self.client_port = None, client_port
        self.port = self.sock.getsockname()[1] if self.sock else None
        self.to_client = self.to_board = 0
        self.stopping = threading.Event()
        self.thread = threading.Thread(target=self._run, daemon=True)
        self.thread.start()

    def _connect_out(self):
        import socket

        try:
            self.conn = socket.create_connection(("127.0.0.1", self.client_port), timeout=1)
        except OSError:
            self.conn = None                     # not listening yet: the next turn tries again

    def _run(self):
        import select

        while not self.stopping.is_set():
            if self.mode == "tcp-out" and self.conn is None:
                self._connect_out()
            readers = [self.board.fileno()] + [s for s in (self.sock, self.conn) if s]
            ready, _, _ = select.select(readers, [], [], 0.05)
            try:
                self._forward(ready)
            except OSError:                      # the client went away: wait for the next
                if self.conn is not None:
                    self.conn.close()
                self.conn = None

    def _forward(self, ready):
        if self.board.fileno() in ready:
            self._to_client(self.board.read(65536))
        if self.sock in ready and self.mode == "tcp":
            self.conn, _ = self.sock.accept()
        elif self.sock in ready:
            data, self.peer = self.sock.recvfrom(65536) if self.mode == "udp" else \
                (self.sock.recv(65536), self.peer)
            self._to_board(data)
        if self.conn is not None and self.conn in ready:
            data = self.conn.recv(65536)
            if not data:
                raise ConnectionResetError("closed")
            self._to_board(data)

    def _to_client(self, data):
        if self.mode.startswith("udp") and self.peer:
            self.sock.sendto(data, self.peer)
        elif self.conn is not None:
            self.conn.sendall(data)
        else:
            return                               # nobody to send to yet: dropped
        self.to_client += len(data)

    def _to_board(self, data):
        self.board.write(data)
        self.to_board += len(data)

    def close(self):
        self.stopping.set()
        self.thread.join(timeout=10)
        for s in (self.conn, self.sock):
            if s is not None:
                s.close()
        self.board.close()


def free_port(kind):
    """A port nothing listens on now (the client binds it next)."""
    import socket

    s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM if kind == "udp" else socket.SOCK_STREAM)
    s.bind(("127.0.0.1", 0))
    port = s.getsockname()[1]
    s.close()
    return port


#: client connection -> the relay's mode
NETWORK_CASES = {"udpout": "udp", "udpin": "udp-push", "tcp": "tcp", "tcpin": "tcp-out"}


def relay_and_connection(board_port, kind):
    """A relay from the board's port, and the client's connection string to it."""
    client_port = free_port("udp" if kind.startswith("udp") else "tcp")
    relay = Relay(board_port, NETWORK_CASES[kind], client_port)
    port = relay.port if kind in ("udpout", "tcp") else client_port
    host = "127.0.0.1" if kind in ("udpout", "tcp") else "0.0.0.0"
    return relay, f"{kind}:{host}:{port}"


def until(condition, what, timeout_s=60.0):
    """Poll until condition() holds (a hang guard, never a measurement)."""
    import time

    deadline = time.monotonic() + timeout_s
    while not condition():
        assert time.monotonic() < deadline, f"no {what} within {timeout_s:g} s (hang guard)"
        time.sleep(0.01)


def heartbeats_in(data: bytes) -> int:
    from heliquad.sim.base.dialect import dialect
    from heliquad.sim.base.framing import Codec, Framer

    codec = Codec(dialect())
    hb = dialect().MAVLINK_MSG_ID_HEARTBEAT
    return sum(msgid == hb for msgid, _, _ in Framer(codec).feed(data))


@pytest.mark.parametrize("kind", NETWORK_CASES)
def test_the_link_carries_telemetry_and_commands_over_the_network(kind):
    # The same TelemetryLink over a forwarder: the board's samples come in, the host's
    # heartbeat goes out. A listening link (udpin:, tcpin:) sends only once it has heard from
    # the board: its first heartbeat is skipped, a command refused in one line saying why.
    board = FakeBoard()
    relay, conn = relay_and_connection(board.port, kind)
    link = TelemetryLink(conn)
    try:
        if kind in ("udpin", "tcpin"):
            link.heartbeat()                                  # nowhere to go yet: skipped
            with pytest.raises(InputError, match=f"^{conn} has heard nothing from the board yet"):
                link.arm(False)
        if kind == "tcpin":
            until(lambda: relay.conn is not None, "connection from the relay")
        seqs = []

        def got_samples():
            link.heartbeat()           # as a session does: udpout's relay learns its address
            board.send_samples(1, armed=True)
            seqs.extend(m.seq for m in link.poll(only=("HQ_SYSID_SAMPLE",)))
            return len(seqs) >= 5

        until(got_samples, "samples over the link")
        assert seqs == sorted(seqs) and len(set(seqs)) == len(seqs)
        received = bytearray()

        def board_heard_a_heartbeat():
            link.heartbeat()
            try:
                received.extend(os.read(board.main, 65536))
            except BlockingIOError:
                pass
            return heartbeats_in(bytes(received)) > 0

        os.set_blocking(board.main, False)
        until(board_heard_a_heartbeat, "heartbeat at the board")
    finally:
        link.close()
        relay.close()
        board.close()


def test_a_tcp_board_that_hangs_up_is_the_link_lost():
    board = FakeBoard()
    relay, conn = relay_and_connection(board.port, "tcp")
    link = TelemetryLink(conn)
    try:
        until(lambda: relay.conn is not None, "the connection")
        relay.close()                                           # the forwarder goes away
        with pytest.raises(InputError, match=f"^telemetry link lost: {conn}: "):
            until(lambda: link.poll() is None, "the link lost")
    finally:
        link.close()
        board.close()


@pytest.mark.parametrize("conn, says", [
    ("tcp:127.0.0.1:{closed}", "cannot open tcp:127.0.0.1:{closed}: Connection refused"),
    ("udpout:127.0.0.1", "udpout:127.0.0.1: expected udpout:HOST:PORT"),
    ("tcp:127.0.0.1:http", "tcp:127.0.0.1:http: the port must be a number from 1 to 65535, not 'http'"),
    ("udpin:0.0.0.0:70000", "udpin:0.0.0.0:70000: the port must be a number from 1 to 65535"),
    ("tcp:no-such-host.invalid:5760", "cannot open tcp:no-such-host.invalid:5760: "),
    ("ws:127.0.0.1:5760", "ws:127.0.0.1:5760: unknown connection ws:; use a serial device or "
                          "one of udpin:HOST:PORT"),
])
def test_a_bad_network_connection_is_one_line_naming_it(conn, says, tmp_path):
    closed = free_port("tcp")
    conn, says = conn.format(closed=closed), says.format(closed=closed)
    res = heliquad("log", "--port", conn, "--out", tmp_path / "x.tlog")
    assert res.returncode == 2 and "Traceback" not in res.stderr
    assert res.stderr.startswith(f"heliquad log: error: {says}") and res.stderr.count("\n") == 1
    assert not (tmp_path / "x.tlog").exists()          # the link first: nothing created


def heliquad(*args, **kw):
    import subprocess
    import sys

    return subprocess.run([sys.executable, "-m", "heliquad.host.cli.parser", *map(str, args)],
                          capture_output=True, text=True, timeout=120, **kw)


@pytest.fixture(scope="module")
def running_board(tmp_path_factory):
    """``heliquad board``: the simulated rig in real time, its telemetry on a pty."""
    import tool_runs

    # All its telemetry kept for the reader: a log's every sample is asserted.
    with tool_runs.running_board(tmp_path_factory.mktemp("board"), "--backlog-bytes", 0) as port:
        yield port


@pytest.mark.parametrize("kind", ["udpout", "udpin", "tcp"])
def test_heliquad_log_records_a_board_over_the_network(running_board, kind, tmp_path):
    # heliquad log --port udp...: a forwarded board is logged as a serial one is, every
    # sample between the first and the last there. Stopped with Ctrl-C once the log holds
    # a second of samples.
    import signal

    from heliquad.host.acquire.log_session import summarise_tlog
    from tool_runs import cli

    relay, conn = relay_and_connection(running_board, kind)
    out = tmp_path / "net.tlog"
    log = cli("log", "--port", conn, "--out", out)      # Ctrl-C-able however pytest started
    try:
        until(lambda: out.exists() and summarise_tlog(str(out))["samples"] >= 200
              or log.poll() is not None, "a second of samples in the log")
        log.send_signal(signal.SIGINT)
        stdout, stderr = log.communicate(timeout=60)
    finally:
        if log.poll() is None:
            log.kill()
            log.communicate()
        relay.close()
    assert log.returncode == 130 and stderr == "heliquad log: interrupted\n", stderr
    s = summarise_tlog(str(out))
    assert s["damage"] is None and s["lost"] == 0
    assert s["samples"] == s["last_seq"] - s["first_seq"] + 1 >= 200
    assert relay.to_board > 0                  # the host's heartbeats reached the board


MAVUTIL_CLIENT = """
import sys
from pymavlink import mavutil
m = mavutil.mavlink_connection(sys.argv[1])
m.mav.heartbeat_send(mavutil.mavlink.MAV_TYPE_GCS, mavutil.mavlink.MAV_AUTOPILOT_INVALID, 0, 0, 0)
hb = m.recv_match(type="HEARTBEAT", blocking=True, timeout=60)
att = m.recv_match(type="ATTITUDE", blocking=True, timeout=60)
print(hb.get_srcSystem(), hb.type, att is not None)
"""


@pytest.mark.parametrize("kind", ["udpout", "tcp"])
def test_pymavlink_reads_the_forwarded_board(running_board, kind):
    # The same forwarder serves pymavlink's own tools: mavutil connects as a ground station
    # would and decodes the board's HEARTBEAT and ATTITUDE (common messages).
    import subprocess
    import sys

    relay, conn = relay_and_connection(running_board, kind)
    try:
        res = subprocess.run([sys.executable, "-c", MAVUTIL_CLIENT, conn], capture_output=True,
                             text=True, timeout=120,
                             env=dict(os.environ, MAVLINK20="1", MAVLINK_DIALECT="common"))
    finally:
        relay.close()
    assert res.returncode == 0, res.stderr
    sysid, mav_type, attitude = res.stdout.split()
    assert sysid == "1" and attitude == "True"


MAVUTIL_PARAMS = """
import os, sys
os.environ["MAVLINK20"] = "1"
import pymavlink.dialects.v20 as v20
from heliquad.sim.base.dialect import dialect
MAV = dialect()
sys.modules["pymavlink.dialects.v20.heliquad"] = v20.heliquad = MAV
from pymavlink import mavutil
m = mavutil.mavlink_connection(sys.argv[1], dialect="heliquad", source_system=255,
                               source_component=190)
m.mav.heartbeat_send(MAV.MAV_TYPE_GCS, MAV.MAV_AUTOPILOT_INVALID, 0, 0, 0)
m.wait_heartbeat(timeout=60)
values, count = {}, None
m.mav.param_request_list_send(1, 1)
for _ in range(200):
    p = m.recv_match(type="PARAM_VALUE", blocking=True, timeout=1)
    if p is None:                      # lost on the way: ask again for what is missing
        for i in range(count or 0):
            if i not in values:
                m.mav.param_request_read_send(1, 1, b"", i)
        if count is None:
            m.mav.param_request_list_send(1, 1)
        continue
    count = p.param_count
    values[p.param_index] = (p.param_id, p.param_value)
    if len(values) == count:
        break

def set_and_read(value):
    m.mav.param_set_send(1, 1, b"RATE_RLL_KC", value, MAV.MAV_PARAM_TYPE_REAL32)
    for _ in range(100):
        p = m.recv_match(type="PARAM_VALUE", blocking=True, timeout=1)
        if p is not None and p.param_id == "RATE_RLL_KC":
            return p.param_value
    return None

old = dict(values.values())["RATE_RLL_KC"]
new = set_and_read(2.9)
back = set_and_read(old)
print(len(values), count, round(new, 4), round(back, 4))
"""


@pytest.mark.parametrize("kind", ["udpout", "tcp"])
def test_parameters_over_the_network_with_mavutil_and_heliquad_params(running_board, kind):
    # Through the forwarder, pymavlink's mavutil as a ground station: every parameter of the
    # simulated board fetched, a gain set and set back; then heliquad params lists them.
    import subprocess
    import sys

    relay, conn = relay_and_connection(running_board, kind)
    try:
        res = subprocess.run([sys.executable, "-c", MAVUTIL_PARAMS, conn], capture_output=True,
                             text=True, timeout=300)
        listed = heliquad("params", "--port", conn, "list")
    finally:
        relay.close()
    assert res.returncode == 0, res.stderr
    count = str(len(_firmware.param_table()))
    assert res.stdout.split() == [count, count, "2.9", "2.422"]
    assert listed.returncode == 0, listed.stderr
    rows = [line.split() for line in listed.stdout.splitlines() if line.startswith("RATE_")]
    assert len(rows) == 12 and ["RATE_RLL_KC", "2.422", "REAL32"] in rows
