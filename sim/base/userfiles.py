"""Reading a file a user gave, for every layer: the text, or one line naming the file and
what is wrong with it (:class:`~heliquad.sim.base.errors.InputError`)."""

from __future__ import annotations

from .errors import InputError

__all__ = ["read_text", "open_binary"]


def open_binary(path, what: str = "file"):
    """A file a user gave, opened for binary reading. InputError, naming the file, when it
    is missing, a folder or unreadable."""
    try:
        return open(path, "rb")
    except FileNotFoundError:
        raise InputError(f"{path}: no such file") from None
    except IsADirectoryError:
        raise InputError(f"{path}: is a folder, not a {what}") from None
    except OSError as exc:
        raise InputError(f"{path}: {exc.strerror or exc}") from None


def read_text(path, limit: int, what: str = "file") -> str:
    """The text of a file a user gave: UTF-8 (a byte-order mark is dropped), at most
    ``limit`` bytes. InputError, naming the file, when it is missing, a folder, unreadable,
    larger, not UTF-8 or empty."""
    with open_binary(path, what) as fh:
        try:
            data = fh.read(limit + 1)
        except OSError as exc:
            raise InputError(f"{path}: {exc.strerror or exc}") from None
    if len(data) > limit:
        raise InputError(f"{path}: larger than {limit // 2**20} MiB: not a {what}")
    try:
        text = data.decode("utf-8-sig")
    except UnicodeDecodeError as exc:
        raise InputError(f"{path}: not UTF-8 text (byte {exc.start}): not a {what}") from None
    if not text.strip():
        raise InputError(f"{path}: empty file (expected a {what})")
    return text
