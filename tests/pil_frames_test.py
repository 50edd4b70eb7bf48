"""The drop-in's plain frames run natively (sim/chip/pil_frames.hpp, native_frames.py) are the
Python path's frames, byte for byte: the same replies (sequence numbers included), the same
telemetry, the same logged experiment. The Python path (HQ_PIL_FRAMES=python) is the
reference: it runs every frame through PilBoard and DropIn as before the native path
existed."""

from __future__ import annotations

import math
import os
import select
import threading
import tty

import pytest

from firmwares import image_for
from heliquad.host.acquire.experiment import run_sil
from heliquad.host.records.tlog import read_tlog
from heliquad.sim.base.dialect import dialect
from heliquad.sim.base.framing import Codec, Framer
from heliquad.sim.chip.pil.board import PilBoard
from heliquad.sim.chip.pil.drop_in import DropIn, Stop
from heliquad.sim.chip.pil.native_frames import DRAIN, TO_LOOP_END, TO_OUTPUTS
from heliquad.sim.chip.pil.program import FRAMES_VARIABLE
from heliquad.sim.chip.pil.pty import Pty
from heliquad.sim.plant.tf_plant import TfPlant
from heliquad.sim.rig.setup import SilConfig

pytestmark = pytest.mark.pil
MAV = dialect()
ROLL = ((28.19,), (1.0, 5.13, 22.93))
#: A bound on a hang (a reply that never comes), never a measure: a reply takes milliseconds.
REPLY_WAIT_S = 30.0
#: The roll rig's rotors (the paper's vehicle).
ROTORS = 5
#: A loop's period in core cycles (5 ms at 120 MHz).
PERIOD_CYCLES = 600_000


def _fly(path: str, link: str, out, monkeypatch):
    monkeypatch.setenv(FRAMES_VARIABLE, path)         # the drop-in inherits it
    cfg = SilConfig(axis="roll", num=ROLL[0], den=ROLL[1], inject="mixer", freq_hz=2.0,
                    amplitude=0.05, cycles=6, fade_cycles=1, firmware_link=link,
                    **image_for("teensy35"))
    return run_sil(cfg, str(out / f"{path}-{link}"), progress=lambda *_: None)


def _loops_and_native(summary: str) -> tuple:
    words = summary.replace(",", "").replace("(", "").split()
    return int(words[words.index("loops") - 1]), int(words[words.index("frames") - 1])


@pytest.mark.parametrize("link", ["usb", "uart"])
def test_an_experiment_logs_the_same_bytes_through_either_path(link, tmp_path, monkeypatch):
    runs = {path: _fly(path, link, tmp_path, monkeypatch) for path in ("python", "native")}
    py, nat = runs["python"], runs["native"]
    with open(py.csv_path, "rb") as a, open(nat.csv_path, "rb") as b:
        assert a.read() == b.read()
    messages = {path: [(m.get_type(), repr(m)) for _, m in read_tlog(r.tlog_path, MAV)]
                for path, r in runs.items()}
    assert len(messages["python"]) > 1000
    assert messages["python"] == messages["native"]
    loops, native = _loops_and_native(nat.firmware_summary)
    assert native > 0.8 * loops                      # most frames were the native path's
    assert _loops_and_native(py.firmware_summary) == (loops, 0)
    assert py.firmware_summary.split(";")[1] == nat.firmware_summary.split(";")[1]


