"""A worker's runs made in a process of its own: the runner.

A Dask worker runs a task in a thread beside its event loop, and the loop wakes several
times a second (heartbeats, its timers). Each wake-up has to take the GIL from the run, and
while it waits, every release of the GIL by the run (a socket read, a NumPy call) costs a
futex wake-up of the waiting thread: measured on a two-core machine, a run took 12-19 %
longer on a worker than in a process of its own, the worker's loop thread waiting some
10 ms at each wake-up and making thousands of futex calls a second. The runner is a
Python process of its own for each worker thread, kept for the thread's next runs (the
study's plugin starts one per thread as the worker joins the study, so that its imports
are made before the first run arrives): the run has its interpreter to itself, as when a
user types the commands, and the worker's thread waits on a pipe, without the GIL.

The runner is in a session of its own (a terminal's Ctrl-C reaches the study's client,
which closes the cluster in order). It holds the read end of a pipe, the lifeline, whose
write end only its worker holds: when the worker closes, is killed or crashes, the pipe
closes and the runner exits at once (:data:`ORPHANED`), mid-run too, so that a run never
goes on writing after its worker is gone and Dask has handed the run to another. What its
run started goes too: a firmware the run started is in a session of its own and would serve
its ptys until its idle timeout. A worker that ends a runner mid-run (closing) kills them
itself once the runner has exited; a runner whose worker went away without a word leaves a
cleaner behind that does it once the runner is gone. Each runner has a temporary folder of
its own (TMPDIR for its runs and what they start), removed with it. A runner that dies
mid-run on its own (a crash in the simulator's C++) costs its run only: the run is a failed
record saying what ended it (``runs.died_record``), and the thread's next run starts a new
runner.
"""

from __future__ import annotations

import importlib
import os
import shutil
import signal
import struct
import subprocess
import sys
import tempfile
import threading
import time
import traceback

from .. import __version__

__all__ = ["in_runner", "start_spares", "close_runners", "runner_plugin", "serve", "clean",
           "ORPHANED", "PLUGIN_NAME", "RunnerGone"]

#: What the runner process runs (``-P``: the worker's working directory is not put on its
#: import path).
SERVE = "from heliquad.host.study.runner import serve; serve()"
#: What an orphaned runner's cleaner runs (:func:`clean`).
CLEAN = "from heliquad.host.study.runner import clean; clean()"
#: A message's length prefix on the pipes.
_HEADER = struct.Struct("<Q")
#: The study's worker plugin (:func:`runner_plugin`), by heliquad's version: a newer
#: heliquad's replaces an older one's on a scheduler.
PLUGIN_NAME = f"heliquad-runners-{__version__}"
#: The exit code of a runner whose worker went away.
ORPHANED = 70
#: Written on the lifeline before it is closed: the worker ends what the run started itself.
QUIT = b"q"
#: What a runner imports as it starts, before its first run arrives: what a study's run uses
#: (the commands, the simulator, identification, the figures; about 1.5 s), so that a
#: worker's first run does not wait for it. Only a head start: one that fails to import
#: fails later, in the run that needs it, with its own error.
WARM = ("heliquad.host.commands.study", "heliquad.host.study.runs",
        "heliquad.host.commands.sweep", "heliquad.host.acquire.sweep",
        "heliquad.host.acquire.session", "heliquad.host.commands.identify",
        "heliquad.host.campaign.identify", "matplotlib.figure", "matplotlib.backends.backend_agg")

_LOCAL = threading.local()
_LOCK = threading.RLock()            # _started forgets a dead spare while holding it
#: The runners started in this process, by the worker they serve (None outside a worker),
#: and the spares not yet taken by a thread.
_ALL: dict = {}
_SPARE: dict = {}


class RunnerDied(RuntimeError):
    """The runner ended on its own before it answered."""


class RunnerGone(RuntimeError):
    """The runner was ended (its worker closing) before it answered: the run is not over."""


