"""MAVLink telemetry logs (.tlog): each message as an 8-byte big-endian timestamp (us) then
the raw MAVLink packet, the format QGroundControl and pymavlink's tools read.

The writer's file only ever ends with a whole record, so a crash, Ctrl-C or a full disk leaves
a valid log up to the last whole message flushed, and it never writes over a file that exists
(:func:`create_log`): a log is a record of a flight or a rig session that cannot be made
again.

The reader takes every well-formed record (a timestamp, then a whole packet of a known
message whose CRC verifies) and resynchronises past damage: where a record does not verify,
it skips byte by byte to the next offset where one does. What it skipped (where and how
much) and the records whose timestamp goes back in time are counted in a
:class:`TlogDamage`; a flipped bit in a packet costs that one message, not the rest of the log.
A timestamp is not covered by the packet's CRC. A damaged one is seen when it breaks the order
of time, and in a simulated session's log whatever it does: there every record is stamped with
the run's start (a fixed offset, the wall clock when it began) plus the time of its control
loop, the ``time_us`` of the first HQ_SYSID_SAMPLE at or after it. A log is taken for one
when more than half of its HQ_SYSID_SAMPLE records are stamped with their own ``time_us``
plus one and the same offset (older logs: an offset of 0), so a record stamped otherwise is
counted. On a board's log (the host's clock) a damaged stamp that keeps time in order cannot
be seen.

Analysis never reads the stamps: each sample's time is its ``time_us``, inside its CRC.
"""

from __future__ import annotations

import collections
import dataclasses
import os
import struct
import warnings

__all__ = ["TlogWriter", "TlogDamage", "create_log", "read_tlog"]

_STAMP = struct.Struct(">Q")


def create_log(path, buffering: int = -1):
    """A new file for a log, opened for binary writing; one that exists is never truncated
    (InputError naming it and how to go on). ``buffering`` as for :func:`open`."""
    from .errors import InputError

    try:
        return open(path, "xb", buffering=buffering)
    except FileExistsError:
        raise InputError(f"{path} exists: heliquad never writes over a log; give another "
                         "name (or move the old one away)") from None
    except OSError as exc:
        raise InputError(f"cannot create {path}: {exc.strerror or exc}") from None


class TlogWriter:
    """Append MAVLink packets with timestamps to a new .tlog file.

    Records wait in memory until :meth:`flush` (a session flushes after every read of its
    link). The file only ever ends with a whole record:

    * a Ctrl-C or SIGTERM during a flush leaves the records it had not written waiting, and
      the next flush (or :meth:`close`) goes on from the file's size, so none is lost or
      written twice;
    * a write that finds no room (a full disk, a file-size limit) cuts the file back to its
      last whole record, stops the log and raises :class:`DiskFull` naming the file; any
      other write error does the same with an OSError. Every record before it is kept.
    """

    def __init__(self, path):
        self.path = path
        self._fh = create_log(path, buffering=0)
        # (bytes of whole records in the file, records waiting): one attribute, replaced in
        # one step, so that an interrupt never finds the two out of step.
        self._state = (0, [])
        self.messages = 0                    # whole records in the file
        self.failed: BaseException | None = None    # what stopped the log

    def write(self, timestamp_us: int, packet: bytes) -> None:
        if self.failed is not None:
            raise self.failed
        self._state[1].append(_STAMP.pack(int(timestamp_us)) + bytes(packet))

    def flush(self) -> None:
        """Write the waiting records (:class:`DiskFull` or OSError when they do not fit)."""
        if self.failed is not None:
            raise self.failed
        size, records = self._state
        if not records:
            return
        data = b"".join(records)
        fd = self._fh.fileno()
        # An earlier flush interrupted by a signal may have written part of these already.
        done = os.fstat(fd).st_size - size
        try:
            with memoryview(data) as view:
                while done < len(data):
                    done += self._fh.write(view[done:])
        except OSError as exc:
            self._stop(exc, size, records)
            raise self.failed from None
        self._state = (size + len(data), [])
        self.messages += len(records)

    def _stop(self, exc: OSError, size: int, records: list) -> None:
        """A write failed: keep the whole records that reached the file, cut the rest."""
        from .errors import DiskFull, no_room

        fd = self._fh.fileno()
        written, kept = os.fstat(fd).st_size - size, 0
        whole = 0
        for record in records:
            if kept + len(record) > written:
                break
            kept += len(record)
            whole += 1
        try:
            os.ftruncate(fd, size + kept)
        except OSError:
            pass                          # the reader skips a record cut short
        self._state = (size + kept, [])
        self.messages += whole
        self.failed = DiskFull.from_os_error(self.path, exc) if no_room(exc) else \
            OSError(exc.errno, exc.strerror, self.path)

    def close(self) -> None:
        """Flush what waits and close the file (once; a log stopped by a failed write is
        closed as it was cut)."""
        if self._fh.closed:
            return
        try:
            if self.failed is None:
                self.flush()
        finally:
            self._fh.close()

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()