class _Bench:
    """A drop-in served in a thread behind its two ptys, stepped frame by frame from here as
    the simulator steps it, keeping every reply's and the telemetry's raw bytes."""

    def __init__(self, tmp_path, native: bool):
        import teensy_image

        board = PilBoard(str(teensy_image.image().elf), link="usb")
        board.boot()
        # Python events in the middle of frames the native path would run: each hands its
        # frame over to Python there, before the reply or after it (one per frame, 0.1 ms
        # further into the loop each time, past the step's outputs).
        m, self.events = board.machine, []
        start = m.now() + 150 * PERIOD_CYCLES
        for k in range(50):
            m.at(start + k * (PERIOD_CYCLES + PERIOD_CYCLES // 50),
                 lambda k=k: self.events.append((k, m.now())), scaled=False)
        self.sim, self.tel = Pty(str(tmp_path / "sim")), Pty(str(tmp_path / "tel"))
        self.drop_in = DropIn(board, self.sim, self.tel, idle_timeout_s=60, native=native)
        self.exit = []
        self.thread = threading.Thread(target=lambda: self.exit.append(self.drop_in.serve()))
        self.sim_fd = os.open(self.sim.slave_path, os.O_RDWR | os.O_NOCTTY)
        self.tel_fd = os.open(self.tel.slave_path, os.O_RDWR | os.O_NOCTTY | os.O_NONBLOCK)
        for fd in (self.sim_fd, self.tel_fd):
            tty.setraw(fd)
        self.codec = Codec(MAV, system_id=1, component_id=MAV.MAV_COMP_ID_IMU)
        self.framer = Framer(Codec(MAV, system_id=1))
        self.replies, self.telemetry, self.sync_ends = [], bytearray(), []
        self.thread.start()

    def frame(self, n: int, fifo: bytes, kind: int, rc, sync=False, fault=0):
        self.codec.seq = n                     # a resent frame is the same bytes
        os.write(self.sim_fd, self.codec.encode(MAV.MAVLINK_MSG_ID_HQ_SENSOR_FRAME, {
            "time_us": n * 5000, "frame": n, "fifo_kind": kind, "fifo_len": len(fifo),
            "sync": int(sync), "rc_us": list(rc), "imu_fault": fault,
            "fifo": list(fifo) + [0] * (168 - len(fifo))}))
        while True:
            ready, _, _ = select.select([self.sim_fd], [], [], REPLY_WAIT_S)
            assert ready, f"no reply to frame {n}"
            for msgid, packet, payload in self.framer.feed(os.read(self.sim_fd, 4096)):
                if msgid == MAV.MAVLINK_MSG_ID_HQ_ACTUATOR_FRAME:
                    self.replies.append(packet)
                    self.take_telemetry()
                    if sync:     # where its drain ended (the drop-in waits for a frame now)
                        self.sync_ends.append((n, self.drop_in.board.machine.now()))
                    return self.framer.codec.decode(msgid, payload)

    def events_after_tick(self, frame: int, first: int):
        """Python events every 0.1 ms for 2 ms from ``first`` tenths of a millisecond after
        the board's next SysTick: after the step of the frame sent next (a sync frame: in
        its drain). Made right after a sync frame's reply, when the drop-in's thread, on
        either path, has finished that frame and runs no board until the next one."""
        m = self.drop_in.board.machine
        tick = self.drop_in.board.board.chip.scs.systick.zero_at
        for j in range(20):
            m.at(tick + (first + j) * PERIOD_CYCLES // 50,
                 lambda k=(frame, j): self.events.append((k, m.now())), scaled=False)

    def take_telemetry(self):
        try:
            while True:
                self.telemetry += os.read(self.tel_fd, 65536)
        except BlockingIOError:
            pass

    def uplink(self, data: bytes):
        os.write(self.tel_fd, data)

    def close(self):
        Stop.requested = True
        try:
            self.thread.join(REPLY_WAIT_S)
        finally:
            Stop.requested = False
        assert not self.thread.is_alive() and self.exit == [0]
        self.take_telemetry()
        for fd in (self.sim_fd, self.tel_fd):
            os.close(fd)
        self.sim.close()
        self.tel.close()


def _session(bench: _Bench) -> None:
    """Arming, a hover on the roll plant, a stick change, sync frames, a resent frame, an IMU
    overflow, and a ground station's heartbeats and a parameter request on the uplink."""
    plant = TfPlant("roll", *ROLL, 0.005)
    mav = MAV.MAVLink(None, srcSystem=255, srcComponent=190)
    rc = [1500, 1500, 1000, 1500, 1000, 1000, 0, 0]
    kind = MAV.HQ_SENSOR_NONE
    for n in range(1, 241):
        rc[4] = 2000 if n >= 10 else 1000
        rc[2] = 1400 if n >= 20 else 1000
        rc[0] = 1500 + int(60 * math.sin(n / 15.0)) if 120 <= n < 160 else 1500
        if n in (30, 90, 180):
            bench.uplink(mav.heartbeat_encode(MAV.MAV_TYPE_GCS, MAV.MAV_AUTOPILOT_INVALID,
                                              0, 0, 0).pack(mav))
        if n == 100:
            bench.uplink(mav.param_request_list_encode(1, 1).pack(mav))
        fault = MAV.HQ_IMU_FAULT_OVERFLOW if n == 70 else MAV.HQ_IMU_FAULT_NONE
        if n in (200, 240):
            bench.events_after_tick(n, 13 if n == 200 else 9)
        sync = n % 40 == 0 or n in (199, 239)     # before 200 and 240: see events_after_tick
        reply = bench.frame(n, plant.fifo(kind), kind, rc, sync=sync, fault=fault)
        if n == 45:
            assert bench.frame(n, plant.fifo(kind), kind, rc).frame == n     # resent
        kind = reply.sensor_kind
        plant.step_motors(reply.motor[:reply.motor_count])


def test_replies_and_telemetry_are_the_python_paths_to_the_byte(tmp_path):
    out = {}
    for native in (False, True):
        (tmp_path / str(native)).mkdir()
        bench = _Bench(tmp_path / str(native), native)
        try:
            _session(bench)
        finally:
            bench.close()
        out[native] = (bench.replies, bytes(bench.telemetry), bench.drop_in, bench.events,
                       bench.sync_ends)
    assert len(out[True][0]) == 241 and len(out[True][1]) > 20_000
    assert out[True][0] == out[False][0]
    assert out[True][1] == out[False][1]
    assert len(out[True][3]) >= 70 and out[True][3] == out[False][3]
    assert len(out[True][4]) == 8 and out[True][4] == out[False][4]
    drop_in = out[True][2]
    assert 180 < drop_in.native.frames.frames < 240      # the plain frames, not the others
    finished = drop_in.native.finished                   # those the events handed over
    assert finished[TO_OUTPUTS] >= 30 and finished[TO_LOOP_END] >= 1 and finished[DRAIN] >= 1
    assert drop_in.repeated == out[False][2].repeated == 1


def _hover(bench: _Bench, frames: int, first: int = 1, after_sync=None) -> list:
    """Arming and a hover; ``after_sync(n)`` is called after each sync frame's reply (the
    drop-in then runs no board until the next frame, on either path)."""
    plant = TfPlant("roll", *ROLL, 0.005)
    rc = [1500, 1500, 1000, 1500, 1000, 1000, 0, 0]
    kind, replies = MAV.HQ_SENSOR_NONE, []
    for n in range(first, first + frames):
        rc[4] = 2000 if n >= 10 else 1000
        rc[2] = 1400 if n >= 20 else 1000
        reply = bench.frame(n, plant.fifo(kind), kind, rc, sync=n % 40 == 0)
        if n % 40 == 0 and after_sync is not None:
            after_sync(n)
        kind = reply.sensor_kind
        plant.step_motors(reply.motor[:ROTORS])      # none while a rebooted board starts
        replies.append(reply)
    return replies


def test_a_board_the_native_path_cannot_run_is_served_by_the_python_path(tmp_path):
    # Every access logged (a trace): the native path stands aside, and every frame is still
    # answered, none of them natively (it must not take turns that do nothing instead).
    bench = _Bench(tmp_path, native=True)
    bench.drop_in.board.machine.trace_enabled = True
    try:
        assert len(_hover(bench, 30)) == 30
    finally:
        bench.close()
    assert bench.drop_in.native.frames.frames == 0 and bench.drop_in.frames == 30


def _spin_at(board) -> int:
    """A branch to itself in the image (enter_bootloader's wait for the reset): the board's
    loop hangs there and the watchdog resets the chip."""
    image = board.machine.image
    sym = image.symbol("_ZN2hq6teensy16enter_bootloaderERNS0_10Ftm0MotorsERNS0_12UsbCdcSerialE")
    code = board.machine.read(sym.address, sym.size)
    at = next(i for i in range(0, len(code) - 1, 2) if code[i:i + 2] == b"\xfe\xe7")
    return sym.address + at


def test_a_watchdog_reset_inside_a_native_frame_reboots_the_board_as_in_python(tmp_path):
    # The board's core sent into a branch to itself between frames 40 and 41: the next
    # frame's run spins until the watchdog resets the chip, in the native run (which hands
    # the frame over with the reset) or in Python's; the board reboots and flies on, and
    # the replies are the same. Then a Python event does it in the middle of frame 131:
    # handed over at the event, reset in Python's run of the rest.
    out = {}
    for native in (False, True):
        (tmp_path / str(native)).mkdir()
        bench = _Bench(tmp_path / str(native), native)
        board = bench.drop_in.board
        m, spin = board.machine, _spin_at(board)

        def hang(n):
            if n == 40:
                m.set_reg("pc", spin | 1)
            if n == 120:                   # after the reboot (a reset drops every event)
                m.at(m.now() + 10 * PERIOD_CYCLES + PERIOD_CYCLES // 2,
                     lambda: m.set_reg("pc", spin | 1), scaled=False)
        try:
            _hover(bench, 200, after_sync=hang)
        finally:
            bench.close()
        out[native] = (bench.replies, board.resets, bench.drop_in.native)
    assert out[True][1] == out[False][1] == 2
    assert out[True][0] == out[False][0]
    assert out[True][2].finished[TO_OUTPUTS] >= 2
