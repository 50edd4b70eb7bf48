"""The host fuzz harnesses (tests/fuzz) without atheris: their seed corpora and a few thousand
deterministic pseudo-random inputs, so a broken harness or a parser regression fails the
normal test suite; and regression tests for what fuzzing found."""

import random
import struct
import sys
import warnings
from pathlib import Path

import pytest
from fastcrc import crc16

sys.path.insert(0, str(Path(__file__).resolve().parent / "fuzz"))

import dataflash_fuzz  # noqa: E402
import framer_fuzz  # noqa: E402
import fuzz_input  # noqa: E402
import tlog_fuzz  # noqa: E402

from ardupilot_dataflash import DataFlashWriter
from heliquad.host.records import tlog
from heliquad.sim.base.errors import InputError
from heliquad.sim.base import framing as mavframe  # noqa: E402

HARNESSES = {"tlog": tlog_fuzz, "framer": framer_fuzz}
RANDOM_INPUTS = 1500                    # per harness and kind (raw, structured, mutated seed)
MAX_RANDOM_LEN = 600
MUTATIONS = 4


def mutate(data: bytes, rng: random.Random) -> bytes:
    """A few byte changes, insertions and deletions after the mode byte, as a fuzzer makes."""
    out = bytearray(data)
    for _ in range(rng.randint(1, MUTATIONS)):
        pos = rng.randrange(1, len(out) + 1)
        kind = rng.randrange(3)
        if kind == 0 and pos < len(out):
            out[pos] = rng.randrange(256)
        elif kind == 1:
            out[pos:pos] = rng.randbytes(rng.randint(1, 16))
        else:
            del out[pos:pos + rng.randint(1, 16)]
    return bytes(out)


def pseudo_random_inputs(harness, seed: int):
    """Raw and structured random inputs and mutated seeds, RANDOM_INPUTS of each."""
    rng = random.Random(seed)
    seeds = list(harness.seed_inputs().values())
    for _ in range(RANDOM_INPUTS):
        yield bytes((0,)) + rng.randbytes(rng.randrange(MAX_RANDOM_LEN))
        yield bytes((harness.STRUCTURED,)) + rng.randbytes(rng.randrange(MAX_RANDOM_LEN))
        yield mutate(rng.choice(seeds), rng)


def test_the_oracle_checksum_is_mavlinks():
    assert fuzz_input.x25(b"123456789") == 0x6F91              # CRC-16/MCRF4XX check value
    rng = random.Random(1)
    for n in (0, 1, 9, 255, 300):
        data = rng.randbytes(n)
        assert fuzz_input.x25(data) == crc16.mcrf4xx(data)


@pytest.mark.parametrize("name", HARNESSES)
def test_seed_inputs_pass_and_are_valid_logs_and_streams(name):
    harness = HARNESSES[name]
    seeds = harness.seed_inputs()
    read = {label: len(harness.check(data)) for label, data in seeds.items()}
    n = len(harness.SEED_MESSAGES)
    whole = {"raw-log": 2 * n, "raw-log-cut": 2 * n - 1} if name == "tlog" else {
        "raw-all": n, "raw-all-in-quarters": n}
    assert read["raw-heartbeat"] == 1 and {label: read[label] for label in whole} == whole


@pytest.mark.parametrize("name", HARNESSES)
def test_pseudo_random_inputs_pass(name):
    harness = HARNESSES[name]
    read = sum(len(harness.check(data)) for data in pseudo_random_inputs(harness, seed=7))
    assert read > RANDOM_INPUTS                  # the mutated seeds and recipes do get through


def test_structured_streams_reach_many_decoders_and_odd_lengths():
    rng = random.Random(3)
    ids, odd_lengths, signed = set(), set(), 0
    for _ in range(400):
        data = bytes((framer_fuzz.STRUCTURED,)) + rng.randbytes(rng.randrange(MAX_RANDOM_LEN))
        for msgid, packet, payload in framer_fuzz.check(data):
            ids.add(msgid)
            size = framer_fuzz.BUILDER.sizes[msgid]
            odd_lengths.add((len(payload) > size) - (len(payload) < size))
            signed += packet[2] & fuzz_input.INCOMPAT_SIGNED
    assert len(ids) > 50 and odd_lengths == {-1, 0, 1} and signed > 0


def test_the_framer_harness_catches_a_framer_that_loses_a_packet(monkeypatch):
    feed = mavframe.Framer.feed
    monkeypatch.setattr(mavframe.Framer, "feed", lambda self, data: feed(self, data)[:-1])
    with pytest.raises(AssertionError):
        framer_fuzz.check(framer_fuzz.seed_inputs()["raw-all"])


