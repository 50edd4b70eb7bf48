"""How the ``heliquad`` program takes signals: the one place (exit codes: host/cli/parser.py).

* While it starts (interpreter, imports, parsing), nothing is open and nothing runs under
  it: SIGINT, SIGTERM and SIGHUP end it at once with one line and the signal's exit code
  (:func:`take_at_start`, installed by the program's first statement, host/cli/program.py).
* While a command runs, SIGINT raises KeyboardInterrupt, SIGTERM :class:`Terminated` and
  SIGHUP :class:`HungUp` where they land (:func:`take_while_running`), so every long command
  stops in the same order whichever came: the excitation stopped, the records kept and
  marked, the firmware stopped and its temporary folder removed.
* A signal the program was started with ignored stays ignored, as POSIX has background
  jobs and ``nohup`` do: a shell starts ``cmd &`` with SIGINT ignored (a terminal's Ctrl-C
  is not for it), ``nohup`` starts it with SIGHUP ignored. SIGTERM is always taken: it is
  how a service manager or a script stops a command, whatever it was started with.

Deliberately small (os and signal only): the program imports it before anything else.
"""

import contextlib
import os
import signal
import sys

__all__ = ["EXIT_CODES", "ABORTED_BY", "Terminated", "HungUp", "take_at_start",
           "take_while_running", "settle", "stopped_by", "ignoring", "TERMINAL_SIGNALS"]


class Terminated(KeyboardInterrupt):
    """SIGTERM, raised where the signal arrives (the command line installs the handler) so
    a run ends as it does on Ctrl-C: the excitation stopped, the records kept and marked,
    the firmware stopped and its temporary folder removed."""


class HungUp(Terminated):
    """SIGHUP: the terminal or SSH session the command ran in closed. The run ends as it
    does on SIGTERM (exit 129 instead of 143)."""

#: What each signal ends a command with: 128 + its number, as a shell reports a process
#: the signal killed, and the word said for it.
EXIT_CODES = {signal.SIGINT: 130, signal.SIGTERM: 143, signal.SIGHUP: 129}
WORDS = {signal.SIGINT: "interrupted", signal.SIGTERM: "terminated", signal.SIGHUP: "hung up"}
#: How a run's records (a sweep's manifest) say which signal stopped it.
ABORTED_BY = {signal.SIGINT: "interrupted (Ctrl-C)", signal.SIGTERM: "terminated (SIGTERM)",
              signal.SIGHUP: "hung up (SIGHUP)"}
#: The signals a started-with-ignored disposition is kept for (POSIX background jobs, nohup).
KEEP_IGNORED = (signal.SIGINT, signal.SIGHUP)
#: What a terminal sends its foreground process group: Ctrl-C, and the hang-up when it
#: closes. A child started while they are ignored keeps ignoring them (a Python one too: it
#: takes SIGINT only when it starts with it at its default), so the terminal's signal
#: reaches this process, which stops the child in order.
TERMINAL_SIGNALS = (signal.SIGINT, signal.SIGHUP)

_ignored_at_start: set = set()


def _command() -> str:
    """`` COMMAND`` when the command line names one, for the one line said."""
    words = [a for a in sys.argv[1:] if not a.startswith("-")]
    # A command's name: letters and dashes (mavlink-dialect), nothing a user typed to confuse.
    return f" {words[0]}" if words and words[0].replace("-", "_").isidentifier() else ""


def _ended_at_start(signum, frame) -> None:
    os.write(2, f"heliquad{_command()}: {WORDS[signum]}\n".encode())
    os._exit(EXIT_CODES[signum])


def take_at_start() -> None:
    """Install the start-up handlers: each of the three signals ends the program at once,
    with its line and code, except one it was started with ignored (:data:`KEEP_IGNORED`)."""
    for signum in EXIT_CODES:
        if signum in KEEP_IGNORED and signal.getsignal(signum) is signal.SIG_IGN:
            _ignored_at_start.add(signum)
            continue
        signal.signal(signum, _ended_at_start)


def stop_exception(signum: int) -> KeyboardInterrupt:
    """What a stop by ``signum`` raises where it lands: KeyboardInterrupt (SIGINT),
    :class:`Terminated` (SIGTERM), :class:`HungUp` (SIGHUP); :func:`stopped_by` reads it
    back."""

    return {signal.SIGTERM: Terminated, signal.SIGHUP: HungUp}.get(signum, KeyboardInterrupt)()


def _raise_stop(signum, frame):
    raise stop_exception(signum)


def take_while_running() -> None:
    """The handlers while a command runs: SIGINT raises KeyboardInterrupt, SIGTERM
    :class:`Terminated`, SIGHUP :class:`HungUp`; one started with ignored stays ignored."""
    for signum in EXIT_CODES:
        if signum in KEEP_IGNORED and (signum in _ignored_at_start or
                                       signal.getsignal(signum) is signal.SIG_IGN):
            continue
        signal.signal(signum, signal.default_int_handler if signum == signal.SIGINT
                      else _raise_stop)


def settle() -> None:
    """Once the program's exit code is decided, the three signals are ignored: one that comes
    while it says why it ended and exits cannot add a traceback to that line."""
    for signum in EXIT_CODES:
        signal.signal(signum, signal.SIG_IGN)


def stopped_by(exc: BaseException) -> int:
    """The signal a KeyboardInterrupt (or :class:`Terminated`, :class:`HungUp`) stands for."""

    if isinstance(exc, HungUp):
        return signal.SIGHUP
    return signal.SIGTERM if isinstance(exc, Terminated) else signal.SIGINT


@contextlib.contextmanager
def ignoring(signums=tuple(EXIT_CODES)):
    """``signums`` (default SIGINT, SIGTERM and SIGHUP) ignored inside, their handlers put
    back at the end: while children stop in order, or while children are started that must
    not take them (:data:`TERMINAL_SIGNALS`). Main thread only."""
    before = {s: signal.signal(s, signal.SIG_IGN) for s in signums}
    try:
        yield
    finally:
        for s, handler in before.items():
            signal.signal(s, handler)
