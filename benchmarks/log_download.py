"""Benchmark: a log downloaded from the Teensy 3.5 image over its emulated USB port.

A card image holding one log of random bytes (256 KiB by default) goes in the emulated
board's microSD socket; the image boots disarmed with a USB host on its port (sim/chip/
usb_host.py), which opens the port and asks for the whole log with one LOG_REQUEST_DATA, as
``heliquad logs download`` and MAVProxy ask. The board's answers are read as they come; the
figures:

* the download rate in the chip's time: the log's bytes over the emulated seconds from the
  request to the last LOG_DATA (the emulator's time is its cycle model's, so this figure is
  the same in every run);
* the loop meanwhile: every step's cycles (hq_loop_report, as HQ_FW_STATUS counts them),
  median and largest, before and during the download (and the largest in microseconds at
  120 MHz and as a share of the 5 ms budget), the overruns, and the telemetry that kept
  flowing (HEARTBEATs and ATTITUDEs a second, and the bytes the USB link dropped);
* the same bytes as the card's file, checked;
* the wall-clock rate, information only (it is the emulator's speed, not the board's).

    python benchmarks/log_download.py [--kib 256] [--elf PATH]

The test of the rate is tests/log_download_test.py.
"""

from __future__ import annotations

import argparse
import dataclasses
import pathlib
import statistics
import tempfile
import time

import numpy as np

from heliquad import _firmware as fw
from heliquad.sim.base.dialect import dialect
from heliquad.sim.chip import Teensy35
from heliquad.sim.chip.pil.board import RC_FRAME_LOOPS, REPORT, REPORT_SYMBOL, WAIT_SYMBOL
from heliquad.sim.chip.teensy35 import STEP_SYMBOL
from heliquad.sim.chip.usb_host import UsbHost, settle
from heliquad.sim.sensor.mpu6050_packets import raw_packet

ROOT = pathlib.Path(__file__).resolve().parents[1]
DEFAULT_ELF = ROOT / "build" / "teensy35" / "heliquad-fw-teensy35.elf"
CORE_HZ = 120e6
LOOP_BUDGET_US = 5000.0             # the 200 Hz loop's period
BOOT_BUDGET = 40_000_000            # instructions to the first loop
#: The log is written in the logger's pieces, synced as the logger syncs.
WRITE_BYTES = 4096
#: Emulated time between reads of the host's bytes, and the most a download may take.
SLICE_S = 0.02
GUARD_S = 30.0
#: Emulated time the loop runs before the request, its "before" figures.
BEFORE_S = 2.0
LOG_ID = 1


def write_log_card(path: pathlib.Path, data: bytes) -> None:
    """A fresh card image at ``path`` whose only log, LOGS/00000001.BIN, is ``data``."""
    assert fw.make_card_image(str(path), fw.MIN_CARD_IMAGE_BYTES) == ""
    card = fw.CardFiles(str(path))
    assert card.mount() == fw.CardState.OK and card.begin_log()
    for at in range(0, len(data), WRITE_BYTES):
        piece = data[at:at + WRITE_BYTES]
        assert card.write(piece) == len(piece)
        card.advance_us(fw.LOG_SYNC_PERIOD_US)
        card.service()
    card.end_log()


@dataclasses.dataclass
class Download:
    """What a download over the emulated USB measured."""
    size_bytes: int
    data: bytes                     # the LOG_DATA's bytes, in order of their offsets
    emulated_s: float               # from the request to the last LOG_DATA
    wall_s: float
    steps_before: list              # each step's cycles, BEFORE_S before the request
    steps_during: list              # and from the request to the last LOG_DATA
    overruns: int                   # at the end
    heartbeats: int                 # during the download
    attitudes: int
    usb_dropped_bytes: int          # the USB link's, at the end

    @property
    def rate_bytes_per_s(self) -> float:
        return self.size_bytes / self.emulated_s

    def budget_share(self, cycles: int) -> float:
        return cycles / CORE_HZ * 1e6 / LOOP_BUDGET_US


