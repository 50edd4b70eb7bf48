"""MAVLink telemetry logs (.tlog): each message as an 8-byte big-endian timestamp (us) then
the raw MAVLink packet, the format QGroundControl and pymavlink's tools read.

The writer flushes as it goes, so a crash or Ctrl-C leaves a valid log up to the last whole
message, and it never writes over a file that exists (:func:`create_log`): a log is a record
of a flight or a rig session that cannot be made again. The reader stops at damage (a
truncated or corrupted tail) with a warning.
"""

from __future__ import annotations

import struct
import warnings

__all__ = ["TlogWriter", "create_log", "read_tlog"]

_STAMP = struct.Struct(">Q")


def create_log(path, what: str = "log"):
    """A new file for a log, opened for binary writing; one that exists is never truncated
    (InputError naming it and how to go on)."""
    from .errors import InputError

    try:
        return open(path, "xb")
    except FileExistsError:
        raise InputError(f"{path} exists: heliquad never writes over a {what}; give another "
                         "name (or move the old one away)") from None
    except OSError as exc:
        raise InputError(f"cannot create {path}: {exc.strerror or exc}") from None


class TlogWriter:
    """Append MAVLink packets with timestamps to a .tlog file."""

    def __init__(self, path):
        self.path = path
        self._fh = create_log(path)
        self.messages = 0

    def write(self, timestamp_us: int, packet: bytes) -> None:
        self._fh.write(_STAMP.pack(int(timestamp_us)))
        self._fh.write(packet)
        self.messages += 1

    def flush(self) -> None:
        self._fh.flush()

    def close(self) -> None:
        if not self._fh.closed:
            self._fh.close()

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()


def read_tlog(path, mav_module, only=None):
    """Messages of a .tlog as ``(timestamp_us, message)``, up to the first damage.

    A truncated last record or a packet that fails its CRC ends the read with a warning
    naming the byte offset; what came before is returned. ``only``: message type names to
    decode (default all).
    """
    from .mavframe import HEADER_LEN, INCOMPAT_SIGNED, SIGNATURE_LEN, STX_V2, Codec, Framer

    with open(path, "rb") as fh:
        data = fh.read()
    codec = Codec(mav_module)
    wanted = None if only is None else {cls.msgname for cls in codec.classes.values()} & set(only)
    out, pos = [], 0
    while pos < len(data):
        if len(data) - pos < 8 + HEADER_LEN or data[pos + 8] != STX_V2:
            break
        length = data[pos + 9]
        total = HEADER_LEN + length + 2 + (SIGNATURE_LEN if data[pos + 10] & INCOMPAT_SIGNED else 0)
        packet = data[pos + 8:pos + 8 + total]
        framed = Framer(codec).feed(packet) if len(packet) == total else []
        if len(framed) != 1 or len(framed[0][1]) != total:   # not a packet found inside it
            break
        msgid, _, payload = framed[0]
        cls = codec.classes[msgid]
        if wanted is None or cls.msgname in wanted:
            out.append((struct.unpack(">Q", data[pos:pos + 8])[0], codec.decode(msgid, payload)))
        pos += 8 + total
    if pos < len(data):
        warnings.warn(f"{path}: damaged or truncated at byte {pos} of {len(data)}; "
                      f"read the {len(out)} messages before it")
    return out
