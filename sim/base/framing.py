"""Fast MAVLink 2 framing and coding for the high-rate links (sim link, telemetry).

pymavlink's generated parser decodes every message in pure Python, about 40 us each; at
200 Hz with several messages per loop that made the host side, not the firmware or the link,
the bottleneck of the SIL. This module frames packets by their header, checks the CRC with
fastcrc's C implementation of CRC-16/MCRF4XX (the MAVLink X.25 CRC, which pymavlink uses
too), and decodes a message only when asked. Every format comes from the generated dialect
module's metadata (field order, struct format, CRC extra), so firmware/mavlink/heliquad.xml
stays the one definition.
"""

from __future__ import annotations

import struct

from fastcrc import crc16

__all__ = ["Framer", "Codec", "Message"]

STX_V2 = 0xFD
HEADER_LEN = 10                 # STX, len, incompat, compat, seq, sysid, compid, msgid x3
CRC_LEN = 2
SIGNATURE_LEN = 13
INCOMPAT_SIGNED = 0x01
_mcrf4xx = crc16.mcrf4xx


class Message:
    """A decoded message: its fields as attributes, pymavlink-style ``get_type()``."""

    __slots__ = ("_type", "__dict__")

    def __init__(self, msg_type: str, fields: dict):
        self._type = msg_type
        self.__dict__.update(fields)

    def get_type(self) -> str:
        return self._type

    def __repr__(self) -> str:
        return f"{self._type}({self.__dict__})"


class Codec:
    """Encoder and decoder for one generated dialect module. Packets it encodes come from
    ``system_id`` and ``component_id`` (default: a ground station's, MAV_COMP_ID_MISSIONPLANNER
    of system 255)."""

    def __init__(self, mav_module, system_id: int = 255, component_id: int | None = None):
        if component_id is None:
            component_id = mav_module.MAV_COMP_ID_MISSIONPLANNER
        self.classes = dict(mav_module.mavlink_map)
        self.extras = {msgid: cls.crc_extra for msgid, cls in self.classes.items()}
        self.extra_bytes = {msgid: bytes((extra,)) for msgid, extra in self.extras.items()}
        self.system_id, self.component_id = system_id, component_id
        self.seq = 0
        self._plans = {}
        self._decoders = {}

    def _plan(self, msgid: int):
        """(class, [(field name, 'char' | 'array' | 'scalar', length)]) in wire order."""
        plan = self._plans.get(msgid)
        if plan is None:
            cls = self.classes[msgid]
            fields = []
            for name, n in zip(cls.ordered_fieldnames, cls.array_lengths):
                ftype = cls.fieldtypes[cls.fieldnames.index(name)]
                fields.append((name, "char" if ftype == "char" else "array" if n else "scalar", n))
            plan = self._plans[msgid] = (cls, fields)
        return plan

    def crc_extra(self, msgid: int):
        return self.extras.get(msgid)

    def encode(self, msgid: int, values: dict) -> bytes:
        """One MAVLink 2 packet; ``values`` by field name (arrays as sequences)."""
        cls, fields = self._plan(msgid)
        flat = []
        for name, kind, _ in fields:
            v = values[name]
            if kind == "array":
                flat.extend(v)
            else:
                flat.append(v.encode() if isinstance(v, str) else v)
        payload = cls.unpacker.pack(*flat).rstrip(b"\0") or b"\0"   # MAVLink 2 truncation
        header = bytes((STX_V2, len(payload), 0, 0, self.seq & 0xFF, self.system_id,
                        self.component_id, msgid & 0xFF, (msgid >> 8) & 0xFF, msgid >> 16))
        self.seq += 1
        crc = _mcrf4xx(header[1:] + payload + bytes((cls.crc_extra,)))
        return header + payload + struct.pack("<H", crc)

    def decode(self, msgid: int, payload) -> Message | None:
        """The message in ``payload`` (zero-extended to its full length), or None if unknown."""
        decoder = self._decoders.get(msgid)
        if decoder is None:
            if msgid not in self.classes:
                return None
            decoder = self._decoders[msgid] = self._decoder(msgid)
        return decoder(payload)

    def _decoder(self, msgid: int):
        """A function decoding one message type (its layout worked out once)."""
        cls, plan = self._plan(msgid)
        unpack, size, name = cls.unpacker.unpack, cls.unpacker.size, cls.msgname
        layout, i = [], 0                      # (field, first value, last value or None)
        for field, kind, n in plan:
            layout.append((field, kind, i, i + n if kind == "array" else None))
            i += n if kind == "array" else 1
        simple = all(kind == "scalar" for _, kind, _, _ in layout)
        names = tuple(field for field, _, _, _ in layout)

        def decode(payload):
            data = bytes(payload)
            values = unpack(data if len(data) == size else data[:size].ljust(size, b"\0"))
            if simple:
                return Message(name, dict(zip(names, values)))
            fields = {}
            for field, kind, first, last in layout:
                if kind == "scalar":
                    fields[field] = values[first]
                elif kind == "array":
                    fields[field] = list(values[first:last])
                else:
                    fields[field] = values[first].split(b"\0", 1)[0].decode(errors="replace")
            return Message(name, fields)

        return decode


def packet_at(buf, start: int, extras: dict):
    """The whole MAVLink 2 packet whose STX is at ``buf[start]``: ``(msgid, total length,
    payload length)`` when it is all there, of a known message, and its CRC verifies;
    ``None`` when it is not a packet; ``0`` when its header or body is cut off by the end
    of ``buf`` (more bytes may complete it)."""
    n = len(buf)
    if n - start < HEADER_LEN:
        return 0
    length = buf[start + 1]
    total = HEADER_LEN + length + CRC_LEN
    if buf[start + 2] & INCOMPAT_SIGNED:
        total += SIGNATURE_LEN
    if n - start < total:
        return 0
    msgid = buf[start + 7] | (buf[start + 8] << 8) | (buf[start + 9] << 16)
    extra = extras.get(msgid)
    end_payload = start + HEADER_LEN + length
    if extra is None or _mcrf4xx(extra, initial=_mcrf4xx(buf[start + 1:end_payload])) != (
            buf[end_payload] | (buf[end_payload + 1] << 8)):
        return None
    return msgid, total, length


class Framer:
    """Splits a byte stream into whole, CRC-checked MAVLink 2 packets.

    Garbage and packets of unknown messages are skipped byte by byte until the next valid
    start, so the stream resynchronises after damage. ``feed`` returns
    ``(msgid, packet, payload)`` tuples; ``packet`` is the raw bytes for a .tlog.
    """

    def __init__(self, codec: Codec):
        self.codec = codec
        self.buf = bytearray()
        self.skipped = 0

    def feed(self, data: bytes) -> list:
        buf = self.buf
        buf += data
        out = []
        pos = 0
        n = len(buf)
        extras = self.codec.extra_bytes
        view = memoryview(buf)
        while True:
            start = buf.find(STX_V2, pos)
            if start < 0:
                self.skipped += n - pos
                pos = n
                break
            self.skipped += start - pos
            found = packet_at(view, start, extras)
            if found == 0:                                        # cut off: wait for more
                pos = start
                break
            if found is None:
                self.skipped += 1
                pos = start + 1                                   # not a packet: resync
                continue
            msgid, total, length = found
            packet = bytes(view[start:start + total])
            out.append((msgid, packet, packet[HEADER_LEN:HEADER_LEN + length]))
            pos = start + total
        view.release()                     # a bytearray with a live view cannot shrink
        del buf[:pos]
        return out