class UsbGcs:
    """The image on the emulated board with a card, its IMU giving a sample for every step
    (a level vehicle at rest, rotating a little) and its receiver a frame of ``rc`` every
    four (``rc`` None: no receiver), a host on its USB port holding it open, and a ground
    station's parser over what arrives."""

    def __init__(self, elf, card_path, rc: dict | None = None):
        self.mav = dialect()
        self.board = Teensy35(elf, sd_image=card_path)
        self.sample = raw_packet([0.01, -0.02, 0.005], [0.0, 0.0, -9.80665])
        self.rc, self.fed = rc, 0
        self.board.machine.break_at(STEP_SYMBOL, self._feed)
        self.steps = []                 # each step's cycles that ended at the loop's sleep
        self._report = self.board.machine.image.symbol(REPORT_SYMBOL).address
        self.board.machine.break_at(WAIT_SYMBOL, self._record_step)
        self.host = UsbHost(self.board.chip)
        assert self.board.run_to_loop(1, instructions=BOOT_BUDGET).reason == "loop"
        self.run(0.5)
        settle(self.host, self.run, timeout_s=1.0)
        self.host.open()
        settle(self.host, self.run, timeout_s=1.0)
        self.parser = self.mav.MAVLink(None)
        self.gcs = self.mav.MAVLink(None, srcSystem=255, srcComponent=190)

    def _feed(self, machine):
        self.board.mpu.emu.push_fifo(self.sample, False)
        if self.rc is not None and self.fed % RC_FRAME_LOOPS == 0:
            self.board.rc_capture_pulses(self.rc)
        self.fed += 1

    def _record_step(self, machine):
        self.steps.append(REPORT.unpack(machine.read(self._report, REPORT.size))[1])

    def take_steps(self) -> list:
        steps, self.steps = self.steps, []
        return steps

    def run(self, seconds: float) -> None:
        self.board.run(seconds=seconds)

    def now_s(self) -> float:
        return self.board.machine.seconds()

    def receive(self) -> list:
        return [m for m in self.parser.parse_buffer(self.host.take_received()) or []
                if m.get_type() != "BAD_DATA"]

    def send(self, msg) -> None:
        self.host.send(msg.pack(self.gcs))

    def request(self, log_id: int, ofs: int, count: int) -> None:
        self.send(self.gcs.log_request_data_encode(1, 1, log_id, ofs, count))


def measure(elf, card_path, size_bytes: int) -> Download:
    """Downloads log 1 (``size_bytes`` long) from the image over USB."""
    t0 = time.perf_counter()
    gcs = UsbGcs(elf, card_path)
    gcs.run(BEFORE_S)
    gcs.receive()
    steps_before = gcs.take_steps()
    gcs.request(LOG_ID, 0, 0xFFFFFFFF)
    start_s, got, during = gcs.now_s(), {}, []
    end_s = None
    while end_s is None and gcs.now_s() - start_s < GUARD_S:
        gcs.run(SLICE_S)
        for m in gcs.receive():
            during.append(m)
            if m.get_type() == "LOG_DATA" and m.id == LOG_ID and m.count > 0:
                got[m.ofs] = bytes(m.data[:m.count])
                if sum(map(len, got.values())) >= size_bytes:
                    end_s = gcs.now_s()
    if end_s is None:
        raise AssertionError(f"{sum(map(len, got.values()))} of {size_bytes} bytes in "
                             f"{GUARD_S} s of emulated time")
    # The time of the last LOG_DATA is the end of the slice it came in (at most SLICE_S
    # late: the rate is at most that pessimistic).
    steps_during = gcs.take_steps()
    gcs.run(1.0)                                     # one more HQ_FW_STATUS after it
    status = [m for m in during + gcs.receive() if m.get_type() == "HQ_FW_STATUS"]
    return Download(
        size_bytes=size_bytes, data=b"".join(got[k] for k in sorted(got)),
        emulated_s=end_s - start_s, wall_s=time.perf_counter() - t0,
        steps_before=steps_before, steps_during=steps_during,
        overruns=status[-1].loop_overruns,
        heartbeats=sum(m.get_type() == "HEARTBEAT" for m in during),
        attitudes=sum(m.get_type() == "ATTITUDE" for m in during),
        usb_dropped_bytes=status[-1].link_dropped[gcs.mav.HQ_LINK_USB])


#: The receiver: arm switch (channel 5) high, throttle low to arm, then mid.
RC_ARM = {0: 1500, 1: 1500, 2: 1000, 3: 1500, 4: 2000, 5: 1000}
THROTTLE_CHANNEL, THROTTLE_MID_US = 2, 1500
#: The excitation logged: a roll sine at the mixer, as a sweep's points are.
EXCITATION_HZ, EXCITATION_AMPLITUDE = 2.0, 0.05
#: A card that holds busy this long once a period of emulated time (sd_card.py's busy_hold).
BUSY_HOLD = (0.25, 1.0)


@dataclasses.dataclass
class Flight:
    """What an armed flight logging on the card showed: HQ_FW_STATUS of every second (the
    last after the disarming), and the log the card holds then."""
    status: list
    log: bytes

    @property
    def armed_status(self) -> list:
        return [m for m in self.status if m.armed]

    @property
    def max_step_cycles(self) -> int:
        return max(m.loop_cycles_max for m in self.armed_status)


