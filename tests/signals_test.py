"""How heliquad's processes take signals, ports and their own stop (host/process/signals.py,
host/cli/parser.py): a Ctrl-C wherever it lands, a signal the program was started with ignored,
SIGHUP, one program to a port, what a late reader of ``heliquad board`` gets, and the
board's orderly stop that lands it and keeps its parameters.

Every signal is sent at a point the test observes (an import under way, a line printed, a
file grown), and every outcome is checked on what the run said and wrote."""

import errno
import os
import select
import signal
import subprocess
import sys
import time

import pytest

from tool_runs import (Tool, as_foreground_job, assert_nothing_left, one_line, private_tmpdir,
                       size, wait_for)

#: A console script as pip writes it (``from heliquad.host.cli.program import entry; entry()``),
#: that sends itself SIGINT as the interpreter starts importing the module named first on
#: its command line: the signal lands there, whatever the machine's speed.
INTERRUPTED_IMPORT = """
import builtins, os, signal, sys
target = sys.argv.pop(1)
real_import = builtins.__import__
def importing(name, *args, **kwargs):
    if name == target:
        builtins.__import__ = real_import
        os.kill(os.getpid(), signal.SIGINT)
    return real_import(name, *args, **kwargs)
builtins.__import__ = importing
sys.argv[0] = "heliquad"
from heliquad.host.cli.program import entry
entry()
"""


@pytest.fixture
def tmpdir_(tmp_path):
    with private_tmpdir(tmp_path) as tmp:
        yield tmp


_foreground = as_foreground_job


# Where a Ctrl-C can land while `heliquad params` starts: the command line's own modules
# (argparse, re, errors), the commands' parsers (parsing: `commands`, `shared_options`), and
# while the command runs numpy (the parameters' values), the link's `connection` and
# pyserial. Before the fix the first five gave a KeyboardInterrupt traceback and exit -2.
@pytest.mark.parametrize("target", ["argparse", "re", "errors", "commands", "shared_options",
                                    "numpy", "connection", "serial"])
def test_a_ctrl_c_while_the_program_imports_is_one_line_and_130(target, tmp_path):
    res = subprocess.run([sys.executable, "-c", INTERRUPTED_IMPORT, target, "params", "--port",
                          tmp_path / "no-board", "list"], capture_output=True, text=True,
                         timeout=120, preexec_fn=_foreground)
    assert (res.returncode, res.stderr) == (130, "heliquad params: interrupted\n"), res.stderr


def test_a_ctrl_c_at_start_names_a_command_with_a_dash(tmp_path):
    res = subprocess.run([sys.executable, "-c", INTERRUPTED_IMPORT, "argparse", "mavlink-dialect",
                          "--out", tmp_path / "d"], capture_output=True, text=True, timeout=120,
                         preexec_fn=_foreground)
    assert (res.returncode, res.stderr) == (130, "heliquad mavlink-dialect: interrupted\n")
    assert not (tmp_path / "d").exists()


def test_the_console_script_is_the_program_module():
    # The installed `heliquad` takes the signals before it imports the command line.
    from importlib.metadata import entry_points

    script, = [e for e in entry_points(group="console_scripts") if e.name == "heliquad"]
    assert script.value == "heliquad.host.cli.program:entry"


def _ignored(pid: int) -> int:
    """The process's ignored-signals mask (/proc/PID/status SigIgn)."""
    with open(f"/proc/{pid}/status") as fh:
        return int(next(ln for ln in fh if ln.startswith("SigIgn:")).split()[1], 16)


def test_a_command_started_with_sigint_ignored_keeps_ignoring_it_and_sigterm_stops_it(
        tmpdir_, tmp_path):
    # As a non-interactive shell starts `heliquad board &` (and a CI runner its jobs):
    # SIGINT ignored. POSIX's way for background jobs is to keep ignoring it: a terminal's
    # Ctrl-C is not for them. SIGTERM still stops it in order.
    rig = tmp_path / "rig"
    board = subprocess.Popen(
        [sys.executable, "-m", "heliquad.host.cli.parser", "board", "--telemetry", str(rig)],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
        env=dict(os.environ, TMPDIR=str(tmpdir_)),
        preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_IGN))
    try:
        assert "board running" in board.stdout.readline()
        assert _ignored(board.pid) & (1 << (signal.SIGINT - 1))
        board.send_signal(signal.SIGINT)                   # discarded by the kernel
        board.send_signal(signal.SIGTERM)
        out, err = board.communicate(timeout=120)
    finally:
        if board.poll() is None:
            board.kill()
            board.communicate()
    assert board.returncode == 143 and one_line(err) == "heliquad board: terminated", err
    assert "stopped after" in out
    assert not os.path.lexists(rig)
    assert_nothing_left(tmpdir_)