@dataclasses.dataclass
class TlogDamage:
    """What a read found wrong with a .tlog."""
    size: int = 0                       # bytes in the file
    regions: list = dataclasses.field(default_factory=list)   # (offset, bytes) skipped
    out_of_order: list = dataclasses.field(default_factory=list)  # offsets of such records
    off_loop: list = dataclasses.field(default_factory=list)  # offsets: not their loop's time
    messages: int = 0                   # well-formed records read

    @property
    def skipped(self) -> int:
        return sum(n for _, n in self.regions)

    def __bool__(self) -> bool:
        return bool(self.regions or self.out_of_order or self.off_loop)

    def summary(self) -> str:
        """One line: what was skipped and where, or "" when nothing was wrong."""
        parts = []
        if self.regions:
            first = self.regions[0][0]
            parts.append(f"{self.skipped} of {self.size} bytes skipped in {len(self.regions)} "
                         f"damaged place{'s' if len(self.regions) > 1 else ''} (the first at byte "
                         f"{first})")
        if self.out_of_order:
            parts.append(f"{len(self.out_of_order)} timestamp{'s' if len(self.out_of_order) > 1 else ''}"
                         f" going back in time (the first at byte {self.out_of_order[0]})")
        if self.off_loop:
            parts.append(f"{len(self.off_loop)} timestamp{'s' if len(self.off_loop) > 1 else ''}"
                         f" not the time of their control loop (the first at byte "
                         f"{self.off_loop[0]})")
        return "; ".join(parts)

    def record(self) -> dict:
        """For a JSON file: the counts and the first places."""
        return {"bytes": self.size, "messages": self.messages, "skipped_bytes": self.skipped,
                "damaged_regions": len(self.regions), "first_regions": self.regions[:10],
                "stamps_out_of_order": len(self.out_of_order),
                "stamps_not_loop_time": len(self.off_loop)}


class _LoopTimes:
    """The check of a simulated session's stamps: each record's stamp against the offset plus
    the ``time_us`` of the HQ_SYSID_SAMPLE that ends its loop. The offset is the one most
    samples share (the run's start); the verdict counts only when more than half of the
    samples share it, which a log stamped by the host's clock never does. The records before
    a skipped region are not checked (the sample that ended their loop may be what was
    lost), nor those after the last sample."""

    def __init__(self):
        self.pending = []           # (offset, stamp) of the records since the last sample
        self.loops = []             # (offset, stamp, time_us, the loop's other records)

    def sample(self, pos: int, stamp: int, time_us: int) -> None:
        self.loops.append((pos, stamp, time_us, self.pending))
        self.pending = []

    def verdict(self) -> list:
        """Offsets of the records not stamped with their loop's time (and the shared offset)."""
        if not self.loops:
            return []
        shift, count = collections.Counter(s - t for _, s, t, _ in self.loops).most_common(1)[0]
        if 2 * count <= len(self.loops):
            return []
        off = []
        for pos, stamp, time_us, records in self.loops:
            off.extend(p for p, s in records if s != time_us + shift)
            if stamp != time_us + shift:
                off.append(pos)
        return off


def _record_at(data, pos: int, extras: dict):
    """(msgid, packet length, payload length) of a well-formed record at ``pos``, or None."""
    from ..sim.mavframe import STX_V2, packet_at

    start = pos + _STAMP.size
    found = packet_at(data, start, extras) if start < len(data) and data[start] == STX_V2 \
        else None
    return found or None


def _resync(data, pos: int, extras: dict) -> tuple:
    """(offset, record) of the next well-formed record after the damaged ``pos``, or
    (the file's size, None) when none follows."""
    from ..sim.mavframe import STX_V2

    n, stamp_len, p = len(data), _STAMP.size, pos + 1
    while p + stamp_len < n:
        p = data.find(STX_V2, p + stamp_len) - stamp_len
        if p < pos + 1:
            break
        if (found := _record_at(data, p, extras)) is not None:
            return p, found
        p += 1
    return n, None


def read_tlog(path, mav_module, only=None, damage: TlogDamage | None = None):
    """Messages of a .tlog as ``(timestamp_us, message)``, every well-formed record in order.

    ``only``: message type names to decode (default all; the others are still checked).
    ``damage``: a :class:`TlogDamage` to fill; without one, damage is reported as a warning
    naming the file and what was skipped.
    """
    from ..sim.mavframe import HEADER_LEN, Codec

    with open(path, "rb") as fh:
        data = fh.read()
    codec = Codec(mav_module)
    extras = codec.extra_bytes
    names = None if only is None else set(only)
    wanted = None if names is None else {msgid for msgid, cls in codec.classes.items()
                                         if cls.msgname in names}
    report = TlogDamage() if damage is None else damage
    report.size = len(data)
    out, pos, n, last_stamp = [], 0, len(data), None
    stamp_len = _STAMP.size
    loop, sample_id = _LoopTimes(), getattr(mav_module, "MAVLINK_MSG_ID_HQ_SYSID_SAMPLE", None)

    while pos < n:
        found = _record_at(data, pos, extras)
        if found is None:                       # damage: on to the next well-formed record
            start = pos
            pos, found = _resync(data, pos, extras)
            report.regions.append((start, pos - start))
            loop.pending = []
            if found is None:
                break
        msgid, total, length = found
        stamp = _STAMP.unpack_from(data, pos)[0]
        if last_stamp is not None and stamp < last_stamp:
            report.out_of_order.append(pos)
        last_stamp = stamp
        report.messages += 1
        body = pos + stamp_len + HEADER_LEN
        if msgid == sample_id:              # time_us: the payload's first field (may be trimmed)
            loop.sample(pos, stamp, int.from_bytes(data[body:body + min(8, length)], "little"))
        else:
            loop.pending.append((pos, stamp))
        if wanted is None or msgid in wanted:
            out.append((stamp, codec.decode(msgid, data[body:body + length])))
        pos += stamp_len + total
    report.off_loop = loop.verdict()
    if damage is None and report:
        warnings.warn(f"{path}: damaged: {report.summary()}; read the {report.messages} "
                      "well-formed messages")
    return out
