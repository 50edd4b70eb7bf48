"""Announcements: how a board emulated by ``heliquad board`` makes its port findable by
``--port auto``, which lists USB devices through pyserial and so cannot see a pty.

While a board runs, it keeps one small JSON file, ``board-PID.json`` (PID: its process), in
the announcement folder: ``$HELIQUAD_BOARDS_DIR`` when set (tests point it at a folder of
their own), else ``$XDG_RUNTIME_DIR/heliquad-boards``, else ``heliquad-boards-UID`` in the
temporary folder (a relative $HELIQUAD_BOARDS_DIR is taken from the current folder). The
file carries the pty's path and the USB identity the board stands in
for (the Teensy image's vendor and product IDs and strings, from the firmware's facts, and a
serial number: the emulated chip's, or :data:`HOST_BUILD_SERIAL`); docs/file-formats.md has
its keys. It is written once the pty exists and removed when the board stops; the folder
goes with it when the board made it. A board that cannot announce says so in one line on
stderr and runs on.

The board holds an exclusive lock (flock) on its file for its life: a file whose lock can be
taken is stale (its board was killed outright; its process number and pty may since belong
to something else) and is removed. :func:`announcements` lists the live ones. Everything else
is ignored, never an error and never a wait: a folder that is not this user's alone (owned by
another user, or group or other may write it), a file that is a link, not a regular file of
this user's or larger than :data:`MAX_BYTES`, not a well-formed announcement, and a device
that is not a pty's terminal owned by this user.
"""

from __future__ import annotations

import contextlib
import dataclasses
import json
import os
import re
import stat
import sys
import tempfile

try:
    import fcntl
except ImportError:               # Windows: no ptys, so no boards to announce or find
    fcntl = None

from ..base.firmware_facts import USB_IDENTITY

__all__ = ["BoardPort", "FOLDER_ENV", "HOST_BUILD_SERIAL", "announced", "announcements",
           "folder"]

#: The environment variable that puts the announcement folder elsewhere (tests do).
FOLDER_ENV = "HELIQUAD_BOARDS_DIR"
#: The serial number a board running the host build announces (it has no chip).
HOST_BUILD_SERIAL = "host-build"
#: What the file's "format" key says, and its version.
FORMAT = "heliquad board announcement"
VERSION = 1
#: An announcement is a few hundred bytes; a file larger than this is not one.
MAX_BYTES = 4096
_NAME = re.compile(r"board-([0-9]+)\.json")
#: The device numbers (majors) of Linux's pty terminals (Documentation/admin-guide/devices.txt:
#: UNIX98 PTY slaves, 136-143).
PTY_MAJORS = range(136, 144)
#: The keys and their types: the file has exactly these.
_KEYS = {"format": str, "version": int, "process": int, "device": str, "vid": int, "pid": int,
         "manufacturer": str, "product": str, "serial_number": str, "firmware": str}


@dataclasses.dataclass(frozen=True)
class BoardPort:
    """A serial port and the USB identity it shows (None: the system does not say)."""

    device: str
    vid: int | None
    pid: int | None
    product: str | None
    serial_number: str | None
    #: What publishes it: "usb" (a device pyserial lists) or "heliquad board" (announced).
    source: str = "usb"
    #: What an announced board runs ("host", "teensy35"); None for a USB device.
    firmware: str | None = None


def folder() -> str:
    """Where announcements are kept (module docstring), as an absolute path."""
    if os.environ.get(FOLDER_ENV):
        return os.path.abspath(os.environ[FOLDER_ENV])
    if os.environ.get("XDG_RUNTIME_DIR"):
        return os.path.join(os.environ["XDG_RUNTIME_DIR"], "heliquad-boards")
    return os.path.join(tempfile.gettempdir(), f"heliquad-boards-{_uid()}")


def _uid() -> int:
    return os.getuid() if hasattr(os, "getuid") else 0


def _refusal(path: str) -> str | None:
    """Why the folder ``path`` is not to be trusted (another user who may write it could
    announce ports of theirs), or None: it is a folder this user owns that no one else may
    write."""
    try:
        st = os.stat(path)
    except OSError as exc:
        return exc.strerror or type(exc).__name__
    if not stat.S_ISDIR(st.st_mode):
        return "not a folder"
    if hasattr(os, "getuid") and st.st_uid != _uid():
        return "another user owns it"
    if st.st_mode & 0o022:
        return "group or other may write it"
    return None


@contextlib.contextmanager
def announced(device: str, serial_number: str, firmware: str):
    """Inside, ``device`` (a pty that exists) is announced with the Teensy image's USB
    identity and ``serial_number``, its file locked; the file is removed at the end, and the
    folder too when this board made it and it is empty. When it cannot be announced: one line
    on stderr saying why, and the board runs unannounced."""
    where = folder()
    record = {"format": FORMAT, "version": VERSION, "process": os.getpid(),
              "device": os.path.abspath(device), **USB_IDENTITY._asdict(),
              "serial_number": serial_number, "firmware": firmware}
    held = _write(where, f"board-{os.getpid()}.json", json.dumps(record, indent=1) + "\n")
    if isinstance(held, str):
        sys.stderr.write(f"heliquad board: not announced in {where} ({held}); --port auto "
                         "will not find this board\n")
        sys.stderr.flush()
        held = None
    try:
        yield None if held is None else held[0]
    finally:
        if held is not None:
            path, fd, made = held
            with contextlib.suppress(OSError):
                os.remove(path)
            os.close(fd)                             # the lock goes with it
            if made:
                with contextlib.suppress(OSError):   # another board's file is still there
                    os.rmdir(where)


