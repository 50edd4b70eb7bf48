"""Fuzz target: heliquad.sim.base.framing's Framer and Codec (the sim and telemetry links).

    python tests/fuzz/framer_fuzz.py CORPUS_DIR -max_total_time=60     (needs atheris)

Input layout: byte 0 chooses the mode (bit 0: 0 raw, 1 structured); then the chunking
recipe, CUT_RECIPE_LEN bytes (see ``fuzz_input.split_at``); then the byte stream itself,
taken as it is (raw) or built from the remaining bytes by ``fuzz_input.StreamBuilder``
(structured), which makes packets with valid CRCs so the decoders are reached.

Contract checked per input:
- ``Framer.feed`` never raises and returns exactly the packets of ``reference_frames``, the
  framing rule written out slowly, keeping the same unread tail;
- feeding the stream in chunks gives the same packets and tail as one feed;
- every packet's header, length and CRC (with the dialect's crc_extra) check out and
  ``Codec.decode`` gives a message of that id's type; it returns None for unknown ids and
  never raises, whatever the payload length;
- ``Codec.encode`` of a decoded message frames back to the same fields (NaN equal to NaN);
  its payload carries no trailing zeros. Text that was not UTF-8 decodes with replacement
  characters and cannot come back byte for byte, so such text is not compared.
"""

from __future__ import annotations

import random
import sys

from fuzz_input import (CRC_LEN, CUT_RECIPE_LEN, HEADER_LEN, INCOMPAT_SIGNED, SIGNATURE_LEN,
                        STX_V2, ByteReader, StreamBuilder, reference_frames, same_fields,
                        sample_values, split_at, x25)

from heliquad.sim.base import framing as mavframe
from heliquad.sim.base.dialect import dialect
from heliquad.sim.base.framing import Codec, Framer

STRUCTURED = 0x01               # mode byte: build the stream from the input
MAX_PAYLOAD = 255
CODEC = Codec(dialect())
BUILDER = StreamBuilder(CODEC)
SEED_MESSAGES = ("HEARTBEAT", "ATTITUDE", "STATUSTEXT", "PARAM_VALUE", "HQ_SENSOR_FRAME",
                 "HQ_ACTUATOR_FRAME", "HQ_SYSID_SAMPLE", "HQ_EXCITATION_STATUS", "HQ_FW_STATUS")
REPLACEMENT_CHAR = "\ufffd"


def _check_packet(msgid: int, packet: bytes, payload: bytes) -> None:
    """One framed packet: its header, length and CRC, its decoding, and a round trip."""
    length = packet[1]
    signature = SIGNATURE_LEN if packet[2] & INCOMPAT_SIGNED else 0
    assert packet[0] == STX_V2 and len(packet) == HEADER_LEN + length + CRC_LEN + signature
    assert int.from_bytes(packet[7:HEADER_LEN], "little") == msgid
    assert payload == packet[HEADER_LEN:HEADER_LEN + length]
    crc = int.from_bytes(packet[HEADER_LEN + length:HEADER_LEN + length + CRC_LEN], "little")
    assert x25(packet[1:HEADER_LEN + length] + bytes((CODEC.crc_extra(msgid),))) == crc
    msg = CODEC.decode(msgid, payload)
    assert msg.get_type() == CODEC.classes[msgid].msgname
    _check_round_trip(msgid, msg)


def _check_round_trip(msgid: int, msg) -> None:
    again = CODEC.encode(msgid, vars(msg))
    framed = Framer(CODEC).feed(again)
    assert len(framed) == 1 and framed[0][:2] == (msgid, again)
    payload = framed[0][2]
    assert payload == (payload.rstrip(b"\0") or b"\0"), "payload not truncated"
    lossy = [name for name, v in vars(msg).items() if isinstance(v, str) and REPLACEMENT_CHAR in v]
    assert same_fields(vars(CODEC.decode(msgid, payload)), vars(msg), skip=lossy)


def _check_direct_decode(stream: bytes) -> None:
    """Codec.decode of a payload that never passed a CRC: any id, any length."""
    reader = ByteReader(stream)
    msgid = BUILDER.ids[reader.uint(2) % len(BUILDER.ids)]
    msg = CODEC.decode(msgid, reader.take(reader.byte()))
    assert msg.get_type() == CODEC.classes[msgid].msgname
    unknown = reader.uint(3)
    assert unknown in CODEC.classes or CODEC.decode(unknown, stream[:MAX_PAYLOAD]) is None


def check(data: bytes) -> list:
    """Run the contract on one input; the framed packets."""
    reader = ByteReader(data)
    structured = reader.byte() & STRUCTURED
    cut_recipe = reader.take(CUT_RECIPE_LEN)
    stream = BUILDER.stream(reader) if structured else reader.rest()

    whole = Framer(CODEC)
    packets = whole.feed(stream)
    expected, tail = reference_frames(stream, BUILDER.extras)
    assert [packet for _, packet, _ in packets] == expected
    assert bytes(whole.buf) == tail

    chunked = Framer(CODEC)
    pieces = []
    for chunk in split_at(stream, cut_recipe):
        pieces += chunked.feed(chunk)
    assert pieces == packets and chunked.buf == whole.buf

    for msgid, packet, payload in packets:
        _check_packet(msgid, packet, payload)
    if not structured:
        _check_direct_decode(stream)
    return packets


def test_one_input(data: bytes) -> None:
    check(data)


def seed_inputs() -> dict:
    """Seed corpus: raw streams of valid packets of several message types, and a few
    structured recipes."""
    rng = random.Random(0)
    by_name = {cls.msgname: msgid for msgid, cls in CODEC.classes.items()}
    packets = [CODEC.encode(by_name[name], sample_values(CODEC.classes[by_name[name]], rng))
               for name in SEED_MESSAGES]
    one_feed = bytes(1 + CUT_RECIPE_LEN)
    in_quarters = bytes((0, 3, 0, 0x40, 0, 0x80, 0, 0xC0)).ljust(1 + CUT_RECIPE_LEN, b"\0")
    seeds = {f"raw-{name.lower()}": one_feed + p for name, p in zip(SEED_MESSAGES, packets)}
    seeds["raw-all"] = one_feed + b"".join(packets)
    seeds["raw-all-in-quarters"] = in_quarters + b"".join(packets)
    for i in range(4):
        seeds[f"structured-{i}"] = bytes((STRUCTURED,)) + rng.randbytes(CUT_RECIPE_LEN + 400)
    return seeds


def main(argv: list) -> None:
    import atheris
    from fuzz_input import instrument
    instrument(atheris, (mavframe,))
    atheris.Setup(argv, test_one_input)
    atheris.Fuzz()


if __name__ == "__main__":
    main(sys.argv)
