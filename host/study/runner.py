"""A worker's runs made in a process of its own: the runner.

A Dask worker runs a task in a thread beside its event loop, and the loop wakes several
times a second (heartbeats, its timers). Each wake-up has to take the GIL from the run, and
while it waits, every release of the GIL by the run (a socket read, a NumPy call) costs a
futex wake-up of the waiting thread: measured on a two-core machine, a run took about 12 %
longer on a worker than in a process of its own, the worker's loop thread waiting some
10 ms at each wake-up and making thousands of futex calls a second. The runner is a
Python process of its own for each worker thread, started at its first run and kept for the
next: the run has its interpreter to itself, as when a user types the commands, and the
worker's thread waits on a pipe, without the GIL.

The runner is in a session of its own (a terminal's Ctrl-C reaches the study's client,
which closes the cluster in order) and ends when its worker does: it watches a pipe only
its worker holds open, and exits at once when that closes (the worker closed, killed or
crashed), so that a run never goes on writing after its worker is gone and its run is
handed to another. A runner that dies mid-run (a crash in the simulator's C++) costs its
run only: the run is a failed record with the signal that ended it, and the next run
starts a new runner.
"""

from __future__ import annotations

import importlib
import os
import signal
import struct
import subprocess
import sys
import threading

__all__ = ["in_runner", "start_spares", "close_runners", "runner_plugin", "serve"]

#: What the runner process runs.
SERVE = "from heliquad.host.study.runner import serve; serve()"
#: A message's length prefix on the pipes.
_HEADER = struct.Struct("<Q")
#: The exit code of a runner whose worker went away.
ORPHANED = 70

#: What a runner imports as it starts, before its first run arrives: what a study's run uses
#: (the commands, the simulator, identification, the plots; about 1.5 s), so that a worker's
#: first run does not wait for it.
WARM = ("heliquad.host.commands.study", "heliquad.host.study.runs",
        "heliquad.host.commands.sweep", "heliquad.host.acquire.sweep",
        "heliquad.host.acquire.session", "heliquad.host.commands.identify",
        "heliquad.host.campaign.identify", "matplotlib.pyplot")

_LOCAL = threading.local()
_ALL: list = []                 # every runner started in this process (closed with it)
_SPARE: list = []               # started when the worker did, for its threads' first runs
_ALL_LOCK = threading.Lock()


class RunnerDied(RuntimeError):
    """The runner ended before it answered."""


class Runner:
    """One runner process and the pipes to it."""

    def __init__(self):
        request_r, request_w = os.pipe()
        reply_r, reply_w = os.pipe()
        life_r, life_w = os.pipe()
        theirs = (request_r, reply_w, life_r)
        try:
            self.proc = subprocess.Popen(
                [sys.executable, "-c", SERVE, *map(str, theirs)], pass_fds=theirs,
                stdin=subprocess.DEVNULL, start_new_session=True)
        except BaseException:
            for fd in (request_w, reply_r, life_w):
                os.close(fd)
            raise
        finally:
            for fd in theirs:
                os.close(fd)
        self.requests = os.fdopen(request_w, "wb")
        self.replies = os.fdopen(reply_r, "rb")
        self.lifeline = life_w              # never written: its closing ends the runner

    def alive(self) -> bool:
        return self.proc.poll() is None

    def call(self, perform, run, out):
        """``perform(run, out)`` made in the runner: its return value, or what it raised
        raised here; RunnerDied when the runner ended first."""
        # Dask's serialiser, there wherever a worker is: it pickles a test's or a
        # closure's function by value, as Dask itself sends the task here
        import cloudpickle

        try:
            _send(self.requests, cloudpickle.dumps((perform, run, out)))
            status, value = cloudpickle.loads(_receive(self.replies))
        except (OSError, EOFError):
            raise RunnerDied(self._death()) from None
        if status == "raised":
            raise value
        return value

    def _death(self) -> str:
        try:
            code = self.proc.wait(5)
        except subprocess.TimeoutExpired:
            self.close()
            code = self.proc.returncode
        if code is not None and code < 0:
            return f"the run's process died of {signal.Signals(-code).name}"
        return f"the run's process ended (exit code {code}) before its run did"

    def close(self) -> None:
        """End the runner (at once, mid-run too) and wait for it."""
        for stream in (self.requests, self.replies):
            try:
                stream.close()
            except OSError:
                pass
        if self.lifeline is not None:
            os.close(self.lifeline)
            self.lifeline = None
        try:
            self.proc.wait(5)
        except subprocess.TimeoutExpired:
            self.proc.kill()
            self.proc.wait()


