"""Errors every layer reports to users as one line, without a traceback."""

__all__ = ["InputError", "FirmwareError"]


class InputError(ValueError):
    """Bad user input: a malformed file, an impossible option, too little data.

    The command-line interface prints ``str(error)`` on one line and exits with code 2.
    """


class FirmwareError(RuntimeError):
    """The firmware stopped answering, died, or broke the link contract."""
