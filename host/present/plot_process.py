"""identify's plots drawn in a process of their own, beside the fits.

Drawing is most of what ``heliquad identify`` spends on a long session (matplotlib's import,
and the responses figure's panels), and it needs little from the fits: the records are
known before any model. So a process of its own imports matplotlib while this one reads the
log, draws and renders the records (:class:`~heliquad.host.present.responses.ResponsesFigure`) while
this one fits, and once the models are known draws bode.png and finishes responses.png (the
replays, the titles and the legend onto the rendered picture); it says each is done or what
failed, which is raised here. It reads its pipe in a thread of its own from the start, so
sending it the records never waits for matplotlib's import.

(A second process for bode.png, measured: no sooner on two cores, and a third more CPU.)

Ctrl-C does not reach the process: it ends when this side closes its pipe (the command is
interrupted or fails), after the step it is in, so a picture is never left half written.
"""

from __future__ import annotations

import contextlib
import importlib
import os
import pickle
import queue
import subprocess
import sys
import threading
from multiprocessing.connection import Connection

from ...sim.base.errors import InputError
from .bode import write_bode
from .responses import ResponsesFigure

__all__ = ["PlotProcess", "InlinePlots", "command_plots", "drawing_here", "serve"]

#: How long, once the pipe is closed, the process may take to end before it is stopped.
END_WAIT_S = 30.0
#: How long to wait for the exit code of a process whose pipe broke.
ENDED_WAIT_S = 5.0


class PlotProcess:
    """The plotting process, as a context manager: :meth:`records`, then :meth:`finish`.

    A fresh interpreter (``python -c``, not multiprocessing's spawn, which would run the
    caller's main script again) in a process group of its own, so a terminal's Ctrl-C
    reaches this side only; the two talk through its stdin and stdout."""

    def __init__(self):
        theirs_in, ours_out = os.pipe()
        ours_in, theirs_out = os.pipe()
        try:
            self.proc = subprocess.Popen([sys.executable, "-c", SERVE], stdin=theirs_in,
                                         stdout=theirs_out, process_group=0)
        except BaseException:
            os.close(ours_out)
            os.close(ours_in)
            raise
        finally:
            os.close(theirs_in)
            os.close(theirs_out)
        self.conn = Connection(ours_out, readable=False)
        self.answers = Connection(ours_in, writable=False)
        self.writing = False                    # finish sent: it may be writing a picture
        self.failed = None                      # the process ended before finish

    def records(self, segments, input_name: str, output_name: str) -> None:
        """Start drawing the responses figure's records (``(freq_hz, t_s, u, y)`` each).
        Should the process have ended, that is said by :meth:`finish`: what the caller
        writes meanwhile (the points, the models) is not to be lost to a picture."""
        try:
            self._send(("records", segments, input_name, output_name))
        except InputError as exc:
            self.failed = exc

    def finish(self, bode: dict, responses: dict) -> None:
        """Write bode.png (``write_bode``'s arguments) and responses.png (``path``, ``title``,
        ``replays``) and wait until both are written; what failed there is raised here."""
        if self.failed is not None:
            raise self.failed
        self.writing = True
        self._send(("bode", bode))
        self._send(("responses", responses))
        for exc in [self._answer(), self._answer()]:
            if exc is not None:
                raise exc

    def _send(self, message) -> None:
        try:
            self.conn.send(message)
        except BrokenPipeError:
            raise self._ended() from None

    def _answer(self):
        """What one picture's drawing raised there, or None once it is written."""
        try:
            status, detail = self.answers.recv()
        except EOFError:
            return self._ended()
        return detail if status == "error" else None

    def _ended(self) -> InputError:
        try:
            code = self.proc.wait(ENDED_WAIT_S)     # its pipe is closed: it has ended, or is
        except subprocess.TimeoutExpired:          # ending
            code = None
        return InputError(f"the plots were not drawn: their process ended (exit code {code})")

    def close(self) -> None:
        """Close the pipes and wait for the process to end: after the step it is in once
        it may be writing a picture, at once before (it has written nothing then)."""
        self.conn.close()
        self.answers.close()
        if not self.writing:
            self.proc.kill()
        try:
            self.proc.wait(END_WAIT_S)
        except subprocess.TimeoutExpired:
            self.proc.kill()
            self.proc.wait()

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()


class InlinePlots:
    """:class:`PlotProcess`'s steps in this process, one after the other: where every core
    is busy anyway (the demo runs its axes side by side), another interpreter would only
    add its own start to the work."""

    def __init__(self):
        self.figure = None

    def records(self, segments, input_name: str, output_name: str) -> None:
        self.figure = ResponsesFigure(segments, input_name, output_name)

    def finish(self, bode: dict, responses: dict) -> None:
        write_bode(**bode)
        self.figure.save(**responses)

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.figure = None


