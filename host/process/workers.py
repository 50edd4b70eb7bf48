"""Child processes run side by side (the demo's axes), as one command.

Each child is a Python process in a process group of its own, so that a terminal's Ctrl-C
reaches this process alone, which passes it on to every child once: each then stops in
order (a sweep stops its excitation and keeps its log and manifest) while this one waits.
SIGTERM is passed on the same way. What a child writes to stdout and stderr is shown here
whole line by whole line, its name in front, so that lines of different children never
mix within a line; what it reports (:func:`send_result`, one JSON value) comes back on a
pipe of its own, apart from its output.

A child that fails says so in its result (or ends without one); the others go on.
"""

from __future__ import annotations

import contextlib
import dataclasses
import json
import os
import selectors
import signal
import subprocess
import sys
import time

from .signals import ignoring, stopped_by

__all__ = ["Child", "start_child", "run_children", "send_result", "RESULT_FD_VARIABLE"]

#: The environment variable that tells a child the pipe its result goes to.
RESULT_FD_VARIABLE = "HELIQUAD_RESULT_FD"
#: Once Ctrl-C or SIGTERM has been passed on, how long the children have to stop in order
#: before they are killed.
STOP_GRACE_S = 60.0
_READ = 65536


@dataclasses.dataclass
class Child:
    """A child process: its name (the prefix of its lines), the process, and once it has
    ended, what it reported (None when it reported nothing) and its exit code."""

    name: str
    proc: subprocess.Popen
    result_fd: int
    result: object = None
    returncode: int | None = None


def start_child(name: str, argv: list, env: dict | None = None) -> Child:
    """Start ``argv`` (a Python command whose code calls :func:`send_result`) as a child in
    a process group of its own, unbuffered, its stdout and stderr piped here."""
    read_end, write_end = os.pipe()
    try:
        child_env = dict(os.environ if env is None else env, PYTHONUNBUFFERED="1")
        child_env[RESULT_FD_VARIABLE] = str(write_end)
        proc = subprocess.Popen(argv, stdin=subprocess.DEVNULL, stdout=subprocess.PIPE,
                                stderr=subprocess.PIPE, pass_fds=(write_end,), env=child_env,
                                process_group=0)
    except BaseException:
        os.close(read_end)
        raise
    finally:
        os.close(write_end)
    return Child(name, proc, read_end)


def send_result(value) -> None:
    """In a child: report ``value`` (JSON-serialisable) to the parent, once."""
    fd = int(os.environ[RESULT_FD_VARIABLE])
    with os.fdopen(fd, "wb") as fh:
        fh.write(json.dumps(value).encode())


class _Pump:
    """Reads every child's stdout, stderr and result pipe until each ends, and shows the
    output line by line with the child's name in front."""

    def __init__(self, children, out, err):
        self.selector = selectors.DefaultSelector()
        for child in children:
            self.selector.register(child.proc.stdout.fileno(), selectors.EVENT_READ,
                                   (child, out, bytearray()))
            self.selector.register(child.proc.stderr.fileno(), selectors.EVENT_READ,
                                   (child, err, bytearray()))
            self.selector.register(child.result_fd, selectors.EVENT_READ,
                                   (child, None, bytearray()))

    def run(self, deadline: float | None = None) -> bool:
        """Until every pipe has ended (True), or ``deadline`` (time.monotonic) passes."""
        while self.selector.get_map():
            wait = None if deadline is None else deadline - time.monotonic()
            if wait is not None and wait <= 0:
                return False
            for key, _ in self.selector.select(wait):
                self._read(key)
        return True

    def _read(self, key) -> None:
        child, stream, pending = key.data
        chunk = os.read(key.fd, _READ)
        pending += chunk
        if stream is not None:
            *lines, rest = pending.split(b"\n")
            for line in lines:
                _show(stream, child.name, line)
            pending[:] = rest
        if chunk:
            return
        self.selector.unregister(key.fd)
        if stream is None:
            os.close(key.fd)
            try:
                child.result = json.loads(pending) if pending.strip() else None
            except ValueError:                      # cut short: the child died writing it
                child.result = None
        elif pending:
            _show(stream, child.name, pending)

    def close(self) -> None:
        for key in list(self.selector.get_map().values()):
            if key.data[1] is None:
                os.close(key.fd)
        self.selector.close()


def _show(stream, name: str, line: bytes) -> None:
    stream.write(f"[{name}] {line.decode(errors='replace').rstrip()}\n")
    stream.flush()


def run_children(commands, out=None, err=None) -> list:
    """Start a child for each ``(name, argv)`` of ``commands`` (:func:`start_child`), show
    their output (on ``out`` and ``err``, default this process's) until each has ended, and
    return them, each with its result and exit code.

    Ctrl-C (KeyboardInterrupt), SIGTERM or SIGHUP (host/process/signals.py) here is passed on to every
    child still running, once, as the same signal to its process group; this process
    then waits for them to stop (ignoring further signals; after STOP_GRACE_S it kills
    them) and raises it again."""
    children, pump = [], None
    try:
        for name, argv in commands:
            children.append(start_child(name, argv))
        pump = _Pump(children, out or sys.stdout, err or sys.stderr)
        pump.run()
    except KeyboardInterrupt as exc:
        with ignoring():
            _signal_all(children, stopped_by(exc))
            pump = pump or _Pump(children, out or sys.stdout, err or sys.stderr)
            if not pump.run(time.monotonic() + STOP_GRACE_S):
                _signal_all(children, signal.SIGKILL)
                pump.run(time.monotonic() + STOP_GRACE_S)
        raise
    finally:
        if pump is not None:
            pump.close()
        _wait_all(children)
    return children


def _signal_all(children, signum) -> None:
    for child in children:
        if child.proc.poll() is None:
            with contextlib.suppress(ProcessLookupError):
                os.killpg(child.proc.pid, signum)


def _wait_all(children) -> None:
    for child in children:
        child.returncode = child.proc.wait()
        for stream in (child.proc.stdout, child.proc.stderr):
            stream.close()
