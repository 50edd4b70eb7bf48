"""Real ground-station software against the simulated board (``heliquad board``, the
firmware in real time on a pty): MAVSDK (the Python package, which carries the C++ library)
and MAVProxy, as their users run them. Each test skips, saying why and how to install it,
where its client is not installed; CI installs both (.ci/run: the ``gcs`` extra, and MAVProxy
1.8.75 without its declared dependencies), and there (CI set) a missing client fails.

What is checked is what each client reports, never how fast: every wait is for a condition,
bounded by a generous guard against a hang."""

from __future__ import annotations

import importlib.metadata
import importlib.util
import os
import re
import signal
import struct
import subprocess
import sys
import threading

import pytest

from heliquad import _firmware
from heliquad.sim.base.dialect import dialect
from private_pymavlink import private_pymavlink
from tool_runs import cli

MAV = dialect()
#: A guard against a hang, never a measure: clients and the board on a loaded machine.
GUARD_S = 60.0
#: The integer parameters and their documented defaults (docs/parameters.md).
#: The firmware's parameters: a ground station fetches and loads this many.
PARAM_COUNT = len(_firmware.param_table())
INTEGER_DEFAULTS = {**{f"ESC{i}_MIN": 1000 for i in range(1, 9)},
                    **{f"ESC{i}_MAX": 2000 for i in range(1, 9)},
                    "RC_SW_HIGH": 1700, "RC_SW_LOW": 1300, "RC_THR_LOW": 1100,
                    "EXC_MIN_FADE": 1, "IMU_PATH": 0, "MAV_GCS_SYSID": 0,
                    "SER_TEL1_BAUD": 921600, "CA_ROTOR_COUNT": 5}


#: How each client is installed (pyproject's ``gcs`` extra; MAVProxy without its declared
#: dependencies, which pull vtk and opencv, none of which it needs here).
MAVSDK_INSTALL = "pip install mavsdk==4.1.0 (heliquad's gcs extra)"
MAVPROXY_INSTALL = "pip install --no-deps MAVProxy==1.8.75"
#: The MAVProxy whose behaviour the test states (how it reads INT32 values).
MAVPROXY_VERSION = "1.8.75"


def need(module: str, install: str, version: str | None = None) -> None:
    """Skip, saying how to install it, where the client ``module`` (at ``version``, if
    given) is absent; in CI (CI set) fail instead: CI installs both, and a client gone
    missing must not pass as a skip."""
    if importlib.util.find_spec(module) is not None:
        if version is None or importlib.metadata.version(module) == version:
            return
        message = f"{module} {importlib.metadata.version(module)} is installed, the test " \
                  f"states {module} {version}'s behaviour: {install}"
    else:
        message = f"{module} is not installed: {install}"
    if os.environ.get("CI"):
        pytest.fail(message)
    pytest.skip(message)


def test_a_missing_client_skips_here_and_fails_in_ci(monkeypatch):
    monkeypatch.delenv("CI", raising=False)
    with pytest.raises(pytest.skip.Exception, match="no_such_gcs is not installed: pip x"):
        need("no_such_gcs", "pip x")
    monkeypatch.setenv("CI", "true")
    with pytest.raises(pytest.fail.Exception, match="no_such_gcs is not installed: pip x"):
        need("no_such_gcs", "pip x")
    with pytest.raises(pytest.fail.Exception, match="pytest 0.0 's behaviour|states pytest 0.0"):
        need("pytest", "pip y", "0.0")


class Board:
    """``heliquad board`` in a process of its own; stopped with Ctrl-C as a user does."""

    def __init__(self, tmp_path, *extra):
        self.port = str(tmp_path / "board")
        # Ctrl-C-able however pytest was started (tool_runs.cli: SIGINT at its default).
        self.proc = cli("board", "--telemetry", self.port,
                        "--param-store", tmp_path / "store.bin", *extra)
        line = self.proc.stdout.readline()
        assert "board running" in line, self.proc.stderr.read()
        self.device = os.path.realpath(self.port)

    def stop(self):
        self.proc.send_signal(signal.SIGINT)
        self.proc.communicate(timeout=GUARD_S)


