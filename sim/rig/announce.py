"""Announcements: how a board emulated by ``heliquad board`` makes its port findable by
``--port auto``, which lists USB devices through pyserial and so cannot see a pty.

While a board runs, it keeps one small JSON file, ``board-PID.json`` (PID: its process), in
the announcement folder: ``$HELIQUAD_BOARDS_DIR`` when set (tests point it at a folder of
their own), else ``$XDG_RUNTIME_DIR/heliquad-boards``, else ``heliquad-boards-UID`` in the
temporary folder. The file carries the pty's path and the USB identity the board stands in
for (the Teensy image's vendor and product IDs and strings, from the firmware's facts, and a
serial number: the emulated chip's, or :data:`HOST_BUILD_SERIAL`); docs/file-formats.md has
its keys. It is written once the pty exists and removed when the board stops.

:func:`announcements` lists the live ones. A file that is not a well-formed announcement,
whose process is gone (a board killed outright leaves its file), whose path is not a
terminal device that exists, or in a folder another user owns, is ignored: never an error.
"""

from __future__ import annotations

import contextlib
import dataclasses
import json
import os
import re
import stat
import tempfile

from ..base.firmware_facts import USB_MANUFACTURER, USB_PID, USB_PRODUCT, USB_VID

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
_NAME = re.compile(r"^board-([0-9]+)\.json$")
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


def folder() -> str:
    """Where announcements are kept (module docstring)."""
    if os.environ.get(FOLDER_ENV):
        return os.environ[FOLDER_ENV]
    if os.environ.get("XDG_RUNTIME_DIR"):
        return os.path.join(os.environ["XDG_RUNTIME_DIR"], "heliquad-boards")
    return os.path.join(tempfile.gettempdir(), f"heliquad-boards-{_uid()}")


def _uid() -> int:
    return os.getuid() if hasattr(os, "getuid") else 0


def _ours(path: str) -> bool:
    """Whether ``path`` is a folder this user owns (another user's could carry false ports)."""
    try:
        st = os.stat(path)
    except OSError:
        return False
    return stat.S_ISDIR(st.st_mode) and (not hasattr(os, "getuid") or st.st_uid == _uid())


@contextlib.contextmanager
def announced(device: str, serial_number: str, firmware: str):
    """Inside, ``device`` (a pty that exists) is announced with the Teensy image's USB
    identity and ``serial_number``; the file is removed at the end, and the folder too once
    empty. A folder that cannot be made or is not this user's: no announcement."""
    where = folder()
    record = {"format": FORMAT, "version": VERSION, "process": os.getpid(),
              "device": os.path.abspath(device), "vid": USB_VID, "pid": USB_PID,
              "manufacturer": USB_MANUFACTURER, "product": USB_PRODUCT,
              "serial_number": serial_number, "firmware": firmware}
    path = _write(where, f"board-{os.getpid()}.json", json.dumps(record, indent=1) + "\n")
    try:
        yield path
    finally:
        if path is not None:
            with contextlib.suppress(OSError):
                os.remove(path)
            with contextlib.suppress(OSError):       # another board's file is still there
                os.rmdir(where)


def _write(where: str, name: str, text: str) -> str | None:
    """``text`` into ``where``/``name`` whole (written aside, then renamed), or None."""
    for _ in range(3):            # another board may remove the folder as it empties it
        try:
            os.makedirs(where, mode=0o700, exist_ok=True)
            if not _ours(where):
                return None
            fd, tmp = tempfile.mkstemp(prefix=".board-", dir=where)
            with os.fdopen(fd, "w") as fh:
                fh.write(text)
            os.replace(tmp, os.path.join(where, name))
            return os.path.join(where, name)
        except FileNotFoundError:
            continue
        except OSError:
            return None
    return None


def announcements() -> list[BoardPort]:
    """The boards announced in :func:`folder` that are running now, by path."""
    where = folder()
    if os.name != "posix" or not _ours(where):    # boards run on ptys: POSIX only
        return []
    try:
        names = sorted(os.listdir(where))
    except OSError:
        return []
    found = []
    for name in names:
        match = _NAME.match(name)
        record = _read(os.path.join(where, name)) if match else None
        if record is not None and record["process"] == int(match.group(1)) \
                and _running(record["process"]) and _terminal(record["device"]):
            found.append(BoardPort(record["device"], record["vid"], record["pid"],
                                   record["product"], record["serial_number"],
                                   source="heliquad board"))
    return sorted(found, key=lambda port: port.device)


def _read(path: str) -> dict | None:
    """The announcement in ``path`` with exactly its keys and their types, or None."""
    try:
        with open(path, "rb") as fh:
            data = fh.read(MAX_BYTES + 1)
        record = json.loads(data.decode("utf-8")) if len(data) <= MAX_BYTES else None
    except (OSError, ValueError):
        return None
    if not isinstance(record, dict) or set(record) != set(_KEYS) \
            or record["format"] != FORMAT or record["version"] != VERSION:
        return None
    if not all(type(record[key]) is kind for key, kind in _KEYS.items()):
        return None
    return record


def _running(pid: int) -> bool:
    """Whether process ``pid`` exists."""
    if pid <= 0:
        return False
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:        # someone else's: it exists
        return True
    except (OSError, OverflowError):
        return False
    return True


def _terminal(path: str) -> bool:
    """Whether ``path`` is a terminal device (a pty, a tty) that exists."""
    try:
        return stat.S_ISCHR(os.stat(path).st_mode) and os.path.isabs(path)
    except (OSError, ValueError):
        return False
