"""Fuzz target: heliquad.host.records.tlog.read_tlog, the .tlog reader.

    python tests/fuzz/tlog_fuzz.py CORPUS_DIR -max_total_time=60     (needs atheris)

Input layout: byte 0 chooses the mode (bit 0: 0 raw, 1 structured); the rest is the file as
it is (raw) or a recipe for ``fuzz_input.StreamBuilder`` (structured), which writes records
of an 8-byte timestamp and a packet with a valid CRC, then damages, cuts and repeats them.

Contract checked per input (the file is written to one temporary file per process):
- ``read_tlog`` never raises; it returns (int timestamp, message) pairs, each message of a
  type of the dialect;
- they are exactly the well-formed records (a whole packet of a known message whose CRC
  verifies, right after its timestamp) found by reading from byte 0 and, where no record
  verifies, stepping one byte at a time to the next offset where one does, decoded from
  those records' payloads;
- the damage it reports is exactly the bytes stepped over (offset and length of each run),
  the records whose timestamp is earlier than the one before and, in a log stamped by its
  control loops (more than half of the HQ_SYSID_SAMPLE records stamped with their own
  time_us plus one and the same offset, the run's start), the records whose stamp is not
  that offset plus the time_us of the first sample after them with no stepped-over run
  between; a warning comes if and only if there is such damage, and no
  other warning;
- reading the file with the damaged runs cut out gives the same list, silently unless a
  timestamp is wrong;
- ``read_tlog_table`` of HQ_SYSID_SAMPLE gives the same samples, field for field, and the
  same damage.
"""

from __future__ import annotations

import atexit
import os
import random
import struct
import sys
import tempfile
import warnings

from fuzz_input import (HEADER_LEN, STAMP_LEN, STX_V2, ByteReader, StreamBuilder, packet_end,
                        same_fields, sample_values, verifies)

from heliquad.host.records import tlog
from heliquad.sim.base import framing as mavframe
from heliquad.sim.base.dialect import dialect
from heliquad.sim.base.framing import Codec

STRUCTURED = 0x01               # mode byte: build the file from the input
DIALECT = dialect()
CODEC = Codec(DIALECT)
BUILDER = StreamBuilder(CODEC)
MESSAGE_TYPES = {cls.msgname for cls in CODEC.classes.values()}
SEED_MESSAGES = ("HEARTBEAT", "ATTITUDE", "STATUSTEXT", "HQ_SYSID_SAMPLE", "HQ_EXCITATION_STATUS",
                 "HQ_FW_STATUS")
_STAMP = struct.Struct(">Q")
# Rewriting a file on a disk costs ten times what the rest of an input does; use RAM if there.
SCRATCH_DIR = "/dev/shm" if os.access("/dev/shm", os.W_OK) else None
_scratch = None


def _scratch_file() -> tuple:
    """(fd, path) of the process's temporary .tlog, made on first use. Where /proc/self/fd
    exists the file is unlinked at once and read through it, so nothing is left behind
    however the process ends (libFuzzer exits without running atexit handlers)."""
    global _scratch
    if _scratch is None:
        fd, path = tempfile.mkstemp(prefix="tlog_fuzz-", suffix=".tlog", dir=SCRATCH_DIR)
        if os.path.exists(f"/proc/self/fd/{fd}"):
            os.remove(path)
            path = f"/proc/self/fd/{fd}"
        else:
            atexit.register(os.remove, path)
        _scratch = fd, path
    return _scratch


def well_formed_records(data: bytes) -> tuple:
    """([(timestamp, msgid, payload)], [(offset, length) stepped over], [offsets of records
    whose timestamp is earlier than the one before], [offsets of records not stamped with
    their loop's time]) by the resynchronising rule, slowly."""
    def record_end(pos):
        start = pos + STAMP_LEN
        if len(data) - start < HEADER_LEN or data[start] != STX_V2:
            return None
        end = packet_end(data, start)
        return end if end <= len(data) and verifies(data, start, BUILDER.extras) else None

    records, skipped, back, pos, last, at, run = [], [], [], 0, None, [], []
    while pos < len(data):
        end = record_end(pos)
        if end is None:
            first = pos
            while pos < len(data) and record_end(pos) is None:
                pos += 1
            skipped.append((first, pos - first))
            continue
        at.append(pos)
        run.append(len(skipped))          # the stepped-over runs before this record
        start = pos + STAMP_LEN
        stamp = _STAMP.unpack_from(data, pos)[0]
        if last is not None and stamp < last:
            back.append(pos)
        last = stamp
        msgid = int.from_bytes(data[start + 7:start + HEADER_LEN], "little")
        records.append((stamp, msgid, data[start + HEADER_LEN:start + HEADER_LEN + data[start + 1]]))
        pos = end
    return records, skipped, back, not_loop_time(records, at, run)


def not_loop_time(records: list, at: list, run: list) -> list:
    """Offsets of the records whose stamp is not their loop's time plus the run's start,
    when the log is stamped by its loops (the start: the offset most samples share); each
    record's loop found by looking ahead for its sample."""
    sample_id = DIALECT.MAVLINK_MSG_ID_HQ_SYSID_SAMPLE
    time_us = [int.from_bytes(p[:8], "little") if m == sample_id else None
               for _, m, p in records]
    samples = [i for i, t in enumerate(time_us) if t is not None]
    shifts = [records[i][0] - time_us[i] for i in samples]
    start = max(set(shifts), key=shifts.count) if shifts else 0
    if 2 * shifts.count(start) <= len(samples):
        return []
    off = []
    for i, (stamp, _, _) in enumerate(records):
        ends = next((j for j in samples if j >= i), None)
        if ends is not None and run[ends] == run[i] and stamp != start + time_us[ends]:
            off.append(at[i])
    return off