def in_runner(perform, run, out):
    """What a worker runs for each run: ``perform(run, out)`` in this thread's runner (one
    started on first use, and again after one died). A runner that dies mid-run makes the
    run a failed record (``died(run, out, why)``, from ``perform``'s module) and is
    replaced at the next run."""
    runner = getattr(_LOCAL, "runner", None)
    if runner is None or not runner.alive():
        runner = _LOCAL.runner = _started()
    try:
        return runner.call(perform, run, out)
    except RunnerDied as exc:
        _LOCAL.runner = None
        runner.close()
        # the record's maker, imported where a run has failed this way
        from .runs import died_record

        return died_record(run, out, str(exc))


def _started() -> Runner:
    """A spare runner (started with the worker) if one is alive, else a new one."""
    with _ALL_LOCK:
        while _SPARE:
            runner = _SPARE.pop()
            if runner.alive():
                return runner
        runner = Runner()
        _ALL.append(runner)
    return runner


def start_spares(count: int) -> None:
    """Start ``count`` runners now (a worker starting: one per thread), so that their
    imports overlap the study's start."""
    with _ALL_LOCK:
        for _ in range(count):
            runner = Runner()
            _ALL.append(runner)
            _SPARE.append(runner)


def close_runners() -> None:
    """End every runner this process started (a worker closing)."""
    with _ALL_LOCK:
        runners, _ALL[:], _SPARE[:] = list(_ALL), [], []
    for runner in runners:
        runner.close()


def runner_plugin():
    """A Dask worker plugin that ends the worker's runners when the worker closes (a worker
    in the client's own process, as tests start, would otherwise leave them running)."""
    # Dask, imported where a study hands its runs out: the runner itself does without it
    from distributed.diagnostics.plugin import WorkerPlugin

    class RunnerPlugin(WorkerPlugin):
        name = "heliquad-runners"
        idempotent = True

        def setup(self, worker):
            start_spares(worker.state.nthreads)

        def teardown(self, worker):
            close_runners()

    return RunnerPlugin()


def _send(stream, data: bytes) -> None:
    stream.write(_HEADER.pack(len(data)) + data)
    stream.flush()


def _receive(stream) -> bytes:
    header = stream.read(_HEADER.size)
    if len(header) < _HEADER.size:
        raise EOFError
    (size,) = _HEADER.unpack(header)
    data = stream.read(size)
    if len(data) < size:
        raise EOFError
    return data


def _watch(lifeline: int) -> None:
    """In the runner: exit at once when the worker's end of the lifeline closes."""
    while True:
        try:
            if not os.read(lifeline, 1):
                break
        except InterruptedError:
            continue
        except OSError:
            break
    os._exit(ORPHANED)


def serve() -> None:
    """The runner: make each run its worker sends, and send back what it returned or
    raised, until the requests end or the worker goes away."""
    import cloudpickle      # Dask's serialiser (see Runner.call)

    requests_fd, replies_fd, lifeline = map(int, sys.argv[1:4])
    threading.Thread(target=_watch, args=(lifeline,), daemon=True,
                     name="heliquad-lifeline").start()
    for module in WARM:
        importlib.import_module(module)
    with os.fdopen(requests_fd, "rb") as requests, os.fdopen(replies_fd, "wb") as replies:
        while True:
            try:
                perform, run, out = cloudpickle.loads(_receive(requests))
            except EOFError:
                return
            try:
                reply = ("returned", perform(run, out))
            except Exception as exc:      # noqa: BLE001 - raised again in the worker
                reply = ("raised", exc)
            try:
                data = cloudpickle.dumps(reply)
            except Exception as exc:      # noqa: BLE001 - what cannot be sent, said
                data = cloudpickle.dumps(("raised", RuntimeError(
                    f"{type(reply[1]).__name__}: {reply[1]} (not sendable: {exc})")))
            _send(replies, data)