def fly_logging(elf, card_path, seconds: int, busy: bool) -> Flight:
    """Arms the image (MAVLink, the switch high), runs a roll sine excitation for
    ``seconds`` with the on-board log on the card (``busy``: the card holds busy
    BUSY_HOLD), disarms, and reads log 1 off the card."""
    mav = dialect()
    gcs = UsbGcs(elf, card_path, rc=dict(RC_ARM))
    heartbeat = gcs.gcs.heartbeat_encode(mav.MAV_TYPE_GCS, mav.MAV_AUTOPILOT_INVALID, 0, 0, 0)
    gcs.send(heartbeat)
    gcs.send(gcs.gcs.command_long_encode(1, 1, mav.MAV_CMD_COMPONENT_ARM_DISARM, 0, 1,
                                         0, 0, 0, 0, 0, 0))
    gcs.run(0.2)
    gcs.rc[THROTTLE_CHANNEL] = THROTTLE_MID_US
    gcs.send(gcs.gcs.hq_excitation_encode(
        1, 1, mav.HQ_EXCITATION_START, mav.HQ_AXIS_ROLL, mav.HQ_INJECTION_MIXER,
        EXCITATION_HZ, EXCITATION_AMPLITUDE, int(EXCITATION_HZ * seconds), 1,
        mav.HQ_SIGNAL_SINE, [0] * 16, [0.0] * 16, [0.0] * 16))
    if busy:
        gcs.board.sd_card.busy_hold = BUSY_HOLD
    got = []
    for _ in range(seconds):
        gcs.send(heartbeat)
        gcs.run(1.0)
        got += gcs.receive()
    gcs.send(gcs.gcs.command_long_encode(1, 1, mav.MAV_CMD_COMPONENT_ARM_DISARM, 0, 0,
                                         0, 0, 0, 0, 0, 0))
    gcs.run(2.0)                                     # the log ended and closed
    got += gcs.receive()
    status = [m for m in got if m.get_type() == "HQ_FW_STATUS"]
    status = status[[m.armed for m in status].index(1):]      # from the arming on
    reader = fw.CardFiles(str(card_path))
    assert reader.mount() == fw.CardState.OK
    log = reader.read(1, 0, 1 << 24)
    del reader
    return Flight(status=status, log=log)


def print_flight(what: str, f: Flight) -> None:
    last = f.status[-1]
    top = f.max_step_cycles
    print(f"{what}: {len(f.armed_status)} s armed, largest step {top} cycles, "
          f"{top / CORE_HZ * 1e6:.0f} us, {100 * top / CORE_HZ * 1e6 / LOOP_BUDGET_US:.1f} % "
          f"of the 5 ms budget; overruns {last.loop_overruns}; log records "
          f"{last.log_records}, dropped {last.log_dropped}; {len(f.log)} bytes on the card")


def main():
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--kib", type=int, default=256, help="the log's size in KiB")
    parser.add_argument("--elf", type=pathlib.Path, default=DEFAULT_ELF)
    parser.add_argument("--flight-s", type=int, default=8,
                        help="also fly this long armed, logging, with and without a busy card "
                             "(0: not)")
    args = parser.parse_args()
    if not args.elf.exists():
        raise SystemExit(f"{args.elf} not found: build it (cmake --preset teensy35 && cmake "
                         "--build --preset teensy35)")
    log = np.random.default_rng(1).integers(0, 256, args.kib * 1024, dtype=np.uint8).tobytes()
    with tempfile.TemporaryDirectory() as tmp:
        card = pathlib.Path(tmp) / "card.img"
        write_log_card(card, log)
        r = measure(args.elf, card, len(log))
    print(f"log: {len(log)} bytes, downloaded {'whole and equal' if r.data == log else 'WRONG'}")
    print(f"emulated: {r.emulated_s:.3f} s, {r.rate_bytes_per_s / 1e3:.1f} kB/s "
          "(the chip's time, deterministic)")
    print(f"wall: {r.wall_s:.1f} s with the boot, {len(log) / r.wall_s / 1e3:.1f} kB/s "
          "(information only: the emulator's speed)")
    for when, steps in (("before", r.steps_before), ("during", r.steps_during)):
        top = max(steps)
        print(f"steps {when} ({len(steps)}): median {statistics.median(steps):.0f} cycles, "
              f"largest {top} cycles, {top / CORE_HZ * 1e6:.0f} us, "
              f"{100 * r.budget_share(top):.1f} % of the 5 ms budget")
    print(f"during the download: {r.heartbeats / r.emulated_s:.1f} HEARTBEAT/s, "
          f"{r.attitudes / r.emulated_s:.1f} ATTITUDE/s; overruns {r.overruns}, "
          f"USB link dropped {r.usb_dropped_bytes} bytes")
    for busy in (False, True) if args.flight_s > 0 else ():
        with tempfile.TemporaryDirectory() as tmp:
            card = pathlib.Path(tmp) / "card.img"
            assert fw.make_card_image(str(card), fw.MIN_CARD_IMAGE_BYTES) == ""
            flight = fly_logging(args.elf, card, args.flight_s, busy)
        print_flight(f"armed, logging{', card busy 250 ms a second' if busy else ''}", flight)


if __name__ == "__main__":
    main()
