"""The heliquad command line run as a user's terminal runs it, and what a run leaves behind
(not a test module: a helper the tests import).

* :class:`Tool` starts ``heliquad ...`` in its own process group, as a shell starts a
  foreground job (so that :meth:`Tool.ctrl_c` is a terminal's Ctrl-C: SIGINT to the whole
  group), with a private TMPDIR and, optionally, a file-size limit that makes every write
  past it fail as a full disk would (RLIMIT_FSIZE; EFBIG, with SIGXFSZ ignored).
* :func:`adopting_orphans` makes this process the subreaper of everything it starts: a
  process that a tool leaves running when it exits becomes this process's child instead of
  init's, so :func:`orphans` sees it whatever its session or parent was.
* Waits are on things a test can observe (a line, a file's size, a child process), with
  generous limits only as hang guards.
"""

from __future__ import annotations

import contextlib
import ctypes
import os
import pathlib
import resource
import signal
import subprocess
import sys
import time

HANG_GUARD_S = 120.0
POLL_S = 0.02
PR_SET_CHILD_SUBREAPER = 36
#: The firmwares' command lines: the host build, and the Teensy image in the emulated chip.
FIRMWARE_MARKS = ("heliquad-fw-host", "heliquad.sim.chip.pil")


def _prctl_subreaper(on: bool) -> None:
    libc = ctypes.CDLL(None, use_errno=True)
    if libc.prctl(PR_SET_CHILD_SUBREAPER, int(on), 0, 0, 0) != 0:
        raise OSError(ctypes.get_errno(), "prctl(PR_SET_CHILD_SUBREAPER)")


def _stat(pid: int):
    """(state, ppid) of a process, or None when it is gone."""
    try:
        with open(f"/proc/{pid}/stat") as fh:
            text = fh.read()
    except OSError:
        return None
    fields = text[text.rindex(")") + 2:].split()
    return fields[0], int(fields[1])


def cmdline(pid: int) -> str:
    try:
        with open(f"/proc/{pid}/cmdline", "rb") as fh:
            return fh.read().replace(b"\0", b" ").decode(errors="replace").strip()
    except OSError:
        return ""


def children(pid: int) -> list[int]:
    """Living (not zombie) processes whose parent is ``pid``."""
    out = []
    for name in os.listdir("/proc"):
        if name.isdigit():
            st = _stat(int(name))
            if st is not None and st[1] == pid and st[0] != "Z":
                out.append(int(name))
    return out


@contextlib.contextmanager
def adopting_orphans():
    """Inside, the orphans of this process's descendants are re-parented to it."""
    _prctl_subreaper(True)
    try:
        yield
    finally:
        _prctl_subreaper(False)


def orphans(known=()) -> list[str]:
    """The command lines of this process's children other than ``known`` pids (what the
    tools it ran left running), after killing and reaping them so that nothing outlives a
    failing test. Adopted zombies are reaped too."""
    left = []
    for pid in children(os.getpid()):
        if pid in known:
            continue
        left.append(cmdline(pid) or f"pid {pid}")
        with contextlib.suppress(ProcessLookupError):
            os.kill(pid, signal.SIGKILL)
    for name in os.listdir("/proc"):
        if name.isdigit() and int(name) not in known:
            st = _stat(int(name))
            if st is not None and st[1] == os.getpid():
                with contextlib.suppress(ChildProcessError):
                    os.waitpid(int(name), 0)
    return left


@contextlib.contextmanager
def private_tmpdir(base):
    """A TMPDIR for the tools a test runs (``base``/tmp), with orphans adopted meanwhile
    (:func:`adopting_orphans`); :func:`assert_nothing_left` checks both at the end."""
    tmp = base / "tmp"
    tmp.mkdir()
    with adopting_orphans():
        yield tmp


def assert_nothing_left(tmp) -> None:
    """No process left running by the tools the test ran, nothing in their TMPDIR."""
    left = orphans()
    assert left == [], f"left running: {left}"
    assert list(tmp.iterdir()) == []


def wait_for(condition, what: str, proc=None, timeout_s: float = HANG_GUARD_S) -> None:
    """Until ``condition()`` holds; fails if ``proc`` ends first or the hang guard passes."""
    deadline = time.monotonic() + timeout_s
    while not condition():
        if proc is not None and proc.poll() is not None:
            out, err = proc.communicate()
            raise AssertionError(f"ended (exit {proc.returncode}) before {what}: {out}{err}")
        if time.monotonic() > deadline:
            raise AssertionError(f"no {what} within {timeout_s:g} s (hang guard)")
        time.sleep(POLL_S)


