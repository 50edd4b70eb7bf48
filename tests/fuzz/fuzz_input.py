"""Structure-aware input for the host fuzz targets (tests/fuzz/*_fuzz.py).

Random bytes almost never pass a MAVLink CRC, so a fuzzer feeding them straight to a parser
exercises little more than its resynchronisation. The harnesses can instead read the fuzz
input as a recipe: ``ByteReader`` hands out its bytes as small integers and slices (zeros
once it runs dry, so every input is a valid recipe) and ``StreamBuilder`` turns them into
MAVLink 2 packets, with correct CRCs or deliberately wrong ones, for any message of the
dialect or an unknown one, with any payload length, and then damages, truncates and repeats
them. ``reference_frames`` is the framing rule written out slowly, as an oracle.

The wire constants and the CRC below come from the MAVLink 2 serialisation spec, not from
sim/base/framing.py, so the oracle does not share the parser's mistakes. Nothing here needs
atheris; ``instrument`` is handed the atheris module by a harness's entry point.
"""

from __future__ import annotations

import math
import random
import types

__all__ = ["ByteReader", "StreamBuilder", "x25", "packet_end", "verifies", "reference_frames",
           "split_at", "same_fields", "sample_values", "instrument"]

STX_V2 = 0xFD
HEADER_LEN = 10                 # STX, len, incompat, compat, seq, sysid, compid, msgid x3
CRC_LEN = 2
SIGNATURE_LEN = 13
INCOMPAT_SIGNED = 0x01
STAMP_LEN = 8                   # a .tlog record's big-endian timestamp, us

_X25_POLY = 0x8408              # CRC-16/MCRF4XX: reflected 0x1021, initial 0xFFFF, no xorout
_X25_INIT = 0xFFFF


def _x25_table() -> tuple:
    table = []
    for byte in range(256):
        crc = byte
        for _ in range(8):
            crc = (crc >> 1) ^ _X25_POLY if crc & 1 else crc >> 1
        table.append(crc)
    return tuple(table)


_X25_TABLE = _x25_table()


def x25(data) -> int:
    """The MAVLink checksum (CRC-16/MCRF4XX) of ``data``, in plain Python."""
    crc = _X25_INIT
    for byte in data:
        crc = (crc >> 8) ^ _X25_TABLE[(crc ^ byte) & 0xFF]
    return crc


class ByteReader:
    """The fuzz input as a recipe: bytes handed out in order, zeros once it runs dry."""

    def __init__(self, data: bytes):
        self._data = bytes(data)
        self._pos = 0

    def remaining(self) -> int:
        return len(self._data) - self._pos

    def take(self, n: int) -> bytes:
        """The next ``n`` bytes, zero-padded past the end of the input."""
        chunk = self._data[self._pos:self._pos + n]
        self._pos += len(chunk)
        return chunk.ljust(n, b"\0")

    def uint(self, n: int) -> int:
        """The next ``n`` bytes as a little-endian unsigned integer."""
        return int.from_bytes(self.take(n), "little")

    def byte(self) -> int:
        return self.uint(1)

    def rest(self) -> bytes:
        """Everything not read yet (no padding)."""
        chunk = self._data[self._pos:]
        self._pos = len(self._data)
        return chunk


# A packet recipe starts with one flags byte.
UNKNOWN_ID = 0x03               # both bits: a 24-bit id from the input (1 in 4 packets)
ANY_LENGTH = 0x04               # payload length 0..255 from the input, else the message's own
TRUNCATE_ZEROS = 0x08           # drop trailing zero bytes as a MAVLink 2 sender does
BAD_CRC = 0x30                  # both bits: a checksum that does not verify (1 in 4)
SIGNED = 0x40                   # the signed flag and a 13-byte signature
RAW_FLAGS = 0x80                # incompat and compat flags from the input