def read(data: bytes) -> tuple:
    """(read_tlog's list, the warnings it gave, the damage it reported when asked) for a
    file holding ``data``."""
    fd, path = _scratch_file()
    os.ftruncate(fd, 0)
    os.pwrite(fd, data, 0)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        messages = tlog.read_tlog(path, DIALECT)
    damage = tlog.TlogDamage()
    again = tlog.read_tlog(path, DIALECT, damage=damage)
    assert _same_messages(again, messages)
    _check_table(path, messages, damage)
    return messages, [str(w.message) for w in caught], damage


def _check_table(path, messages: list, damage) -> None:
    """read_tlog_table's HQ_SYSID_SAMPLE records: read_tlog's, and its damage."""
    table_damage = tlog.TlogDamage()
    table = tlog.read_tlog_table(path, DIALECT, "HQ_SYSID_SAMPLE", damage=table_damage)
    assert table_damage == damage
    samples = [m for _, m in messages if m.get_type() == "HQ_SYSID_SAMPLE"]
    assert len(table) == len(samples)
    for row, m in zip(table, samples):
        assert same_fields({name: row[name].tolist() for name in table.dtype.names}, vars(m))


def _same_messages(got: list, want: list) -> bool:
    return len(got) == len(want) and all(
        t1 == t2 and m1.get_type() == m2.get_type() and same_fields(vars(m1), vars(m2))
        for (t1, m1), (t2, m2) in zip(got, want))


def tlog_bytes(data: bytes) -> bytes:
    """The file an input stands for."""
    reader = ByteReader(data)
    if reader.byte() & STRUCTURED:
        return BUILDER.stream(reader, stamped=True)
    return reader.rest()


def check(data: bytes) -> list:
    """Run the contract on one input; read_tlog's list."""
    content = tlog_bytes(data)
    messages, caught, damage = read(content)
    assert isinstance(messages, list)
    for item in messages:
        assert isinstance(item, tuple) and len(item) == 2 and type(item[0]) is int
        assert item[1].get_type() in MESSAGE_TYPES

    records, skipped, back, off = well_formed_records(content)
    want = [(stamp, CODEC.decode(msgid, payload)) for stamp, msgid, payload in records]
    assert _same_messages(messages, want), f"{len(messages)} read, {len(want)} well-formed"
    assert damage.regions == skipped and damage.out_of_order == back and damage.off_loop == off
    assert damage.messages == len(records) and damage.size == len(content)
    if skipped or back or off:
        assert len(caught) == 1 and damage.summary() in caught[0], caught
        cut, pos = bytearray(), 0
        for first, length in skipped:
            cut += content[pos:first]
            pos = first + length
        cut += content[pos:]
        clean, caught, again = read(bytes(cut))
        assert _same_messages(clean, messages) and not again.regions
        # Cut out, a damaged run no longer hides which loop the records before it were in.
        assert not caught or again.out_of_order or again.off_loop, caught
    else:
        assert not caught, caught
    return messages


def test_one_input(data: bytes) -> None:
    check(data)


def seed_inputs() -> dict:
    """Seed corpus: valid logs of several message types (raw) and a few structured recipes."""
    rng = random.Random(0)
    by_name = {cls.msgname: msgid for msgid, cls in CODEC.classes.items()}
    records = [_STAMP.pack(1_000_000 + 5_000 * i) + CODEC.encode(
        by_name[name], sample_values(CODEC.classes[by_name[name]], rng))
        for i, name in enumerate(SEED_MESSAGES * 2)]
    seeds = {f"raw-{name.lower()}": b"\0" + r for name, r in zip(SEED_MESSAGES, records)}
    seeds["raw-log"] = b"\0" + b"".join(records)
    seeds["raw-log-cut"] = b"\0" + b"".join(records)[:-5]
    seeds["raw-loop-stamped"] = b"\0" + loop_stamped_log(rng)
    for i in range(4):
        seeds[f"structured-{i}"] = bytes((STRUCTURED,)) + rng.randbytes(400)
    return seeds


def loop_stamped_log(rng, loops: int = 6) -> bytes:
    """A simulated session's log: each loop's messages, then its HQ_SYSID_SAMPLE, all stamped
    with the sample's time_us; one record's stamp is one bit off."""
    by_name = {cls.msgname: msgid for msgid, cls in CODEC.classes.items()}
    out = []
    for k in range(loops):
        time_us = 5_000 * (k + 1)
        for name in ("HEARTBEAT", "STATUSTEXT", "HQ_SYSID_SAMPLE")[k % 2:]:
            values = sample_values(CODEC.classes[by_name[name]], rng)
            if name == "HQ_SYSID_SAMPLE":
                values["time_us"] = time_us
            out.append(_STAMP.pack(time_us ^ (len(out) == 4)) + CODEC.encode(by_name[name], values))
    return b"".join(out)


def main(argv: list) -> None:
    import atheris
    from fuzz_input import instrument
    instrument(atheris, (tlog, mavframe))
    atheris.Setup(argv, test_one_input)
    atheris.Fuzz()


if __name__ == "__main__":
    main(sys.argv)