def _write(where: str, name: str, text: str):
    """``text`` into ``where``/``name`` whole (written aside, locked, then renamed): the path,
    the descriptor that holds its lock and whether the folder was made here; else why not."""
    why = "the folder went away"
    for _ in range(3):            # another board may remove the folder as it empties it
        try:
            made = _make_folder(where)
            refusal = _refusal(where)
            if refusal is not None:
                return refusal
            fd, tmp = tempfile.mkstemp(prefix=".board-", dir=where)
        except FileNotFoundError:
            continue
        except OSError as exc:
            return exc.strerror or type(exc).__name__
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
            data = text.encode("utf-8")
            if os.write(fd, data) != len(data):
                raise OSError(0, "the file was written short")
            os.replace(tmp, os.path.join(where, name))
            return os.path.join(where, name), fd, made
        except OSError as exc:
            os.close(fd)
            with contextlib.suppress(OSError):
                os.remove(tmp)
            why = exc.strerror or type(exc).__name__
            if not isinstance(exc, FileNotFoundError):
                return why
    return why


def _make_folder(where: str) -> bool:
    """Make the folder ``where`` (only this user may enter it); whether it was made here."""
    os.makedirs(os.path.dirname(where), exist_ok=True)
    try:
        os.mkdir(where, 0o700)
    except FileExistsError:
        return False
    return True


def announcements() -> list[BoardPort]:
    """The boards announced in :func:`folder` that are running now, by path."""
    where = folder()
    if os.name != "posix" or _refusal(where) is not None:    # boards run on ptys: POSIX only
        return []
    try:
        names = sorted(os.listdir(where))
    except OSError:
        return []
    found = []
    for name in names:
        match = _NAME.fullmatch(name)
        record = _read(os.path.join(where, name)) if match else None
        if record is not None and record["process"] == int(match.group(1)) \
                and _pty(record["device"]):
            found.append(BoardPort(record["device"], record["vid"], record["pid"],
                                   record["product"], record["serial_number"],
                                   source="heliquad board", firmware=record["firmware"]))
    return sorted(found, key=lambda port: port.device)


def _read(path: str) -> dict | None:
    """The announcement in ``path`` when it is a regular file of this user's, not larger than
    MAX_BYTES, and its board holds its lock; else None (and a stale one is removed). Opened
    without following a link and without waiting (a FIFO does not block)."""
    try:
        fd = os.open(path, os.O_RDONLY | os.O_NOFOLLOW | os.O_NONBLOCK | os.O_NOCTTY)
    except OSError:
        return None
    try:
        st = os.fstat(fd)
        if not stat.S_ISREG(st.st_mode) or st.st_uid != _uid() or st.st_size > MAX_BYTES:
            return None
        if not _locked(fd):
            _remove_stale(path, st)
            return None
        data = os.read(fd, MAX_BYTES + 1)
    except OSError:
        return None
    finally:
        os.close(fd)
    return _parse(data)


def _locked(fd: int) -> bool:
    """Whether another open file (its board) holds a lock on ``fd``'s file."""
    try:
        fcntl.flock(fd, fcntl.LOCK_SH | fcntl.LOCK_NB)
    except BlockingIOError:
        return True
    return False                  # taken: closing ``fd`` lets it go


def _remove_stale(path: str, st: os.stat_result) -> None:
    """Remove ``path`` if it is still the file ``st`` describes (best effort)."""
    with contextlib.suppress(OSError):
        now = os.lstat(path)
        if (now.st_dev, now.st_ino) == (st.st_dev, st.st_ino):
            os.remove(path)


def _parse(data: bytes) -> dict | None:
    """The announcement in ``data`` with exactly its keys and their types, or None."""
    try:
        record = json.loads(data.decode("utf-8")) if len(data) <= MAX_BYTES else None
    except ValueError:
        return None
    if not isinstance(record, dict) or set(record) != set(_KEYS) \
            or record["format"] != FORMAT or record["version"] != VERSION:
        return None
    if not all(type(record[key]) is kind for key, kind in _KEYS.items()):
        return None
    return record


def _pty(path: str) -> bool:
    """Whether ``path`` (absolute) is a pty's terminal that this user owns. On Linux by its
    device number, without opening it; elsewhere opened without waiting and without
    becoming the controlling terminal, and asked."""
    try:
        st = os.stat(path)
    except (OSError, ValueError):
        return False
    if not os.path.isabs(path) or not stat.S_ISCHR(st.st_mode) or st.st_uid != _uid():
        return False
    if sys.platform.startswith("linux"):
        return os.major(st.st_rdev) in PTY_MAJORS
    try:
        fd = os.open(path, os.O_RDWR | os.O_NONBLOCK | os.O_NOCTTY)
    except OSError:
        return False
    try:
        return os.isatty(fd)
    finally:
        os.close(fd)
