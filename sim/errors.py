"""The error every layer reports to users as one line, without a traceback."""

__all__ = ["InputError"]


class InputError(ValueError):
    """Bad user input: a malformed file, an impossible option, too little data.

    The command-line interface prints ``str(error)`` on one line and exits with code 2.
    """