# A stream recipe is a series of operations, one byte each, then their arguments.
OP_PACKETS = 3                  # ops 0..2: a packet (a .tlog record when stamped)
OP_RAW = 3                      # 1..MAX_RAW raw bytes
OP_CUT = 4                      # a packet cut short
OP_FLIP = 5                     # one byte of the stream so far changed
OP_REPEAT = 6                   # the last segment again
N_OPS = 7
MAX_SEGMENTS = 32
MAX_RAW = 64


class StreamBuilder:
    """MAVLink 2 packets and byte streams of them, made from a ``ByteReader``'s bytes."""

    def __init__(self, codec):
        self.ids = sorted(codec.classes)
        self.extras = {msgid: cls.crc_extra for msgid, cls in codec.classes.items()}
        self.sizes = {msgid: cls.unpacker.size for msgid, cls in codec.classes.items()}

    def packet(self, reader: ByteReader) -> bytes:
        """One packet as the recipe says; see the flag constants."""
        flags = reader.byte()
        if flags & UNKNOWN_ID == UNKNOWN_ID:
            msgid = reader.uint(3)
            extra = self.extras.get(msgid, reader.byte())
        else:
            msgid = self.ids[reader.uint(2) % len(self.ids)]
            extra = self.extras[msgid]
        length = reader.byte() if flags & ANY_LENGTH or msgid not in self.sizes else (
            self.sizes[msgid])
        payload = reader.take(length)
        if flags & TRUNCATE_ZEROS:
            payload = payload.rstrip(b"\0") or payload[:1]
        incompat, compat = (reader.byte(), reader.byte()) if flags & RAW_FLAGS else (
            INCOMPAT_SIGNED if flags & SIGNED else 0, 0)
        header = bytes((STX_V2, len(payload), incompat, compat)) + reader.take(3) + (
            msgid.to_bytes(3, "little"))
        crc = x25(header[1:] + payload + bytes((extra,)))
        if flags & BAD_CRC == BAD_CRC:
            crc ^= reader.uint(2) or 1
        packet = header + payload + crc.to_bytes(CRC_LEN, "little")
        if incompat & INCOMPAT_SIGNED:
            packet += reader.take(SIGNATURE_LEN)
        return packet

    def stream(self, reader: ByteReader, stamped: bool = False) -> bytes:
        """Packets, raw bytes, cut packets, flipped bytes and repeats, up to MAX_SEGMENTS.

        ``stamped``: each packet is a .tlog record, led by an 8-byte timestamp.
        """
        out, last = bytearray(), b""
        for _ in range(MAX_SEGMENTS):
            if not reader.remaining():
                break
            op = reader.byte() % N_OPS
            if op < OP_PACKETS or op == OP_CUT:
                last = (reader.take(STAMP_LEN) if stamped else b"") + self.packet(reader)
                if op == OP_CUT:
                    last = last[:reader.byte() % len(last)]
            elif op == OP_RAW:
                last = reader.take(reader.byte() % MAX_RAW + 1)
            elif op == OP_FLIP:
                if out:
                    out[reader.uint(2) % len(out)] ^= reader.byte() or 0xFF
                continue
            out += last                                          # OP_REPEAT adds it again
        return bytes(out)


def packet_end(data: bytes, start: int) -> int:
    """Where the packet whose STX is at ``start`` ends, by its header (maybe past the data);
    ``data`` must hold the header."""
    signature = SIGNATURE_LEN if data[start + 2] & INCOMPAT_SIGNED else 0
    return start + HEADER_LEN + data[start + 1] + CRC_LEN + signature


def verifies(data: bytes, start: int, extras: dict) -> bool:
    """The whole packet at ``start`` is of a known message and its CRC verifies."""
    msgid = int.from_bytes(data[start + 7:start + HEADER_LEN], "little")
    end_payload = start + HEADER_LEN + data[start + 1]
    crc = int.from_bytes(data[end_payload:end_payload + CRC_LEN], "little")
    return msgid in extras and x25(data[start + 1:end_payload] + bytes((extras[msgid],))) == crc