#: Where commands on this thread draw (:func:`drawing_here`): unset, a process of their own.
_HERE = threading.local()


@contextlib.contextmanager
def drawing_here():
    """Within it, on this thread, :func:`command_plots` draws in this process: a study's
    worker, one per core and warm (matplotlib imported by its first run), where a plotting
    process would only add its interpreter's start to every run (about 0.8 s of CPU a
    run, measured) and take a core another worker is using."""
    _HERE.on = True
    try:
        yield
    finally:
        _HERE.on = False


def command_plots():
    """What a command draws with: a :class:`PlotProcess`, or :class:`InlinePlots` within
    :class:`drawing_here`."""
    return InlinePlots() if getattr(_HERE, "on", False) else PlotProcess()


#: What the plotting process runs.
SERVE = "from heliquad.host.present.plot_process import serve; serve()"


def serve() -> None:
    """The plotting process (:data:`SERVE`): the records, then bode.png and responses.png,
    each as it arrives on stdin, the answer to each picture on stdout. A thread reads stdin
    from the start, so the other side's sending never waits for the imports, which are done
    while the records are being estimated. What fails before a picture (an import, the
    records) is the answer to each picture it spoils, not a traceback on the terminal. It
    ends when stdin closes, at once: the interpreter's own clean-up (matplotlib's) would
    only keep the command waiting."""
    conn = Connection(os.dup(0), writable=False)
    answers = Connection(os.dup(1), readable=False)
    os.dup2(2, 1)                               # the answers' pipe is theirs alone
    sys.stdout = sys.stderr
    inbox = queue.SimpleQueue()
    threading.Thread(target=_receive, args=(conn, inbox), daemon=True).start()
    try:
        for name in ("matplotlib.backends.backend_agg", "matplotlib.figure",
                     "heliquad.host.estimate.fit", "heliquad.host.validate.replay"):   # before the records come
            importlib.import_module(name)
        drawers, broken = (write_bode, ResponsesFigure), None
    except Exception as exc:                    # noqa: BLE001 - said to the other side
        drawers, broken = None, exc
    state = {"drawers": drawers, "broken": broken, "figure": broken}
    while (raw := inbox.get()) is not None:
        answer = _handle(raw, state)
        if answer is _END:
            break
        try:
            if answer is not None:
                answers.send(answer)
        except BrokenPipeError:
            break
    sys.stdout.flush()
    sys.stderr.flush()
    os._exit(0)


#: What :func:`_handle` answers to a message it cannot read while nothing else is broken.
_END = ("end", None)


def _handle(raw, state):
    """The answer to one pickled message: None to the records (they have none), ``("done",
    None)`` or ``("error", exc)`` to a picture, _END to one that cannot be read (not ours,
    unless the imports failed, which is then the answer). ``state``: the ``drawers``
    (write_bode and ResponsesFigure), what ``broken`` the imports, and the records'
    ``figure`` (or what they raised)."""
    try:
        message = pickle.loads(raw)
    except Exception:                           # noqa: BLE001
        return _END if state["broken"] is None else ("error", _sendable(state["broken"]))
    try:
        if message[0] == "records":
            state["figure"] = state["broken"] or state["drawers"][1](*message[1:])
            return None
        _draw(state["drawers"], state["broken"], state["figure"], message)
        return ("done", None)
    except Exception as exc:                    # noqa: BLE001 - said to the other side
        if message[0] == "records":
            state["figure"] = exc
            return None
        return ("error", _sendable(exc))


def _draw(drawers, broken, figure, message) -> None:
    """One picture: bode.png, or responses.png onto the records' ``figure``; raises what
    spoils it (``broken``: the imports' failure; ``figure``: the records' failure)."""
    if broken is not None:
        raise broken
    if message[0] == "bode":
        drawers[0](**message[1])
    elif isinstance(figure, Exception):
        raise figure
    else:
        figure.save(**message[1])


def _receive(conn, inbox) -> None:
    """Every message on ``conn`` into ``inbox`` as it came (pickled: unpickling here could
    import numpy while the other thread imports it, and a module imported from two threads
    at once can be seen half made), then None once it closes."""
    try:
        while True:
            inbox.put(conn.recv_bytes())
    except (EOFError, OSError):
        inbox.put(None)


def _sendable(exc: Exception) -> Exception:
    """What the other side is to raise for ``exc``: ``exc`` itself when it is an input or
    a file's error (a full disk, a folder not ours) that goes through a pipe whole, else an
    InputError naming it (matplotlib broken, say)."""
    if isinstance(exc, (InputError, OSError)):
        try:
            pickle.loads(pickle.dumps(exc))
            return exc
        except Exception:                       # noqa: BLE001
            pass
    return InputError(f"the plots were not drawn: {type(exc).__name__}: {exc}")
