"""The ``heliquad`` console script. Its first statement takes the signals (a Ctrl-C while
the interpreter imports heliquad's modules ends the program with one line and exit 130,
host/process/signals.py); only then is the command line (host/cli/parser.py) imported. Nothing but the
program imports this module: importing it changes the process's signal handlers."""

from ..process.signals import take_at_start

take_at_start()


def entry() -> None:
    """The console script's entry point: :func:`heliquad.host.cli.parser.entry`."""
    # after take_at_start: the signals are taken before the command line is imported
    from .parser import entry as run

    run()