def as_foreground_job() -> None:
    """In a child about to run a tool (``preexec_fn``): SIGINT and SIGHUP back to their
    defaults, as a terminal's foreground job has them. A shell that runs the tests in the
    background (``(pytest ...) &``, as a CI runner or nohup does) hands SIGINT down ignored,
    nohup SIGHUP, and heliquad keeps a signal it was started with ignored (POSIX's way for
    background jobs): a test's Ctrl-C would be lost."""
    for signum in (signal.SIGINT, signal.SIGHUP):
        signal.signal(signum, signal.SIG_DFL)


def cli(*args, **popen_kw) -> subprocess.Popen:
    """``heliquad ARGS`` started as a terminal's foreground job (:func:`as_foreground_job`),
    its output on pipes as text: for tests that Ctrl-C it (``send_signal(SIGINT)``)."""
    return subprocess.Popen([sys.executable, "-m", "heliquad.host.cli.parser", *map(str, args)],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            preexec_fn=as_foreground_job, **popen_kw)


@contextlib.contextmanager
def board_process(folder, *args, **popen_kw):
    """``heliquad board ARGS`` (the roll rig in real time) as a foreground job, its telemetry
    on the pty ``folder``/rig; yields its Popen (for a test that signals it), and stops it
    with Ctrl-C, however pytest was started. ``popen_kw``: as :func:`cli` takes them."""
    board = cli("board", "--telemetry", pathlib.Path(folder) / "rig", *args, **popen_kw)
    try:
        assert "board running" in board.stdout.readline()
        yield board
    finally:
        board.send_signal(signal.SIGINT)
        board.communicate(timeout=HANG_GUARD_S)


@contextlib.contextmanager
def running_board(folder, *args, **popen_kw):
    """:func:`board_process`, yielding the path of its telemetry pty."""
    with board_process(folder, *args, **popen_kw):
        yield pathlib.Path(folder) / "rig"


def size(path) -> int:
    try:
        return os.path.getsize(path)
    except OSError:
        return 0


def excitation_running(tlog) -> bool:
    """Whether a log still being written holds the firmware's answer that an excitation has
    started (a record cut short at its end is left for the next look): what a test waits
    for before it breaks a sweep "mid-frequency", whatever the machine's speed."""
    # Imported here: most tests that use this module never read a log.
    from heliquad.host.records.tlog import TlogDamage, read_tlog
    from heliquad.sim.base.dialect import dialect

    if size(tlog) == 0:
        return False
    status = read_tlog(str(tlog), dialect(), only=("HQ_EXCITATION_STATUS",), damage=TlogDamage())
    idle = dialect().HQ_EXCITATION_STATE_IDLE
    return any(m.accepted and m.state != idle for _, m in status)


class Tool:
    """``heliquad ARGS`` as a terminal's foreground job. ``tmpdir``: its TMPDIR (empty when
    the test checks it). ``file_limit``: bytes any file it (or its children) writes may
    reach; past them a write fails with EFBIG, as a full disk fails with ENOSPC."""

    def __init__(self, *args, tmpdir, file_limit: int | None = None, env=None):
        def prepare():
            as_foreground_job()
            if file_limit is not None:
                resource.setrlimit(resource.RLIMIT_FSIZE, (file_limit, file_limit))
                signal.signal(signal.SIGXFSZ, signal.SIG_IGN)

        self.args = [str(a) for a in args]
        self.proc = subprocess.Popen(
            [sys.executable, "-m", "heliquad.host.cli.parser", *self.args],
            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
            env=dict(os.environ, TMPDIR=str(tmpdir), PYTHONUNBUFFERED="1", **(env or {})),
            start_new_session=True, preexec_fn=prepare)
        self.pid = self.proc.pid

    def readline(self) -> str:
        """The next line on its stdout (it writes its progress lines flushed)."""
        return self.proc.stdout.readline()

    def firmware_pid(self) -> int:
        """The firmware process it started (waits until there is one)."""
        found = []

        def started():
            found[:] = [p for p in children(self.pid)
                        if any(mark in cmdline(p) for mark in FIRMWARE_MARKS)]
            return bool(found)

        wait_for(started, "a firmware process", self.proc)
        return found[0]

    def ctrl_c(self) -> None:
        os.killpg(self.pid, signal.SIGINT)

    def sigterm(self) -> None:
        os.kill(self.pid, signal.SIGTERM)

    def sighup(self) -> None:
        """The terminal or SSH session closed: SIGHUP to the foreground job's group."""
        os.killpg(self.pid, signal.SIGHUP)

    def finish(self, timeout_s: float = HANG_GUARD_S):
        """Wait for it to end: (exit code, stdout, stderr)."""
        out, err = self.proc.communicate(timeout=timeout_s)
        return self.proc.returncode, out, err

    def kill(self) -> None:
        if self.proc.poll() is None:
            self.proc.kill()
            self.proc.communicate()


def one_line(stderr: str) -> str:
    """The single line a failing run writes on stderr (fails if there are more)."""
    lines = stderr.strip().splitlines()
    assert len(lines) == 1 and "Traceback" not in stderr, stderr
    return lines[0]