def test_long_damaged_loop_stamped_logs_read_as_the_slow_rule_reads_them():
    # The reader chains records by their headers and checks them in runs of hundreds to tens
    # of thousands at a time; a damaged place starts a short run again. Logs long enough for
    # several runs, damaged near the ends of runs and in stamps, against the byte-by-byte rule.
    rng = random.Random(11)
    log = tlog_fuzz.loop_stamped_log(rng, loops=1500)
    for trial in range(6):
        data = bytearray(log)
        for _ in range(rng.choice((1, 3, 12))):
            at = rng.randrange(len(data))
            kind = rng.randrange(3)
            if kind == 0:
                data[at] ^= 1 << rng.randrange(8)
            elif kind == 1:
                del data[at:at + rng.randint(1, 40)]
            else:
                data[at:at] = rng.randbytes(rng.randint(1, 40))
        assert len(tlog_fuzz.check(bytes((0,)) + bytes(data))) > 2500


def test_the_tlog_harness_catches_a_reader_that_loses_a_message(monkeypatch):
    read_tlog = tlog.read_tlog
    monkeypatch.setattr(tlog, "read_tlog", lambda path, mav, **kw: read_tlog(path, mav, **kw)[:-1])
    with pytest.raises(AssertionError):
        tlog_fuzz.check(tlog_fuzz.seed_inputs()["raw-log"])


def _record(stamp: int, name: str, **values) -> bytes:
    codec = tlog_fuzz.CODEC
    msgid = next(i for i, cls in codec.classes.items() if cls.msgname == name)
    return struct.pack(">Q", stamp) + codec.encode(msgid, values)


HEARTBEAT = dict(type=2, autopilot=3, base_mode=4, custom_mode=5, system_status=6,
                 mavlink_version=3)


def _length_spans_the_next_record() -> bytes:
    first = bytearray(_record(1, "HEARTBEAT", **HEARTBEAT))
    second = _record(2, "STATUSTEXT", severity=6, text="inside", id=0, chunk_seq=0)
    first[9] += len(second)                                 # the length byte, after the stamp
    return bytes(first) + second + _record(3, "HEARTBEAT", **HEARTBEAT)


def _packet_inside_a_bad_packet() -> bytes:
    inner = _record(0, "HEARTBEAT", **HEARTBEAT)[8:]
    outer = bytearray(_record(1, "STATUSTEXT", severity=6, text="x" * 40, id=0, chunk_seq=0))
    outer[8 + 10 + 1:8 + 10 + 1 + len(inner)] = inner      # over the text; the CRC now fails
    return bytes(outer)


@pytest.mark.parametrize("damaged", [_length_spans_the_next_record, _packet_inside_a_bad_packet])
def test_a_damaged_record_with_a_packet_inside_is_reported(damaged, tmp_path):
    # Found by fuzzing: read_tlog took the first valid packet the framer found anywhere in
    # the damaged record's bytes as that record's message, and read on with no warning. The
    # damaged record is skipped and reported; what verifies after it is read.
    data = damaged()
    path = tmp_path / "damaged.tlog"
    path.write_bytes(data)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        messages = tlog.read_tlog(str(path), tlog_fuzz.DIALECT)
    assert len(caught) == 1 and "(the first at byte 0)" in str(caught[0].message)
    assert all(stamp != 1 for stamp, _ in messages)          # nothing of the damaged record
    tlog_fuzz.check(b"\0" + data)


def test_a_log_damaged_in_the_middle_is_read_on_after_it(tmp_path):
    records = [_record(k, "HEARTBEAT", **HEARTBEAT) for k in range(1, 6)]
    middle = bytearray(records[2])
    middle[8 + 12] ^= 0x01                                    # a payload byte: the CRC fails
    path = tmp_path / "middle.tlog"
    path.write_bytes(b"".join(records[:2]) + bytes(middle) + b"".join(records[3:]))
    damage = tlog.TlogDamage()
    messages = tlog.read_tlog(str(path), tlog_fuzz.DIALECT, damage=damage)
    assert [stamp for stamp, _ in messages] == [1, 2, 4, 5]
    assert damage.regions == [(2 * len(records[0]), len(records[0]))]
    assert damage.messages == 4 and not damage.out_of_order