class Runner:
    """One runner process and the pipes to it."""

    def __init__(self):
        self._lock = threading.Lock()
        self.closing = False
        self.busy = False                    # a run sent and not answered
        # the runner's temporary folder (TMPDIR for its runs and what they start)
        self.scratch = tempfile.mkdtemp(prefix="heliquad-runner-")
        pipes = []
        try:
            for _ in range(3):                     # requests, replies, lifeline
                pipes.append(os.pipe())
            (request_r, request_w), (reply_r, reply_w), (life_r, life_w) = pipes
            theirs = (request_r, reply_w, life_r)
            self.proc = subprocess.Popen(
                [sys.executable, "-P", "-c", SERVE, *map(str, theirs), self.scratch],
                pass_fds=theirs, stdin=subprocess.DEVNULL, start_new_session=True)
        except BaseException:
            for fd in (fd for pair in pipes for fd in pair):
                os.close(fd)
            shutil.rmtree(self.scratch, ignore_errors=True)
            raise
        for fd in theirs:
            os.close(fd)
        self.requests = os.fdopen(request_w, "wb")
        self.replies = os.fdopen(reply_r, "rb")
        # its closing ends the runner (and its cleaner ends what the run started); QUIT
        # written first ends it without a cleaner: this side cleans
        self.lifeline = life_w

    def alive(self) -> bool:
        return not self.closing and self.proc.poll() is None

    def call(self, perform, run, out):
        """``perform(run, out)`` made in the runner: its return value, or what it raised
        raised here; RunnerDied when the runner ended on its own first, RunnerGone when it
        was ended (:meth:`close`). Anything else that stops the call (Ctrl-C in a caller's
        main thread) ends the runner: its answer would otherwise be read as the next run's."""
        # Dask's serialiser, there wherever a worker is: it pickles a test's or a
        # closure's function by value, as Dask itself sends the task here
        import cloudpickle

        request = cloudpickle.dumps((perform, run, out))
        self.busy = True
        try:
            _send(self.requests, request)
            reply = _receive(self.replies)
            self.busy = False
        except (OSError, EOFError, ValueError):      # ValueError: read from a closed pipe
            if self.closing:
                raise RunnerGone("the run's process was ended with its worker") from None
            raise RunnerDied(self._death()) from None
        except BaseException:
            self.close()
            raise
        status, value = cloudpickle.loads(reply)
        if status == "raised":
            raise value
        return value

    def _death(self) -> str:
        try:
            code = self.proc.wait(5)
        except subprocess.TimeoutExpired:      # its end of the pipe closed, not yet ended
            self.close()
            code = self.proc.returncode
        if code is not None and code < 0:
            return f"the run's process died of {signal.Signals(-code).name}"
        return f"the run's process ended (exit code {code}) before its run did"

    def close(self) -> None:
        """End the runner and wait for it, then close the pipes and remove its temporary
        folder. Between runs by closing its requests (it ends as a finished process does);
        mid-run by the lifeline (it exits at once) and then the processes its run started
        killed. Safe to call again and from another thread."""
        with self._lock:
            self.closing = True
            below = []
            if not self.busy:
                _quietly_close(self.requests)
                try:
                    self.proc.wait(5)
                except subprocess.TimeoutExpired:
                    pass
            elif self.proc.poll() is None:
                below = _descendants(self.proc.pid)
            if self.lifeline is not None:
                try:
                    os.write(self.lifeline, QUIT)
                except OSError:            # the runner is gone already
                    pass
                os.close(self.lifeline)
                self.lifeline = None
            try:
                self.proc.wait(5)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait()
            _kill(below)
            for stream in (self.requests, self.replies):
                _quietly_close(stream)
            shutil.rmtree(self.scratch, ignore_errors=True)


def _quietly_close(stream) -> None:
    """A pipe closed whatever state it is in (a broken or already closed one too)."""
    try:
        stream.close()
    except (OSError, ValueError):
        pass


