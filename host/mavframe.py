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
    """Encoder and decoder for one generated dialect module."""

    def __init__(self, mav_module, system_id: int = 255, component_id: int = 190):
        self.classes = dict(mav_module.mavlink_map)
        self.extras = {msgid: cls.crc_extra for msgid, cls in self.classes.items()}
        self.system_id, self.component_id = system_id, component_id
        self.seq = 0
        self._plans = {}

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
        if msgid not in self.classes:
            return None
        cls, plan = self._plan(msgid)
        size = cls.unpacker.size
        data = bytes(payload[:size]).ljust(size, b"\0")
        values = cls.unpacker.unpack(data)
        fields = {}
        i = 0
        for name, kind, n in plan:
            if kind == "scalar":
                fields[name] = values[i]
                i += 1
            elif kind == "array":
                fields[name] = list(values[i:i + n])
                i += n
            else:
                fields[name] = values[i].split(b"\0", 1)[0].decode(errors="replace")
                i += 1
        return Message(cls.msgname, fields)


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
        while True:
            start = buf.find(STX_V2, pos)
            if start < 0:
                self.skipped += n - pos
                pos = n
                break
            self.skipped += start - pos
            if n - start < HEADER_LEN:
                pos = start
                break
            length = buf[start + 1]
            total = HEADER_LEN + length + CRC_LEN
            if buf[start + 2] & INCOMPAT_SIGNED:
                total += SIGNATURE_LEN
            if n - start < total:
                pos = start
                break
            msgid = buf[start + 7] | (buf[start + 8] << 8) | (buf[start + 9] << 16)
            extra = self.codec.extras.get(msgid)
            end_payload = start + HEADER_LEN + length
            if extra is None or _mcrf4xx(bytes(buf[start + 1:end_payload]) + bytes((extra,))) != (
                    buf[end_payload] | (buf[end_payload + 1] << 8)):
                self.skipped += 1
                pos = start + 1                                   # not a packet: resync
                continue
            packet = bytes(buf[start:start + total])
            out.append((msgid, packet, packet[HEADER_LEN:HEADER_LEN + length]))
            pos = start + total
        del buf[:pos]
        return out
