"""Power cuts at random instructions on the Teensy image while it logs (docs/sd-card.md, "Power
cuts on the emulated board").

The image flies on the emulated chip with a card in its socket (the card image `heliquad
sd-image` makes by default): armed 2.5 s (log 1), disarmed 0.2 s, armed 1.5 s (log 2),
disarmed. A power cut at instruction N leaves the card image with exactly the blocks the card
acknowledged before N (sim/chip/sd_card.py). After each cut, drawn at random (seeded) from the
first arming to the end of the flight, and a few more in the first frames after each switch
change (a log's beginning and end): `fsck.fat -n` finds the card clean or says only what a
cut may leave (sd_files_test.FSCK_AFTER_POWER_CUT); every log on it reads through this
project's FAT reader and FatFs alike, is a prefix of the same log of the flight without cuts,
opens in DFReader, and is either whole or has its last record within LOG_SYNC_PERIOD_US (1 s)
of the cut on the firmware's clock; a log missing was begun less than that before the cut.

Why the card at a stop at N is the card a cut at N leaves: the card model writes a block to
the image file when the card acknowledges it, inside the SDHC model's event for that block,
and events run only at the core's block boundaries (sim/chip/machine.py). Machine.run with an
instruction budget stops at a block boundary, before the block that would pass N; running
again until no instruction retires runs the events due at that boundary, and nothing else can
write the card before instruction N (the next boundary lies past N). So the image file then
holds what the card acknowledged up to instruction N: the checks read it there, the emulator
paused, and the flight goes on. The stops change nothing the image or the devices see: a fresh
flight stopped at N leaves the same card, byte for byte, and the flight with all its stops
ends with the card of the flight without any.

One flight gives all the cuts, so a cut costs its checks alone. The board's IMU samples on
its own clock, once a loop period of emulated time, as the MPU6050 on a board does: while
the card holds the spare-time service (the first drain after an arming takes some 40 ms),
the loop's steps run nested in the card's wait and read fresh samples, which a lockstep frame
(one sample a frame) cannot give them.
"""

from __future__ import annotations

import hashlib
import pathlib
import random
import shutil
import struct
import sys
from types import SimpleNamespace

import pytest
from pymavlink import DFReader

from heliquad import _firmware as fw
from heliquad.sim.chip.pil.board import IMAGE_LOOP_HZ, PilBoard
from heliquad.sim.sensor.mpu6050_packets import raw_packet
from fat32_image import Fat32Image
from sd_files_test import assert_fsck_accepts, needs_fsck

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parent))
import teensy35_boot_test as boot  # noqa: E402

#: The flight: (arm switch pulse in us, frames). Throttle low, sticks centred throughout; the
#: image arms on the switch's low-to-high edge and disarms when it goes low.
SWITCH_LOW, SWITCH_HIGH = 1000, 2000
FLIGHT = ((SWITCH_LOW, 40), (SWITCH_HIGH, 500), (SWITCH_LOW, 40), (SWITCH_HIGH, 300),
          (SWITCH_LOW, 40))
#: The cuts: how many, their seed, and how many of them are checked against a fresh flight
#: stopped at the same instruction (each costs a flight up to its cut).
CUTS, SEED, FRESH_CUTS = 100, 35, 3
#: More cuts, drawn from the first EDGE_FRAMES frames after each switch change (the log's
#: beginning, its first drain, and its end), EDGE_CUTS at each of the four.
EDGE_CUTS, EDGE_FRAMES = 5, 2
#: The most a cut may lose of the log being written (the sync period).
MAX_LOSS_US = fw.LOG_SYNC_PERIOD_US
#: A still IMU, level.
SAMPLE = raw_packet([0.0, 0.0, 0.0], [0.0, 0.0, -9.80665])
LOGS = "LOGS"
#: SDHC_PRSSTAT's CDIHB: the data lines in use (a block under way, or the card's busy after
#: a write).
PRSSTAT_CDIHB = 1 << 1
#: What fsck.fat says after a cut, counted for the figures (docs/sd-card.md).
FSCK_SAYS = ("cluster chain length", "unused cluster", "FATs differ", "Free cluster summary")