@pytest.fixture
def disarmed_board(tmp_path):
    b = Board(tmp_path, "--disarmed")
    yield b
    b.stop()


@pytest.fixture
def armed_board(tmp_path):
    b = Board(tmp_path)
    yield b
    b.stop()


class Sdk:
    """MAVSDK on the board's pty, and the plugins a test asks for; closed in the order MAVSDK
    requires (plugins and systems before the instance)."""

    def __init__(self, board):
        need("mavsdk", MAVSDK_INSTALL)
        from mavsdk import ComponentType, Configuration, ConnectionResult, Mavsdk

        self.sdk = Mavsdk(Configuration.create_with_component_type(ComponentType.GROUND_STATION))
        url = f"serial://{board.device}:921600"
        assert self.sdk.add_any_connection(url) == ConnectionResult.SUCCESS
        self.system = self.sdk.first_autopilot(GUARD_S)
        assert self.system is not None, "MAVSDK found no autopilot on the board's link"
        self.plugins = []

    def plugin(self, cls):
        self.plugins.append(cls(self.system))
        return self.plugins[-1]

    def close(self):
        import gc

        self.plugins.clear()
        self.system = None
        gc.collect()
        self.sdk.destroy()


@pytest.fixture
def sdk_on():
    made = []

    def connect(board):
        made.append(Sdk(board))
        return made[-1]

    yield connect
    for s in made:
        s.close()


def first(subscribe, predicate=lambda v: True):
    """The first value a MAVSDK subscription delivers that satisfies ``predicate``."""
    got, seen = threading.Event(), []

    def on(value, _user=None):
        if not got.is_set() and predicate(value):
            seen.append(value)
            got.set()

    handle = subscribe(on)
    assert got.wait(GUARD_S), "never delivered"
    return seen[0], handle


def test_mavsdk_reads_and_sets_integer_and_real_parameters(disarmed_board, sdk_on):
    """The non-zero integer parameters read as their values (they read as raw float bits
    while the board encoded them C-cast); set_param_int and set_param_float are taken and read
    back."""
    from mavsdk.plugins.param import Param

    param = sdk_on(disarmed_board).plugin(Param)
    everything = param.get_all_params()
    ints = {p.name: p.value for p in everything.int_params}
    floats = {p.name: p.value for p in everything.float_params}
    assert ints == INTEGER_DEFAULTS
    assert len(floats) == PARAM_COUNT - len(INTEGER_DEFAULTS)
    assert floats["STK_YAW_MAX"] == 90.0 and floats["EXC_MAX_ANG"] == 45.0
    param.set_param_int("ESC1_MAX", 1900)
    assert param.get_param_int("ESC1_MAX") == 1900
    param.set_param_float("RATE_YAW_KC", 6.5)
    assert param.get_param_float("RATE_YAW_KC") == 6.5


def test_mavsdk_reports_a_refused_set_as_a_refusal_not_a_timeout(armed_board, sdk_on):
    """Armed, only the gains may change: MAVSDK hears PARAM_ERROR and says why at once."""
    from mavsdk.plugins.param import Param, ParamError, ParamResult
    from mavsdk.plugins.telemetry import Telemetry

    sdk = sdk_on(armed_board)
    first(sdk.plugin(Telemetry).subscribe_armed, bool)        # the pilot has armed it
    param = sdk.plugin(Param)
    with pytest.raises(ParamError) as refused:
        param.set_param_int("ESC1_MAX", 1900)
    assert refused.value.result == ParamResult.PERMISSION_DENIED
    with pytest.raises(ParamError) as refused:
        param.set_param_float("RATE_YAW_KC", 80.0)            # beyond 0.01 .. 50
    assert refused.value.result == ParamResult.VALUE_OUT_OF_RANGE
    assert param.get_param_int("ESC1_MAX") == 2000