@pytest.mark.parametrize("send", ["ctrl_c", "sigterm", "sighup"])
def test_the_board_lands_and_keeps_a_parameter_set_while_armed(send, tmpdir_, tmp_path):
    # heliquad board --param-store: a gain set while it hovers armed is in force at once,
    # and said to be saved at disarm; an orderly stop (Ctrl-C, SIGTERM, SIGHUP) disarms
    # first, as a pilot does before power-off, and the save completes before the board
    # exits: the next board starts with the value. (Before: always armed, never saved.)
    rig, store = tmp_path / "rig", tmp_path / "store.bin"
    board = Tool("board", "--telemetry", rig, "--param-store", store, tmpdir=tmpdir_)
    assert "board running" in board.readline()
    res = _heliquad("params", "--port", rig, "set", "RATE_YAW_KC", 6.5)
    assert res.returncode == 0, res.stderr
    assert res.stdout.strip() == ("RATE_YAW_KC: 7.393 -> 6.5 (in force now; the board is "
                                  "armed: it saves the change when it disarms)")
    getattr(board, send)()
    code, out, err = board.finish()
    word, expected = {"ctrl_c": ("interrupted", 130), "sigterm": ("terminated", 143),
                      "sighup": ("hung up", 129)}[send]
    assert code == expected and one_line(err) == f"heliquad board: {word}", err
    assert "did not disarm" not in out
    again = Tool("board", "--telemetry", rig, "--param-store", store, tmpdir=tmpdir_)
    assert "board running" in again.readline()
    res = _heliquad("params", "--port", rig, "get", "RATE_YAW_KC")
    again.sigterm()
    assert again.finish()[0] == 143
    assert res.stdout.split() == ["RATE_YAW_KC", "6.5"], res.stderr
    assert_nothing_left(tmpdir_)


def _heliquad(*args):
    return subprocess.run([sys.executable, "-m", "heliquad.host.cli.parser", *map(str, args)],
                          capture_output=True, text=True, timeout=120, stdin=subprocess.DEVNULL)


def test_a_second_program_on_a_port_in_use_is_refused_and_the_first_loses_nothing(
        tmpdir_, tmp_path):
    # Two programs reading one serial port share its bytes: each gets some. The port is
    # opened for one program alone; the second says so in one line (exit 1) and the log
    # of the first has every sample.
    from heliquad.host.acquire.log_session import summarise_tlog

    rig, out = tmp_path / "rig", tmp_path / "flight.tlog"
    # All its telemetry kept for the reader: the first log's every sample is asserted.
    board = Tool("board", "--telemetry", rig, "--backlog-bytes", 0, tmpdir=tmpdir_)
    assert "board running" in board.readline()
    log = Tool("log", "--port", rig, "--out", out, tmpdir=tmpdir_)
    assert "logging" in log.readline()
    wait_for(lambda: size(out) > 20_000, "a log under way", log.proc)
    second = [_heliquad("params", "--port", rig, "list"),
              _heliquad("log", "--port", rig, "--out", tmp_path / "second.tlog")]
    grown = size(out)
    wait_for(lambda: size(out) > grown + 20_000, "the log going on", log.proc)
    log.ctrl_c()
    code, stdout, err = log.finish()
    board.ctrl_c()
    assert board.finish()[0] == 130
    for res in second:
        assert res.returncode == 1, res.stderr
        assert one_line(res.stderr).endswith(f"error: {rig} is busy: another program has it "
                                             "open (a second heliquad log, params or sweep on "
                                             "the same port?); stop that one first")
    assert not (tmp_path / "second.tlog").exists()
    assert code == 130, err
    s = summarise_tlog(str(out))
    assert s["damage"] is None and s["lost"] == 0 and s["samples"] > 200, s
    assert_nothing_left(tmpdir_)


