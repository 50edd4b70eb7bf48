"""MAVLink telemetry logs (.tlog): each message as an 8-byte big-endian timestamp (us) then
the raw MAVLink packet, the format QGroundControl and pymavlink's tools read.

The writer flushes as it goes, so a crash or Ctrl-C leaves a valid log up to the last whole
message. The reader stops at damage (a truncated or corrupted tail) with a warning.
"""

from __future__ import annotations

import struct
import warnings

__all__ = ["TlogWriter", "read_tlog"]


class TlogWriter:
    """Append MAVLink packets with timestamps to a .tlog file."""

    def __init__(self, path):
        self.path = path
        self._fh = open(path, "wb")
        self.messages = 0

    def write(self, timestamp_us: int, packet: bytes) -> None:
        self._fh.write(struct.pack(">Q", int(timestamp_us)) + bytes(packet))
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


def read_tlog(path, mav_module):
    """Messages of a .tlog as ``(timestamp_us, message)``, up to the first damage."""
    data = open(path, "rb").read()
    mav = mav_module.MAVLink(None)
    mav.robust_parsing = True
    out, pos = [], 0
    while pos + 8 < len(data):
        ts = struct.unpack(">Q", data[pos:pos + 8])[0]
        start = pos + 8
        if data[start] not in (0xFD, 0xFE):
            warnings.warn(f"{path}: damaged at byte {pos}; read {len(out)} messages")
            break
        length = data[start + 1] + (12 if data[start] == 0xFD else 8)
        if data[start] == 0xFD and data[start + 2] & 0x01:
            length += 13                              # signed packet
        packet = data[start:start + length]
        try:
            msgs = mav.parse_buffer(packet) if len(packet) == length else None
        except Exception:                             # the generated parser raises its own
            msgs = None
        if not msgs:
            warnings.warn(f"{path}: damaged at byte {pos}; read {len(out)} messages")
            break
        out += [(ts, m) for m in msgs]
        pos = start + length
    return out