def test_a_stamp_that_is_not_its_loops_time_is_reported(tmp_path):
    # A simulated session stamps each record with its loop's time: a flipped stamp bit that
    # keeps time in order is still seen there, and only that record is named.
    import random

    data = tlog_fuzz.loop_stamped_log(random.Random(3))
    path = tmp_path / "loops.tlog"
    path.write_bytes(data)
    damage = tlog.TlogDamage()
    messages = tlog.read_tlog(str(path), tlog_fuzz.DIALECT, damage=damage)
    offsets = [0]
    for _ in messages:
        offsets.append(offsets[-1] + 8 + mavframe.packet_at(data, offsets[-1] + 8,
                                                            tlog_fuzz.CODEC.extra_bytes)[1])
    assert damage.off_loop == [offsets[4]] and not damage.regions and not damage.out_of_order
    assert "1 timestamp not the time of their control loop" in damage.summary()
    tlog_fuzz.check(b"\0" + data)
    # Stamped from the run's start (a SIL log since it carries the wall clock): the same record.
    def restamped(stamp_of):
        path.write_bytes(b"".join(struct.pack(">Q", stamp_of(stamp)) + data[at + 8:end]
                                  for (stamp, _), at, end in zip(messages, offsets, offsets[1:])))
        damage = tlog.TlogDamage()
        tlog.read_tlog(str(path), tlog_fuzz.DIALECT, damage=damage)
        return damage

    assert restamped(lambda stamp: stamp + 1_790_000_000_000_000).off_loop == [offsets[4]]
    # Stamped by another clock (a board's log: the host's time, as each record is read, so
    # it runs on against the loops'), no stamp is held to a loop.
    later = iter(range(0, 7 * len(messages), 7))
    assert not restamped(lambda stamp: stamp + 10**15 + next(later))


def test_the_dataflash_harness_reads_its_seeds_and_random_logs():
    read = {label: dataflash_fuzz.check(data)
            for label, data in dataflash_fuzz.seed_inputs().items()}
    assert read == {"structured-roll": 1, "structured-back": 0, "structured-damaged": 1,
                    "raw-roll": 1}
    rng = random.Random(5)
    seeds = list(dataflash_fuzz.seed_inputs().values())
    swept = 0
    for _ in range(120):
        swept += dataflash_fuzz.check(bytes((0,)) + rng.randbytes(rng.randrange(MAX_RANDOM_LEN)))
        swept += dataflash_fuzz.check(bytes((dataflash_fuzz.STRUCTURED,))
                                      + rng.randbytes(rng.randrange(MAX_RANDOM_LEN)))
        swept += dataflash_fuzz.check(mutate(rng.choice(seeds), rng))
    assert swept > 20                            # the recipes and mutated seeds do get through


def _fmt(w, mtype, name, fmt, columns, length):
    w._raw("FMT", [mtype, length, name.encode(), fmt.encode(), columns.encode()])


@pytest.mark.parametrize("start10, stop, loops, amp", [(1, 1, 0, 1.4e-45), (5, 1, 100, 1.4e-45),
                                                      (5, 1, 0, 1e-44)])
def test_a_chirp_too_small_for_float32_is_refused_and_the_harness_expects_it(start10, stop,
                                                                            loops, amp):
    """Found by fuzzing (CI, stop 48): a chirp of a subnormal amplitude logs as zero at most
    loops; identify refuses it in one line, and the harness no longer calls that log whole."""
    recipe = dataflash_fuzz._RECIPE.pack(10, start10, stop, loops, 0, amp, 0)
    content, whole, _ = dataflash_fuzz.structured_log(recipe)
    assert not whole
    with pytest.raises(InputError, match="zero throughout|not a sweep"):
        dataflash_fuzz.read(content)
    assert dataflash_fuzz.check(bytes((dataflash_fuzz.STRUCTURED,)) + recipe) == 0
    small = dataflash_fuzz._RECIPE.pack(10, start10, stop, loops, 0,
                                        dataflash_fuzz.MIN_WHOLE_AMP, 0)
    assert dataflash_fuzz.check(bytes((dataflash_fuzz.STRUCTURED,)) + small) == 1


@pytest.mark.parametrize("family", ["ardupilot", "heliquad"])
def test_a_format_dataflash_cannot_take_is_refused_in_one_line(family):
    # found by fuzzing: DFReader raised a bare Exception for an unknown format character
    w = DataFlashWriter()
    _fmt(w, 90, "ATT" if family == "ardupilot" else "HQSD", "QK", "TimeUS,Bad", 20)
    with pytest.raises(InputError, match="not a DataFlash log .*Unsupported format char"):
        dataflash_fuzz.read(bytes(w.data))


@pytest.mark.parametrize("family", ["ardupilot", "heliquad"])
def test_a_record_whose_format_lacks_a_field_is_damage_not_a_crash(family):
    # found by fuzzing: a damaged FMT left a record without a field the reader takes, and the
    # attribute error escaped
    w = DataFlashWriter()
    _fmt(w, 68, "SIDD", "Qf", "TimeUS,Time", 15)
    w.write("ATT" if family == "ardupilot" else "MSG", TimeUS=5)
    if family == "heliquad":
        _fmt(w, 71, "HQSD", "QI", "TimeUS,Other", 15)
    for k in range(3):
        w.data += b"\xa3\x95\x44" + struct.pack("<Qf", 100 + k, 0.1 * k)       # SIDD
        if family == "heliquad":
            w.data += b"\xa3\x95\x47" + struct.pack("<QI", 100 + k, k)           # HQSD
    with pytest.raises(InputError, match="SIDD sample|no excitation"):
        dataflash_fuzz.read(bytes(w.data))
