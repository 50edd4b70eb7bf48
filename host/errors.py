"""Errors the host tool reports to users as one line, without a traceback."""

__all__ = ["InputError", "Terminated"]


class InputError(ValueError):
    """Bad user input: a malformed file, an impossible option, too little data.

    The command-line interface prints ``str(error)`` on one line and exits with code 2.
    """


class Terminated(KeyboardInterrupt):
    """SIGTERM, raised where the signal arrives (the command line installs the handler) so
    a run ends as it does on Ctrl-C: the excitation stopped, the records kept and marked,
    the firmware stopped and its temporary folder removed."""