def in_runner(perform, run, out):
    """What a worker runs for each run: ``perform(run, out)`` in this thread's runner (a
    spare started with the worker, or a new one; again after one died). A runner that dies
    mid-run on its own makes the run a failed record (``runs.died_record``, which keeps a
    record the run had already written) and is replaced at the next run; one ended with its
    worker raises RunnerGone (the worker is closing: Dask hands the run to another)."""
    runner = getattr(_LOCAL, "runner", None)
    if runner is None or not runner.alive():
        if runner is not None:
            _forget(runner)
        runner = _LOCAL.runner = _started()
    try:
        return runner.call(perform, run, out)
    except RunnerDied as exc:
        _LOCAL.runner = None
        _forget(runner)
        # the record's maker, imported where a run has failed this way
        from .runs import died_record

        return died_record(run, out, str(exc))
    except BaseException:
        if not runner.alive():
            _LOCAL.runner = None
            _forget(runner)
        raise


def _worker_key():
    """The worker this thread serves (its runners are ended with it), or None."""
    try:
        # Dask, there when a worker runs this: outside one (a test), the key is None
        from distributed import get_worker

        return id(get_worker())
    except (ImportError, ValueError):
        return None


def _started() -> Runner:
    """A spare runner of this thread's worker if one is alive, else a new one."""
    key = _worker_key()
    with _LOCK:
        spares = _SPARE.get(key, [])
        while spares:
            runner = spares.pop()
            if runner.alive():
                return runner
            _forget(runner)
        runner = Runner()
        _ALL.setdefault(key, []).append(runner)
    return runner


def _forget(runner: Runner) -> None:
    """A runner that ended: closed (its pipes) and dropped from the lists."""
    runner.close()
    with _LOCK:
        for runners in (*_ALL.values(), *_SPARE.values()):
            if runner in runners:
                runners.remove(runner)


def start_spares(worker) -> None:
    """Start one runner for each of ``worker``'s threads now, so that their imports overlap
    the study's start. A failure here is only a lost head start: said nowhere, the runs
    start their own runners (and say what stops them)."""
    key = id(worker)
    try:
        with _LOCK:
            for _ in range(worker.state.nthreads):
                runner = Runner()
                _ALL.setdefault(key, []).append(runner)
                _SPARE.setdefault(key, []).append(runner)
    except Exception:                     # noqa: BLE001 - a head start only
        pass


def close_runners(worker=None) -> None:
    """End the runners of ``worker`` (default: of no worker, as a test starts them)."""
    key = None if worker is None else id(worker)
    with _LOCK:
        runners = _ALL.pop(key, [])
        _SPARE.pop(key, None)
    for runner in runners:
        runner.close()


def runner_plugin():
    """The Dask worker plugin of a study: one spare runner a thread when a worker joins,
    its runners ended when the worker closes or the study ends (the client unregisters it,
    so that a cluster's workers keep nothing of the study's once it is over)."""
    # Dask, imported where a study hands its runs out: the runner itself does without it
    from distributed.diagnostics.plugin import WorkerPlugin

    class RunnerPlugin(WorkerPlugin):
        name = PLUGIN_NAME
        idempotent = True

        def setup(self, worker):
            start_spares(worker)

        def teardown(self, worker):
            close_runners(worker)

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


def _watch(lifeline: int, scratch: str) -> None:
    """In the runner: when the worker's end of the lifeline closes, exit at once; unless the
    worker said QUIT first (it cleans up itself), leave a cleaner behind to end what the run
    started once this process is gone."""
    while True:
        try:
            said = os.read(lifeline, 1)
        except InterruptedError:
            continue
        except OSError:
            said = b""
        if said == QUIT:
            os._exit(ORPHANED)
        if not said:
            break
    try:
        _start_cleaner(scratch)
    finally:
        os._exit(ORPHANED)


def _start_cleaner(scratch: str) -> None:
    """A process of its own that waits for this runner's end, then kills the processes below
    it as they are now (a run's firmware, in a session of its own, would serve on until its
    idle timeout) and removes its temporary folder. Not done here: a run that saw its
    firmware killed would write a failed record before this process exits, and the run is
    Dask's to make again."""
    below = [f"{pid}:{created!r}" for pid, created in _descendants(os.getpid())]
    subprocess.Popen([sys.executable, "-P", "-c", CLEAN, str(os.getpid()), scratch, *below],
                     stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL,
                     stderr=subprocess.DEVNULL, start_new_session=True)


