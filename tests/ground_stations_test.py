"""Real ground-station software against the simulated board (``heliquad board``, the
firmware in real time on a pty): MAVSDK (the Python package, which carries the C++ library)
and MAVProxy, as their users run them. Each test skips, saying why, where its client is not
installed; CI installs both (.ci/run), so there they run.

What is checked is what each client reports, never how fast: every wait is for a condition,
bounded by a generous guard against a hang."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import threading

import pytest

from heliquad.sim.dialect import dialect

MAV = dialect()
#: A guard against a hang, never a measure: clients and the board on a loaded machine.
GUARD_S = 60.0
#: The integer parameters and their documented defaults (docs/parameters.md).
INTEGER_DEFAULTS = {**{f"ESC{i}_MIN": 1000 for i in range(1, 6)},
                    **{f"ESC{i}_MAX": 2000 for i in range(1, 6)},
                    "RC_SW_HIGH": 1700, "RC_SW_LOW": 1300, "RC_THR_LOW": 1100,
                    "EXC_MIN_FADE": 1, "IMU_PATH": 0, "MAV_GCS_SYSID": 0}


class Board:
    """``heliquad board`` in a process of its own; stopped with Ctrl-C as a user does."""

    def __init__(self, tmp_path, *extra):
        self.port = str(tmp_path / "board")
        self.proc = subprocess.Popen(
            [sys.executable, "-m", "heliquad.host.cli", "board", "--telemetry", self.port,
             "--param-store", str(tmp_path / "store.bin"), *extra],
            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
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
        pytest.importorskip("mavsdk", reason="MAVSDK (pip install mavsdk) is not installed")
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
    """The 14 non-zero integer parameters read as their values (they read as raw float bits
    while the board encoded them C-cast); set_param_int and set_param_float are taken and read
    back."""
    from mavsdk.plugins.param import Param

    param = sdk_on(disarmed_board).plugin(Param)
    everything = param.get_all_params()
    ints = {p.name: p.value for p in everything.int_params}
    floats = {p.name: p.value for p in everything.float_params}
    assert ints == INTEGER_DEFAULTS
    assert len(floats) == 44 - len(INTEGER_DEFAULTS)
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