#: What the board's telemetry may hold for a reader that opens late: the firmware's bound
#: (sim.board.TELEMETRY_BACKLOG_BYTES, 4095: a few KiB, as a board's USB or UART buffer),
#: plus the writes the kernel had not yet moved into the pty's line discipline when the
#: firmware last looked (one loop's telemetry, about 110 bytes, a write; measured 0 to 112
#: over; 4 KiB allows 37 of them on a loaded machine). Unbounded it was 84 085 bytes.
BACKLOG_BYTES, IN_FLIGHT_BYTES = 4095, 4096


@pytest.mark.parametrize("firmware", ["host", pytest.param("teensy35", marks=pytest.mark.pil)])
def test_a_late_reader_of_the_board_gets_at_most_a_few_kib_of_the_past(firmware, tmpdir_,
                                                                       tmp_path):
    # Nobody reads the board's telemetry for 4 s (the pty held about 3 s, 68 KiB, before
    # the bound: a late reader read them, then a gap). Then the board is paused (SIGSTOP:
    # no new telemetry) and a reader opens the port without discarding what waits there,
    # as a terminal program would: it gets what waited, at most the bound.
    import teensy_image

    rig = tmp_path / "rig"
    env = {"HQ_TEENSY35_ELF": str(teensy_image.image().elf)} if firmware == "teensy35" else {}
    board = Tool("board", "--telemetry", rig, "--firmware", firmware, tmpdir=tmpdir_, env=env)
    assert "board running" in board.readline()
    time.sleep(4.0)                          # unread telemetry; the bound holds at any time
    os.kill(board.pid, signal.SIGSTOP)
    try:
        fd = os.open(rig, os.O_RDONLY | os.O_NOCTTY | os.O_NONBLOCK)
        try:
            waited = _drain(fd)
        finally:
            os.close(fd)
    finally:
        os.kill(board.pid, signal.SIGCONT)
    board.ctrl_c()
    code, out, err = board.finish()
    assert code == 130, out + err
    assert 0 < waited <= BACKLOG_BYTES + IN_FLIGHT_BYTES, waited
    assert_nothing_left(tmpdir_)


def _drain(fd: int, quiet_s: float = 0.5) -> int:
    """Bytes read until none has come for ``quiet_s``."""
    total = 0
    while select.select([fd], [], [], quiet_s)[0]:
        try:
            data = os.read(fd, 65536)
        except BlockingIOError:
            continue
        except OSError as exc:               # EIO: the other end closed
            assert exc.errno == errno.EIO
            break
        if not data:
            break
        total += len(data)
    return total


@pytest.mark.parametrize("exc, code", [
    ("LinkLost('telemetry link lost: x')", 1),
    ("BoardRefused('the board refused A = 1 and kept 0')", 1),
    ("DiskFull('out.tlog', 'No space left on device')", 1),
    ("OSError(errno.EIO, 'Input/output error', '/dev/ttyACM0')", 1),
    ("OSError(errno.ENXIO, 'No such device or address', '/dev/ttyACM0')", 1),
    ("InputError('--freq-hz must be positive')", 2),
    ("OSError(errno.EACCES, 'Permission denied', 'out.csv')", 2),
    ("OSError(errno.EIO, 'Input/output error', 'points.csv')", 2),   # a failing disk's file
    ("KeyboardInterrupt()", 130), ("Terminated()", 143), ("HungUp()", 129),
])
def test_one_rule_turns_every_ending_into_its_exit_code(exc, code, capsys):
    # 2: the user's input; 1: the board refused, went away or fell silent, a disk filled;
    # 130, 143, 129: SIGINT, SIGTERM, SIGHUP (host/cli/parser.py).
    from heliquad.host.cli import parser as cli
    from heliquad.host.process.signals import HungUp, Terminated
    from heliquad.sim.base.errors import BoardRefused, DiskFull, InputError, LinkLost

    names = dict(errno=errno, LinkLost=LinkLost, BoardRefused=BoardRefused, DiskFull=DiskFull,
                 InputError=InputError, Terminated=Terminated, HungUp=HungUp)
    assert cli._ending("heliquad x", eval(exc, names)) == code
    assert capsys.readouterr().err.count("\n") == 1
