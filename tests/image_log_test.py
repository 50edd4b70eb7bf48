"""The Teensy 3.5 image's on-board log in the emulated chip (docs/sd-card.md), measured in the
chip's time (its cycle model: the same figures in every run), with the harness of
benchmarks/log_download.py:

* a 256 KiB log downloaded over the emulated USB port at 100 kB/s of emulated time at least,
  equal to the file on the card (read by the tests' own FAT32 reader), while the loop's steps
  keep their cycles, no loop overruns and the telemetry keeps its rates;
* armed, logging every loop of an excitation on the card: the largest step (HQ_FW_STATUS's
  loop_cycles_max) below a quarter of the 5 ms budget, no overrun, no record dropped;
* the same with a card that holds busy 250 ms every second: still below a quarter, no
  overrun; the records lost are counted (HQ_FW_STATUS log_dropped) and marked in the log
  (HQGP gap records whose counts add up to them), every other record whole.
"""

from __future__ import annotations

import pathlib
import statistics
import sys

import numpy as np
import pytest
from pymavlink import DFReader

from heliquad import _firmware as fw
from fat32_image import Fat32Image

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parents[1] / "benchmarks"))
import log_download as bench  # noqa: E402
import teensy35_boot_test as boot  # noqa: E402

pytestmark = pytest.mark.pil

#: The acceptance figures: the download's rate, and the largest step's share of the budget.
MIN_RATE_BYTES_PER_S = 100e3
MAX_STEP_SHARE = 0.25
LOG_BYTES = 256 * 1024
#: The loop's largest steps are those where the 1 Hz streams meet; which of them fall in a
#: window of a few seconds varies, so the largest step during the download is compared with
#: the largest before it within this much.
STEP_MAX_SLACK = 1.05
FLIGHT_S = 6
LOOP_HZ = 200


@pytest.fixture
def image():
    boot.require_image()
    return boot.IMAGE


def test_a_256_kib_log_downloads_over_usb_at_100_kb_s_and_the_loop_keeps_its_steps(
        tmp_path, image):
    log = np.random.default_rng(5).integers(0, 256, LOG_BYTES, dtype=np.uint8).tobytes()
    card = tmp_path / "card.img"
    bench.write_log_card(card, log)
    assert Fat32Image(card).read("LOGS/00000001.BIN") == log
    r = bench.measure(image, card, len(log))
    assert r.data == log
    assert r.rate_bytes_per_s >= MIN_RATE_BYTES_PER_S, r.rate_bytes_per_s
    assert statistics.median(r.steps_during) == pytest.approx(
        statistics.median(r.steps_before), rel=0.01)
    assert max(r.steps_during) <= STEP_MAX_SLACK * max(r.steps_before)
    assert r.overruns == 0 and r.usb_dropped_bytes == 0
    assert r.attitudes >= 0.95 * LOOP_HZ * r.emulated_s          # every loop's ATTITUDE
    assert r.heartbeats >= int(r.emulated_s)                     # 1 Hz


def records(log: bytes, tmp_path) -> list:
    path = tmp_path / "log.BIN"
    path.write_bytes(log)
    reader, out = DFReader.DFReader_binary(str(path)), []
    while (m := reader.recv_msg()) is not None:
        out.append(m)
    assert len(log) == sum(len(m.get_msgbuf()) for m in out), "every record whole"
    return out


def of(recs, kind: str) -> list:
    return [m for m in recs if m.get_type() == kind]


def flown(tmp_path, image, busy: bool):
    card = tmp_path / "card.img"
    assert fw.make_card_image(str(card), fw.MIN_CARD_IMAGE_BYTES) == ""
    flight = bench.fly_logging(image, card, FLIGHT_S, busy)
    assert len(flight.armed_status) >= FLIGHT_S
    assert flight.max_step_cycles < MAX_STEP_SHARE * bench.CORE_HZ / LOOP_HZ
    assert flight.status[-1].loop_overruns == 0
    assert not flight.status[-1].armed, "disarmed at the end"
    return flight, records(flight.log, tmp_path)


def test_armed_logging_keeps_the_largest_step_below_a_quarter_of_the_budget(tmp_path, image):
    flight, recs = flown(tmp_path, image, busy=False)
    last = flight.status[-1]
    assert last.log_dropped == 0 and not of(recs, "HQGP")
    seqs = [m.Seq for m in of(recs, "HQSD")]
    assert seqs == list(range(seqs[0], seqs[-1] + 1))             # every armed loop
    assert len(seqs) >= FLIGHT_S * LOOP_HZ
    assert any(m.Exc != 0.0 for m in of(recs, "HQSD")), "the excitation logged"


def test_a_card_busy_250_ms_a_second_costs_marked_records_never_a_late_loop(tmp_path, image):
    flight, recs = flown(tmp_path, image, busy=True)
    dropped = flight.status[-1].log_dropped
    gaps = of(recs, "HQGP")
    seqs = [m.Seq for m in of(recs, "HQSD")]
    missing = [(a + 1, b - 1) for a, b in zip(seqs, seqs[1:]) if b != a + 1]
    assert dropped > 0 and len(missing) >= FLIGHT_S - 1            # a spell every second
    assert len(gaps) >= len(missing)
    assert sum(g.Dropped for g in gaps) == dropped                # every drop marked
    times = {m.Seq: m.TimeUS for m in of(recs, "HQSD")}
    for first, last in missing:                                   # inside a gap's span
        before, after = times[first - 1], times[last + 1]
        assert any(before < g.SinceUS and g.TimeUS <= after for g in gaps), (first, last)