def rc(switch_us: int) -> list:
    return [1500, 1500, 1000, 1500, switch_us, 1000]


class Flight:
    """The image flying FLIGHT on a card image, paused at each of ``cuts`` (instruction
    counts) to call ``on_cut(flight)``. ``edges``: the instructions (from, to) of the first
    EDGE_FRAMES frames of each of FLIGHT's stretches."""

    def __init__(self, card: pathlib.Path, cuts=(), on_cut=None):
        self.card = card
        self.board = PilBoard(str(boot.IMAGE), sd_image=str(card), link="uart")
        self.board.boot()
        m = self.machine = self.board.machine
        # The firmware's clock counts core cycles from the cycle counter's start (TeensyClock).
        self.clock_zero = m.now() - self.board.board.chip.dwt.cyccnt()
        self.cuts = sorted(cuts, reverse=True)
        self.on_cut = on_cut
        self.edges = []
        self._run = m.run
        m.run = self._run_with_cuts
        period = int(m.core_hz / IMAGE_LOOP_HZ)
        self._imu_sample(self.board.board.chip.scs.systick.zero_at - period // 5, period)

    def _imu_sample(self, at: int, period: int) -> None:
        """An IMU sample in the FIFO at core cycle ``at`` and every ``period`` after it."""
        def sample():
            self.board.board.mpu.emu.push_fifo(SAMPLE, False)
            self._imu_sample(at + period, period)
        self.machine.at(at, sample, scaled=False)

    def firmware_us(self) -> int:
        """The firmware's clock (micros()) now."""
        return (self.machine.now() - self.clock_zero) * 1_000_000 // int(self.machine.core_hz)

    def fly(self) -> None:
        for switch_us, frames in FLIGHT:
            self.edges.append([self.machine.instructions_now(), None])
            for k in range(frames):
                self.board.frame(b"", False, rc(switch_us), 0, sync=False)
                self.board.telemetry_out.clear()
                if k + 1 == EDGE_FRAMES:
                    self.edges[-1][1] = self.machine.instructions_now()

    def _run_with_cuts(self, instructions=None, seconds=None):
        """Machine.run for the board's frames (a time limit only), paused at each cut."""
        assert instructions is None and seconds is not None
        end = self.machine.cycles_after(seconds)
        while self.cuts:
            stop = self._run_to(self.cuts[-1], end)
            if stop is not None:
                return stop                     # the frame ended before the cut
            self.on_cut(self)
            self.cuts.pop()
        return self._run(seconds=self._left_s(end))

    def _run_to(self, n: int, end: int):
        """Runs to instruction ``n`` (None), the events due there run; or the stop that
        came first."""
        m = self.machine
        while True:
            before = m.instructions_now()
            assert before <= n, "a cut before the flight's start"
            stop = self._run(instructions=n - before, seconds=self._left_s(end))
            if stop.reason != "budget":
                return stop
            if m.instructions_now() == before:
                return None

    def _left_s(self, end: int) -> float:
        m = self.machine
        return max(end - m.now(), 1) / m.core_hz


def blank_card(path: pathlib.Path) -> pathlib.Path:
    assert fw.make_card_image(str(path), fw.DEFAULT_CARD_IMAGE_BYTES) == ""
    return path


def logs_on(image: Fat32Image) -> dict:
    """The card's logs by name, their bytes."""
    if LOGS not in image.listdir():
        return {}
    return {name: image.read(f"{LOGS}/{name}") for name in image.listdir(LOGS)}


def time_us_of(data: bytes, scratch: pathlib.Path) -> list:
    """The TimeUS of every record DFReader reads in a log's bytes, in order."""
    scratch.write_bytes(data)
    log = DFReader.DFReader_binary(str(scratch))
    out = []
    while (m := log.recv_msg()) is not None:
        if "TimeUS" in m.get_fieldnames():
            out.append(m.TimeUS)
    return out


def sha256(path: pathlib.Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def check_cut(flight: Flight, whole: dict, scratch: pathlib.Path) -> dict:
    """The checks on the card at a cut, against the flight's logs without cuts (``whole``:
    name -> (bytes, TimeUS list)): what the cut lost of each log begun and not whole (us),
    how many of those have no record on the card, and what is wrong (nothing, we expect)."""
    card, cut_us = flight.card, flight.firmware_us()
    problems, losses, said, begun = [], {}, None, 0
    try:
        said = assert_fsck_accepts(card)
    except AssertionError as e:
        problems.append(f"fsck.fat: {e}")
    on_card = logs_on(Fat32Image(card))
    names = sorted(whole)
    if sorted(on_card) != names[:len(on_card)]:
        problems.append(f"logs {sorted(on_card)}; the flight made {names}")
    shutil.copyfile(card, scratch.with_suffix(".img"))      # FatFs's mount may write
    files = fw.CardFiles(str(scratch.with_suffix(".img")))
    if files.mount() != fw.CardState.OK:
        problems.append("FatFs does not mount the card")
    for k, name in enumerate(names, start=1):
        data, times = whole[name]
        got = on_card.get(name)
        if got is not None and (not data.startswith(got) or
                                files.read(k, 0, len(data) + 1) != got):
            problems.append(f"{name}: {len(got)} bytes not a prefix of the flight's log, or "
                            "FatFs reads other bytes")
        elif got != data and times[0] <= cut_us:        # begun before the cut, not whole
            read = time_us_of(got, scratch) if got else []
            begun += not read
            losses[name] = cut_us - (read[-1] if read else times[0])
            if not 0 <= losses[name] <= MAX_LOSS_US:
                problems.append(f"{name}: its last record {losses[name]} us before the cut")
    del files
    return {"cut_us": cut_us, "losses": losses, "problems": problems, "fsck": said,
            "begun": begun}


class CutReached(Exception):
    """A fresh flight reached its one cut: it stops there."""


@pytest.fixture(scope="module")
def flights(tmp_path_factory):
    """The flight without cuts, then the same flight with CUTS cuts from the first arming to
    the end and EDGE_CUTS at each later switch change, the checks at each; then FRESH_CUTS
    fresh flights each stopped at one of the cuts."""
    boot.require_image()
    tmp = tmp_path_factory.mktemp("cuts")
    scratch = tmp / "log.BIN"
    uncut = Flight(blank_card(tmp / "uncut.img"))
    uncut.fly()
    whole = {name: (data, time_us_of(data, scratch))
             for name, data in logs_on(Fat32Image(uncut.card)).items()}
    draw = random.Random(SEED)
    cuts = draw.sample(range(uncut.edges[1][0], uncut.machine.instructions_now()), CUTS)
    for start, end in uncut.edges[1:]:
        cuts += draw.sample(range(start, end), EDGE_CUTS)
    cuts = sorted(set(cuts))
    fresh = sorted(draw.sample(cuts, FRESH_CUTS))
    results = {}

    def on_cut(flight):
        n = flight.cuts[-1]
        results[n] = check_cut(flight, whole, scratch)
        sdhc = flight.board.board.chip.sdhc
        results[n]["transfer"] = sdhc.transfer()
        results[n]["busy"] = bool(sdhc.r_PRSSTAT() & PRSSTAT_CDIHB)
        if n in fresh:
            results[n]["card"] = sha256(flight.card)
    cut = Flight(blank_card(tmp / "cut.img"), cuts, on_cut)
    cut.fly()
    stopped = {}
    for n in fresh:
        def reached(flight):
            stopped[n] = sha256(flight.card)
            raise CutReached
        with pytest.raises(CutReached):
            Flight(blank_card(tmp / "fresh.img"), [n], reached).fly()
    return {"whole": whole, "results": results, "stopped": stopped, "uncut_card": uncut.card,
            "cards": (sha256(uncut.card), sha256(cut.card))}


def test_the_flight_logs_both_armings(flights):
    whole = flights["whole"]
    assert sorted(whole) == ["00000001.BIN", "00000002.BIN"]
    for (name, (data, times)), (_, frames) in zip(sorted(whole.items()), FLIGHT[1::2]):
        span_s = (times[-1] - times[0]) / 1e6
        assert span_s == pytest.approx(frames / IMAGE_LOOP_HZ, abs=0.05), name


@needs_fsck
def test_every_cut_leaves_a_clean_card_and_each_log_readable_to_within_a_second(flights):
    results = flights["results"]
    assert len(results) == CUTS + EDGE_CUTS * (len(FLIGHT) - 1)
    wrong = {n: r["problems"] for n, r in results.items() if r["problems"]}
    assert not wrong, wrong
    losses = [us for r in results.values() for us in r["losses"].values()]
    # Most cuts came while a log was open (the flight is armed 4 s of its 4.2 s), some while
    # the card's data lines were in use (a block under way or the card programming one).
    assert len(losses) > CUTS // 2
    assert any(r["busy"] for r in results.values())
    writing = [r["transfer"] for r in results.values() if r["transfer"] and r["transfer"][0]]
    said = [r["fsck"] for r in results.values()]
    fsck_counts = ", ".join(f"{sum(words in s for s in said)} {words!r}" for words in FSCK_SAYS)
    print(f"\n{len(results)} cuts: {len(losses)} in an open log "
          f"({sum(r['begun'] for r in results.values())} of them one with no record yet); "
          f"fsck.fat clean after "
          f"{said.count('')}, said {fsck_counts}; "
          f"{sum(r['busy'] for r in results.values())} with the data lines in use, "
          f"{len(writing)} during a written block's transfer, "
          f"{sum(1 for _, done, left in writing if done and left)} in the middle of a "
          f"multi-block write; the largest loss {max(losses) / 1e6:.3f} s")


def test_a_stop_for_a_cut_changes_nothing_the_flight_does(flights):
    # A fresh flight stopped at a cut's instruction leaves the card the cut saw, and the
    # flight with every stop ends with the card of the flight without any.
    results = flights["results"]
    assert flights["stopped"] and all(
        results[n]["card"] == card for n, card in flights["stopped"].items())
    uncut, cut = flights["cards"]
    assert uncut == cut


def cross_link(card: pathlib.Path) -> None:
    """Log 1's first cluster made to lead into log 2's chain, in the first FAT."""
    image = Fat32Image(card)
    logs = image.entries(image.root_cluster)[LOGS][1]
    first = {name: cluster for name, (_, cluster, _) in image.entries(logs).items()}
    with open(card, "r+b") as f:
        f.seek(image.fat_at + 4 * first["00000001.BIN"])
        f.write(struct.pack("<I", first["00000002.BIN"]))


@needs_fsck
def test_the_checks_find_a_damaged_card_altered_bytes_and_a_log_a_second_short(flights,
                                                                             tmp_path):
    whole, scratch = flights["whole"], tmp_path / "log.BIN"
    data, times = whole["00000002.BIN"]
    card = tmp_path / "card.img"
    shutil.copyfile(flights["uncut_card"], card)

    def problems(at_us, logs=whole):
        at = SimpleNamespace(card=card, firmware_us=lambda: at_us)
        return check_cut(at, logs, scratch)["problems"]
    assert problems(times[-1]) == []
    # The flight logged past the card's end of log 2, and the cut came 1.5 s after its last
    # record there.
    longer = dict(whole, **{"00000002.BIN": (data + bytes(8), times)})
    assert problems(times[-1] + 1_500_000, longer) == [
        "00000002.BIN: its last record 1500000 us before the cut"]
    with open(card, "r+b") as f:
        f.seek(Fat32Image(card).offset("LOGS/00000001.BIN") + 100)
        f.write(b"\xff")
    assert [p[:13] for p in problems(times[-1])] == ["00000001.BIN:"]
    shutil.copyfile(flights["uncut_card"], card)
    cross_link(card)
    assert problems(times[-1])[0].startswith("fsck.fat: ")