def test_mavsdk_hears_the_imu_and_whether_the_vehicle_is_armable(disarmed_board, sdk_on):
    """imu() yields (HIGHRES_IMU: one g, body z down), and health says armable only while an
    arm command would arm: the board's pilot holds the arm switch low, so it is not."""
    from mavsdk.plugins.telemetry import Telemetry

    telemetry = sdk_on(disarmed_board).plugin(Telemetry)
    imu, _ = first(telemetry.subscribe_imu)
    acc = imu.acceleration_frd
    assert (acc.forward_m_s2 ** 2 + acc.right_m_s2 ** 2 + acc.down_m_s2 ** 2) ** 0.5 == \
        pytest.approx(9.81, rel=0.05)
    health, _ = first(telemetry.subscribe_health)
    assert health.is_armable is False                   # arm switch low: a command would not arm


def test_mavsdk_hears_an_armable_vehicle(armed_board, sdk_on):
    """The pre-arm check bit is healthy while armed (and whenever a command would arm)."""
    from mavsdk.plugins.telemetry import Telemetry

    telemetry = sdk_on(armed_board).plugin(Telemetry)
    health, _ = first(telemetry.subscribe_health, lambda h: h.is_armable)
    assert health.is_armable


# --- MAVProxy ------------------------------------------------------------------------------

def as_mavproxy_shows(value: int) -> float:
    """An INT32 value as MAVProxy 1.8.75 shows it: the float whose bits the firmware's
    byte-wise encoding filled (it reads INT32 values C-cast for every autopilot but PX4)."""
    return struct.unpack("<f", struct.pack("<i", value))[0]


class MavProxy:
    """mavproxy.py on the board's port as docs/ground-stations.md runs it (``--master``,
    ``--baudrate 921600``, ``--dialect heliquad`` from a private pymavlink with the dialect
    installed), commands typed on its stdin, its output read line by line. Not
    ``--non-interactive``: MAVProxy 1.8.75 then never reads stdin (its main thread sleeps
    where it would read commands). Each command waits for the output of the one before,
    never for time; closing stdin ends it (EOF is its exit)."""

    def __init__(self, board, folder):
        need("MAVProxy", MAVPROXY_INSTALL, MAVPROXY_VERSION)
        _, env = private_pymavlink(folder / "site")
        res = subprocess.run([sys.executable, "-m", "heliquad.host.cli.parser", "mavlink-dialect",
                              "--install"], capture_output=True, text=True, env=env,
                             timeout=GUARD_S * 5)
        assert res.returncode == 0, res.stderr
        self.proc = subprocess.Popen(
            [sys.executable, "-m", "MAVProxy.mavproxy", f"--master={board.device}",
             "--baudrate", "921600", "--dialect", "heliquad",
             "--state-basedir", str(folder / "state")],
            stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
            env=dict(env, PYTHONUNBUFFERED="1"), cwd=folder)
        self.lines, self.cursor, self.ended = [], 0, False
        self.changed = threading.Condition()
        self.reader = threading.Thread(target=self._read, daemon=True)
        self.reader.start()

    def _read(self):
        for line in self.proc.stdout:
            with self.changed:
                self.lines.append(line.rstrip("\n"))
                self.changed.notify_all()
        with self.changed:
            self.ended = True
            self.changed.notify_all()

    def type(self, command: str) -> None:
        self.proc.stdin.write(command + "\n")
        self.proc.stdin.flush()

    def expect(self, pattern: str) -> re.Match:
        """The first line from the cursor on in which ``pattern`` is found; the cursor moves
        past it. (Its prompt, ``MAV> `` or the mode's, may come first on a line.)"""
        regex = re.compile(pattern)

        def found():
            for i in range(self.cursor, len(self.lines)):
                m = regex.search(self.lines[i])
                if m:
                    self.cursor = i + 1
                    return m
            return self.ended or None

        with self.changed:
            m = self.changed.wait_for(found, GUARD_S)
        if not isinstance(m, re.Match):
            raise AssertionError(f"MAVProxy never printed {pattern!r}; its last lines:\n" +
                                 "\n".join(self.lines[-25:]))
        return m

    def since(self, start: int) -> list:
        with self.changed:
            return self.lines[start:self.cursor]

    def close(self):
        try:
            self.proc.stdin.close()
            self.proc.wait(timeout=GUARD_S)
        except (OSError, subprocess.TimeoutExpired):
            self.proc.kill()
            self.proc.wait()
        self.reader.join(GUARD_S)


