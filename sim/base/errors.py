"""Errors every layer reports to users as one line, without a traceback."""

import errno

__all__ = ["InputError", "FirmwareError", "DiskFull", "LinkLost", "BoardRefused", "NO_ROOM",
           "no_room"]

#: What a write that found no room fails with: the file system is full (ENOSPC), the user's
#: quota is used up (EDQUOT), or the file reached the largest size allowed (EFBIG: the file
#: system's limit, or the process's RLIMIT_FSIZE).
NO_ROOM = frozenset({errno.ENOSPC, errno.EDQUOT, errno.EFBIG})


def no_room(exc: BaseException) -> bool:
    """Whether ``exc`` is a write that failed for want of room (:data:`NO_ROOM`)."""
    return isinstance(exc, OSError) and exc.errno in NO_ROOM


class InputError(ValueError):
    """Bad user input: a malformed file, an impossible option, too little data.

    The command-line interface prints ``str(error)`` on one line and exits with code 2.
    """


class LinkLost(InputError):
    """The board went away or fell silent: a serial port that disappeared, a network link
    the other end closed, requests that went unanswered after every retry; or it cannot be
    reached, its port held by another program. Not the user's
    input: the command-line interface prints it on one line and exits with code 1.

    A subclass of :class:`InputError` so that every place that ends a run in order on a
    problem it can name (a sweep keeps its records and marks its manifest) does so for a
    lost link too; only the exit code differs.
    """


class BoardRefused(InputError):
    """The board refused a command it understood (a parameter it keeps, a start it will
    not make). The command-line interface prints it on one line and exits with code 1; a
    subclass of :class:`InputError` for the same reason as :class:`LinkLost`."""


class FirmwareError(RuntimeError):
    """The firmware stopped answering, died, or broke the link contract."""


class DiskFull(Exception):
    """A record could not be written for want of room (:data:`NO_ROOM`). What was written
    before it is kept whole; the run that was writing stops.

    ``str()`` is one line, ``disk full: PATH (REASON)``, followed by what the run kept, each
    clause added with :meth:`also`. The command-line interface prints it and exits with
    code 1.
    """

    def __init__(self, path, reason: str):
        super().__init__(path, reason)
        self.path, self.reason = str(path), reason
        self.clauses: list[str] = []

    @classmethod
    def from_os_error(cls, path, exc: OSError) -> "DiskFull":
        return cls(path, exc.strerror or str(exc))

    def also(self, clause: str) -> "DiskFull":
        """Add what the run kept (or could not keep) to the message; returns self."""
        self.clauses.append(clause)
        return self

    def __str__(self) -> str:
        return "; ".join([f"disk full: {self.path} ({self.reason})", *self.clauses])