def clean() -> None:
    """The cleaner (:func:`_start_cleaner`): ``RUNNER_PID SCRATCH PID:CREATE_TIME...``."""
    runner_pid, scratch, *below = sys.argv[1:]
    _wait_gone([(int(runner_pid), None)])
    _kill([(int(pid), float(created)) for pid, created in
           (item.split(":", 1) for item in below)])
    shutil.rmtree(scratch, ignore_errors=True)


def _descendants(pid: int) -> list:
    """The processes below ``pid``, whatever session they are in: (pid, start time)."""
    # psutil, there with Dask (distributed needs it): only a runner ended mid-run lists
    # what is below it, so a runner's start does without it
    import psutil

    below = []
    try:
        for proc in psutil.Process(pid).children(recursive=True):
            try:
                below.append((proc.pid, proc.create_time()))
            except psutil.Error:
                pass
    except psutil.Error:
        pass
    return below


def _kill(procs: list) -> None:
    """Kill each (pid, start time) that is still that process (not a new one on a reused
    pid), and wait until they have ended."""
    import psutil      # see _descendants

    for pid, created in procs:
        try:
            proc = psutil.Process(pid)
            if proc.create_time() == created:
                proc.kill()
        except psutil.Error:
            pass
    _wait_gone(procs)


def _wait_gone(procs: list, limit_s: float = 5.0) -> None:
    """Until each (pid, start time) has ended (a zombie waiting to be reaped counts as
    ended), at most ``limit_s``."""
    import psutil      # see _descendants

    deadline = time.monotonic() + limit_s
    for pid, created in procs:
        while time.monotonic() < deadline:
            try:
                proc = psutil.Process(pid)
                if created is not None and proc.create_time() != created:
                    break
                if proc.status() == psutil.STATUS_ZOMBIE:
                    break
            except psutil.NoSuchProcess:
                break
            time.sleep(0.01)


def _use_scratch(path: str) -> None:
    """The runner's temporary folder (its worker made it) as TMPDIR for its runs and what
    they start (a firmware's ptys and logs)."""
    tempfile.tempdir = path
    os.environ["TMPDIR"] = path


def _reply(cloudpickle, status: str, value) -> bytes:
    """The reply, made sure to arrive whole: what cannot be sent or rebuilt on the other
    side (an exception whose constructor takes other arguments) goes as a RuntimeError
    with its text and traceback."""
    try:
        data = cloudpickle.dumps((status, value))
        cloudpickle.loads(data)
        return data
    except Exception as exc:             # noqa: BLE001 - said in the error instead
        what = "".join(traceback.format_exception(value)) if status == "raised" else repr(value)
        return cloudpickle.dumps(("raised", RuntimeError(
            f"{what.strip()} (not sendable from the run's process: {exc})")))


def serve() -> None:
    """The runner: make each run its worker sends, and send back what it returned or
    raised, until the requests end or the worker goes away."""
    import cloudpickle      # Dask's serialiser (see Runner.call)

    requests_fd, replies_fd, lifeline = map(int, sys.argv[1:4])
    scratch = sys.argv[4]
    for fd in (requests_fd, replies_fd, lifeline):
        os.set_inheritable(fd, False)      # not the firmware's and plotters' it starts
    _use_scratch(scratch)
    try:
        threading.Thread(target=_watch, args=(lifeline, scratch), daemon=True,
                         name="heliquad-lifeline").start()
        _serve(cloudpickle, requests_fd, replies_fd)
    finally:
        shutil.rmtree(scratch, ignore_errors=True)


def _serve(cloudpickle, requests_fd: int, replies_fd: int) -> None:
    """The runner's loop: each request's run made, its reply sent, until the requests end."""
    for module in WARM:
        try:
            importlib.import_module(module)
        except Exception:                 # noqa: BLE001 - a head start only (see WARM)
            pass
    with os.fdopen(requests_fd, "rb") as requests, os.fdopen(replies_fd, "wb") as replies:
        while True:
            try:
                request = _receive(requests)
            except EOFError:
                return
            try:
                perform, run, out = cloudpickle.loads(request)
                reply = _reply(cloudpickle, "returned", perform(run, out))
            except BaseException as exc:  # noqa: BLE001 - raised again in the worker
                reply = _reply(cloudpickle, "raised", exc)
            _send(replies, reply)
