"""The ``heliquad`` command line: the parser, and the one place errors become exit codes.

Every subcommand (one module each, :mod:`heliquad.host.commands`) reports bad input as one
line on stderr (``heliquad SUB: error: ...``) and exits with code 2; no traceback reaches
the user for an input problem. A full disk (``heliquad SUB: disk full: FILE ...``) exits 1,
Ctrl-C 130, SIGTERM 143, each after the command has stopped what it runs and kept what it
recorded.
"""

from __future__ import annotations

import argparse
import os
import re
import signal
import sys

# Before numpy is imported: heliquad's matrices are small (a fit's few dozen rows, the FSF's
# few columns), and OpenBLAS's threads, one a core, only spin beside them and take the core
# that identify's plotting process needs (identify of a 10-minute session: 2.5 s of CPU
# instead of 3.0, 0.25 s sooner). Whoever sets it keeps their setting.
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

from . import __version__
from .errors import DiskFull, InputError, Terminated, no_room

__all__ = ["main"]

EXIT_INPUT = 2
#: A run that stopped early and kept its records (a full disk; a sweep's abort).
EXIT_STOPPED = 1
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
    from .commands import add_parsers

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


def _on_sigterm(signum, frame):
    raise Terminated()


def main(argv=None) -> int:
    """Entry point of the ``heliquad`` console script."""
    try:
        args = _build_parser(argv).parse_args(argv)
    except InputError as exc:            # the parser's choices come from the generated dialect
        sys.stderr.write(f"heliquad: error: {exc}\n")
        return EXIT_INPUT
    signal.signal(signal.SIGTERM, _on_sigterm)
    try:
        return args.func(args)
    except InputError as exc:
        sys.stderr.write(f"heliquad {args.command}: error: {exc}\n")
        return EXIT_INPUT
    except BrokenPipeError:              # e.g. piped into `head`: not an error
        sys.stderr.close()
        return 0
    except KeyboardInterrupt as exc:
        terminated = isinstance(exc, Terminated)
        sys.stderr.write(f"heliquad {args.command}: {'terminated' if terminated else 'interrupted'}\n")
        return 143 if terminated else 130
    except DiskFull as exc:
        sys.stderr.write(f"heliquad {args.command}: {exc}\n")
        return EXIT_STOPPED
    except OSError as exc:
        if no_room(exc):
            sys.stderr.write(f"heliquad {args.command}: {DiskFull.from_os_error(exc.filename or 'an output file', exc)}\n")
            return EXIT_STOPPED
        where = f": {exc.filename}" if exc.filename else ""
        sys.stderr.write(f"heliquad {args.command}: error: {exc.strerror or exc}{where}\n")
        return EXIT_INPUT


def entry() -> None:
    """The ``heliquad`` console script: :func:`main`, then the process ends at once with its
    exit code, stdout and stderr flushed. Python's own clean-up after a command (tearing down
    the modules it imported: 40-60 ms once scipy's are among them) would serve nothing: every
    file heliquad writes is closed before its command returns (and the tests read every
    command's outputs through this path)."""
    code = main()
    for stream in (sys.stdout, sys.stderr):
        try:
            stream.flush()
        except (OSError, ValueError):    # a reader that went away (piped into head); closed
            pass
    os._exit(int(code or 0))


if __name__ == "__main__":
    entry()