def test_mavproxy_fetches_sets_and_loads_the_parameters_of_an_armed_board(armed_board, tmp_path):
    """MAVProxy 1.8.75 as a user types at it, the board armed by its pilot. It fetches the
    board's parameters; a REAL32 set is taken and read back; an out-of-range set and a bound
    changed while armed are refused, said why ("AP: ..."), and MAVProxy says it failed.

    Integer parameters: MAVProxy shows each non-zero one as a tiny number (ESC1_MAX as
    2.802596928649634e-42): the firmware sends INT32 values byte-wise, as MAVSDK and
    QGroundControl read them for a generic autopilot, and MAVProxy reads them C-cast for
    every autopilot but PX4. That is MAVProxy's reading, not fixed here; what it sends still
    works (every value as REAL32, which the firmware reads as the number).

    `param load` of the unchanged file `heliquad params save --mavproxy` wrote: no set for a
    REAL32 parameter (the file's digits are within MAVProxy's 1e-6 of each float32); the
    non-zero integers it misreads are re-sent, each the value the board has, and the
    firmware answers a set to the current value with it even while armed, never "changes
    only while disarmed"."""
    need("MAVProxy", MAVPROXY_INSTALL, MAVPROXY_VERSION)
    saved = tmp_path / "board.parm"
    res = subprocess.run([sys.executable, "-m", "heliquad.host.cli.parser", "params", "--port",
                          armed_board.port, "save", "--mavproxy", str(saved)],
                         capture_output=True, text=True, timeout=GUARD_S * 5)
    assert res.returncode == 0, res.stderr
    mp = MavProxy(armed_board, tmp_path)
    try:
        mp.expect(r"^ARMED$")
        mp.expect(rf"Received {PARAM_COUNT} parameters")
        mp.type("param show ESC1_MAX")
        assert float(mp.expect(r"\bESC1_MAX\s+(\S+)$").group(1)) == as_mavproxy_shows(2000)
        mp.type("param show STK_YAW_MAX")
        assert float(mp.expect(r"\bSTK_YAW_MAX\s+(\S+)$").group(1)) == 90.0

        start = mp.cursor
        mp.type(f"param load {saved}")
        loaded = mp.expect(rf"Loaded {PARAM_COUNT} parameters from .* \(changed (\d+)\)")
        sets = [re.search(r"changed (\w+) from (\S+) to (\S+)", line) for line in mp.since(start)]
        sets = {m.group(1): float(m.group(3)) for m in sets if m}
        resent = {name: float(v) for name, v in INTEGER_DEFAULTS.items() if v != 0}
        assert sets == resent and int(loaded.group(1)) == len(resent)

        mp.type("param watch ESC1_MAX")
        mp.type("param watch RATE_YAW_KC")
        start = mp.cursor
        mp.type("param set ESC1_MAX 2000")                # its value: answered, not refused
        mp.expect(r"> ESC1_MAX=2000\.000000")
        assert not [line for line in mp.since(start) if "ESC1_MAX" in line and "AP:" in line]

        mp.type("param set RATE_YAW_KC 6.5")             # a gain: taken while armed
        mp.expect(r"> RATE_YAW_KC=6\.500000")
        mp.type("param fetch RATE_YAW_KC")
        mp.expect(r"RATE_YAW_KC = 6\.5000000")

        mp.type("param set RATE_YAW_KC 80")              # beyond 0.01 .. 50
        mp.expect(r"AP: RATE_YAW_KC out of range 0\.01\.\.50")
        mp.expect(r"Failed to set RATE_YAW_KC to 80 \(invalid returned value 6\.5\)")
        mp.type("param set FS_ABORT_ANG 60")             # a bound: not while armed
        mp.expect(r"AP: FS_ABORT_ANG changes only while disarmed")
        mp.expect(r"Failed to set FS_ABORT_ANG to 60 \(invalid returned value 80\.0\)")
    finally:
        mp.close()