def reference_frames(stream: bytes, extras: dict) -> tuple:
    """(packets, unread tail) by the framing rule, slowly: from each STX, a whole packet of a
    known message whose CRC verifies is taken and skipped; an STX whose packet is not all
    there yet stops the scan (more bytes may complete it); anything else is skipped a byte
    at a time.
    """
    packets, pos = [], 0
    while True:
        start = stream.find(STX_V2, pos)
        if start < 0:
            return packets, b""
        if len(stream) - start < HEADER_LEN or packet_end(stream, start) > len(stream):
            return packets, stream[start:]
        if verifies(stream, start, extras):
            pos = packet_end(stream, start)
            packets.append(stream[start:pos])
        else:
            pos = start + 1


MAX_CUTS = 15
CUT_RECIPE_LEN = 1 + 2 * MAX_CUTS   # the number of cuts, then 16 bits per cut


def split_at(stream: bytes, recipe: bytes) -> list:
    """``stream`` in chunks as ``recipe`` (CUT_RECIPE_LEN bytes) says: its first byte gives
    the number of cuts, then each cut is a 16-bit fraction of the length (empty chunks
    allowed)."""
    reader = ByteReader(recipe)
    n_cuts = reader.byte() % (MAX_CUTS + 1)
    cuts = sorted(reader.uint(2) * (len(stream) + 1) >> 16 for _ in range(n_cuts))
    edges = [0, *cuts, len(stream)]
    return [stream[a:b] for a, b in zip(edges, edges[1:])]


def _same(a, b) -> bool:
    if isinstance(a, float) and isinstance(b, float):
        return a == b or (math.isnan(a) and math.isnan(b))
    if isinstance(a, list) and isinstance(b, list):
        return len(a) == len(b) and all(map(_same, a, b))
    return type(a) is type(b) and a == b


def same_fields(a: dict, b: dict, skip=()) -> bool:
    """Equal decoded fields, NaN equal to NaN; fields named in ``skip`` are not compared."""
    return a.keys() == b.keys() and all(_same(a[k], b[k]) for k in a if k not in skip)


_INT_RANGES = {f"{sign}int{bits}_t": ((0, 2 ** bits - 1) if sign else
                                       (-2 ** (bits - 1), 2 ** (bits - 1) - 1))
               for sign in ("", "u") for bits in (8, 16, 32, 64)}
_TEXT = "abcxyz_ABC019 .-"


def _value(ftype: str, rng: random.Random):
    if ftype in ("float", "double"):
        return rng.uniform(-1e3, 1e3)
    return rng.randint(*_INT_RANGES[ftype])


def sample_values(cls, rng: random.Random) -> dict:
    """Plausible values for every field of a generated message class, for Codec.encode."""
    values = {}
    for name, n in zip(cls.ordered_fieldnames, cls.array_lengths):
        ftype = cls.fieldtypes[cls.fieldnames.index(name)]
        if ftype == "char":
            values[name] = "".join(rng.choice(_TEXT) for _ in range(rng.randint(0, max(n, 1))))
        elif n:
            values[name] = [_value(ftype, rng) for _ in range(n)]
        else:
            values[name] = _value(ftype, rng)
    return values


def instrument(atheris, modules) -> int:
    """Give atheris coverage feedback from every function and method defined in ``modules``.

    ``atheris.instrument_imports`` cannot see through the editable install's import hook
    (scikit-build-core's redirecting loader: the modules load uninstrumented, silently), and
    ``atheris.instrument_all`` would also instrument pymavlink's generated dialect and the
    harness, so coverage would mostly measure the recipe reader. Returns the count.
    """
    count = 0
    for module in modules:
        for obj in vars(module).values():
            for member in vars(obj).values() if isinstance(obj, type) else (obj,):
                func = getattr(member, "__func__", member)           # static and class methods
                if isinstance(func, types.FunctionType) and func.__module__ == module.__name__:
                    atheris.instrument_func(func)
                    count += 1
    return count
