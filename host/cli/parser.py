"""The ``heliquad`` command line: the parser, and the one place errors become exit codes.

Exit codes, one rule for every command (docs/architecture.md, "Exit codes"):

* 0: the command did its job.
* 2: the user's input is wrong: arguments, files (``heliquad SUB: error: ...``, one line,
  no traceback).
* 1: the run could not do or finish its job for a reason outside the input: the board
  refused (:class:`~heliquad.sim.base.errors.BoardRefused`), the board went away or fell
  silent (:class:`~heliquad.sim.base.errors.LinkLost`, or an OSError that says a device or
  connection is gone), a disk filled (``heliquad SUB: disk full: FILE ...``), a sweep that
  stopped early; the records made so far are kept.
* 130 (SIGINT, Ctrl-C), 143 (SIGTERM), 129 (SIGHUP: the terminal or SSH session closed),
  each after the same orderly stop: what the command runs stopped, what it recorded kept
  (host/process/signals.py; a signal the program was started with ignored stays ignored).
"""

from __future__ import annotations

from ..commands import add_parsers

if __name__ == "__main__":               # python -m heliquad.host.cli.parser: signals first
    from ..process.signals import take_at_start

    take_at_start()

import argparse
import errno
import os
import re
import sys

# Before numpy is imported: heliquad's matrices are small (a fit's few dozen rows, the FSF's
# few columns), and OpenBLAS's threads, one a core, only spin beside them and take the core
# that identify's plotting process needs (identify of a 10-minute session: 2.5 s of CPU
# instead of 3.0, 0.25 s sooner). Whoever sets it keeps their setting.
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

from ...sim.base.errors import BoardRefused, DiskFull, InputError, LinkLost, no_room
from .. import __version__
from ..process.signals import EXIT_CODES, WORDS, settle, stopped_by, take_while_running

__all__ = ["main"]

EXIT_INPUT = 2
#: A run that could not do or finish its job for a reason outside the input (the board
#: refused, went away or fell silent; a full disk; a sweep's abort), its records kept.
EXIT_STOPPED = 1
#: What an OSError says when the device or connection under a run went away (a USB serial
#: port unplugged: EIO or ENXIO; a connection reset): the board is gone, not the input wrong.
LINK_GONE = frozenset({errno.EIO, errno.ENXIO, errno.ENODEV, errno.ECONNRESET})
#: What argparse takes for a negative number rather than an option (no option of heliquad's
#: looks like one).
NEGATIVE_NUMBER = re.compile(r"^-(\d+\.?\d*|\.\d+)([eE][-+]?\d+)?$")


class _Parser(argparse.ArgumentParser):
    """argparse with a one-line error and exit code 2, and negative numbers in exponent
    form (``--den 1 -1e5``) read as values: argparse's own test knows only ``-1`` and
    ``-1.5`` and took ``-1e5`` for an unknown option."""

    def __init__(self, *args, **kwargs):
        super().__init__(*args, **kwargs)
        self._negative_number_matcher = NEGATIVE_NUMBER

    def error(self, message):
        sys.stderr.write(f"{self.prog}: error: {message} (see {self.prog} --help)\n")
        sys.exit(EXIT_INPUT)


def _build_parser(argv=None) -> argparse.ArgumentParser:
    """The parser, with the subcommand ``argv`` names only when it names one
    (:func:`~heliquad.host.commands.add_parsers`)."""
    parser = _Parser(prog="heliquad",
                     description="Firmware-in-the-loop flight-controller emulator and "
                                 "frequency-domain system identification for heterogeneous "
                                 "multirotors.")
    parser.add_argument("--version", action="version", version=f"heliquad {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", parser_class=_Parser)
    sub.required = True
    add_parsers(sub, argparse.RawDescriptionHelpFormatter,
                sys.argv[1:] if argv is None else argv)
    return parser


#: Whether this process is the program (:func:`entry`), not a caller of :func:`main`.
_program = False


def main(argv=None) -> int:
    """Entry point of the ``heliquad`` console script: the command's exit code."""
    command = "heliquad"
    try:
        args = _build_parser(argv).parse_args(argv)
        command = f"heliquad {args.command}"
        take_while_running()
        return args.func(args)
    except BaseException as exc:                 # noqa: BLE001: every ending has its code
        if _program:
            settle()                             # a second signal cannot break the line
        return _ending(command, exc)


def _ending(command: str, exc: BaseException) -> int:
    """Say why ``command`` ended in one line on stderr and return its exit code (the rule in
    the module's docstring); an exception not of the rule goes on (a bug: its traceback)."""
    if isinstance(exc, SystemExit):              # --help, --version, the parser's errors
        raise exc
    if isinstance(exc, BrokenPipeError):         # e.g. piped into `head`: not an error
        sys.stderr.close()
        return 0
    if isinstance(exc, KeyboardInterrupt):       # SIGINT, SIGTERM, SIGHUP: after the stop
        signum = stopped_by(exc)
        sys.stderr.write(f"{command}: {WORDS[signum]}\n")
        return EXIT_CODES[signum]
    if isinstance(exc, (LinkLost, BoardRefused)):
        sys.stderr.write(f"{command}: error: {exc}\n")
        return EXIT_STOPPED
    if isinstance(exc, InputError):              # the parser's choices come from the dialect
        sys.stderr.write(f"{command}: error: {exc}\n")
        return EXIT_INPUT
    if isinstance(exc, DiskFull):
        sys.stderr.write(f"{command}: {exc}\n")
        return EXIT_STOPPED
    if isinstance(exc, OSError):
        return _os_error(command, exc)
    raise exc


def _os_error(command: str, exc: OSError) -> int:
    if no_room(exc):
        sys.stderr.write(f"{command}: {DiskFull.from_os_error(exc.filename or 'an output file', exc)}\n")
        return EXIT_STOPPED
    where = f": {exc.filename}" if exc.filename else ""
    if exc.errno in LINK_GONE and _not_a_file(exc.filename):
        sys.stderr.write(f"{command}: error: the board went away: {exc.strerror or exc}{where}\n")
        return EXIT_STOPPED
    sys.stderr.write(f"{command}: error: {exc.strerror or exc}{where}\n")
    return EXIT_INPUT


def _not_a_file(filename) -> bool:
    """Whether an OSError's file is a device or none (a socket, a port): an EIO from a user's
    file on a failing disk is that file's problem, not a board gone."""
    return not filename or os.path.realpath(os.fsdecode(filename)).startswith("/dev/")


def entry() -> None:
    """The ``heliquad`` console script: :func:`main`, then the process ends at once with its
    exit code, stdout and stderr flushed. Python's own clean-up after a command (tearing down
    the modules it imported: 40-60 ms once scipy's are among them) would serve nothing: every
    file heliquad writes is closed before its command returns (and the tests read every
    command's outputs through this path)."""
    global _program
    _program = True
    code = main()
    settle()
    for stream in (sys.stdout, sys.stderr):
        try:
            stream.flush()
        except (OSError, ValueError):    # a reader that went away (piped into head); closed
            pass
    os._exit(int(code or 0))


if __name__ == "__main__":
    entry()
