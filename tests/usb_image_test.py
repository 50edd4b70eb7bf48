"""The Teensy 3.5 image's own USB port, in the emulated chip with the USB host model
(sim/chip/usb.py, usb_host.py): what a computer meets when the board is plugged in.

* Enumeration: the image answers the Linux sequence; its descriptors say what
  teensy_loader_cli and the cdc_acm driver expect (Teensyduino's USB Serial IDs, heliquad's
  strings, a serial number from the chip's unique ID, a CDC-ACM function), read by the
  project's parser and by an independent one (usb-protocol, from PyPI).
* MAVLink over the port: whole messages with good checksums; commands in on USB answered
  on USB; HQ_FW_STATUS names its link and counts both links' bytes.
* A host that stops reading: the loop keeps its rate, drops are counted on USB only, and
  the stream resumes with whole messages.
* 134 baud, as `stty 134` (7 bytes) and teensy_loader_cli's reboot request (1 byte) send
  it: disarmed, the image stops the motors and halts on BKPT (the bootloader chip's cue);
  armed, it refuses and says so, and the motors keep their commands.
"""

from __future__ import annotations

import pathlib
import sys

import pytest

from heliquad.sim.base.firmware_facts import USB_IDENTITY, usb_serial_number
from heliquad.sim.chip import Teensy35
from heliquad.sim.chip.usb_host import UsbHost, settle

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parent))
import teensy35_boot_test as boot  # noqa: E402

pytestmark = pytest.mark.pil

EMULATED_UID = (0x0000_4851, 0x0045_4D55, 0x4D4B_3634, 0x0000_0001)
LINUX_SEQUENCE = [
    ("GET_DESCRIPTOR(device)", 64), ("SET_ADDRESS", 0), ("GET_DESCRIPTOR(device)", 18),
    ("GET_DESCRIPTOR(configuration)", 9), ("GET_DESCRIPTOR(configuration)", 75),
    ("GET_DESCRIPTOR(string 0)", 255), ("GET_DESCRIPTOR(string 2)", 255),
    ("GET_DESCRIPTOR(string 1)", 255), ("GET_DESCRIPTOR(string 3)", 255),
    ("SET_CONFIGURATION", 0)]


def _plugged_in(uid=None, *, open_port=True):
    """The image booted with a host on its USB port, enumerated (and the port opened)."""
    boot.require_image()
    pytest.importorskip("heliquad._firmware")
    board = Teensy35(boot.IMAGE, uid=uid)
    host = UsbHost(board.chip)
    assert board.run_to_loop(1, instructions=boot.BOOT_BUDGET).reason == "loop"
    settle(host, lambda s: board.run(seconds=s), timeout_s=1.0)
    if open_port:
        host.open()
        settle(host, lambda s: board.run(seconds=s), timeout_s=1.0)
    return board, host


def _messages(data: bytes):
    """Every MAVLink message in data, and the count of bytes the parser could not use."""
    from heliquad.sim.base.dialect import dialect
    mav = dialect()
    parser = mav.MAVLink(None)
    parser.robust_parsing = True
    out = []
    for m in parser.parse_buffer(data) or []:
        out.append(m)
    bad = [m for m in out if m.get_type() == "BAD_DATA"]
    return [m for m in out if m.get_type() != "BAD_DATA"], bad


def test_the_image_enumerates_as_linux_does_and_says_who_it_is():
    board, host = _plugged_in(open_port=False)
    import struct
    asked = [(r.request, struct.unpack("<H", r.setup[6:8])[0]) for r in host.transfers]
    assert asked == LINUX_SEQUENCE
    assert all(r.status == "ok" for r in host.transfers)
    ident = host.identity()
    d = ident.device
    assert (d.vid, d.pid, d.ep0_max_packet) == (USB_IDENTITY.vid, USB_IDENTITY.pid, 64)
    assert ident.strings == {1: USB_IDENTITY.manufacturer, 2: USB_IDENTITY.product,
                             3: usb_serial_number(EMULATED_UID)}
    comm, data = ident.configuration.interfaces
    assert (comm.interface_class, comm.interface_subclass) == (2, 2)      # CDC, ACM
    assert [f.name for f in comm.functional] == ["header", "call management",
                                                 "abstract control management", "union"]
    assert data.interface_class == 0x0A                                   # CDC data
    assert [(e.address, e.transfer_type, e.max_packet)
            for e in comm.endpoints + data.endpoints] == \
        [(0x81, "interrupt", 8), (0x02, "bulk", 64), (0x82, "bulk", 64)]


def test_the_descriptors_read_the_same_with_an_independent_parser():
    standard = pytest.importorskip("usb_protocol.types.descriptors.standard")
    board, host = _plugged_in(open_port=False)
    dev = standard.DeviceDescriptor.parse(host.device_bytes)
    assert (dev.idVendor, dev.idProduct, dev.bMaxPacketSize0) == (0x16C0, 0x0483, 64)
    assert (dev.iManufacturer, dev.iProduct, dev.iSerialNumber) == (1, 2, 3)
    cfg = standard.ConfigurationDescriptor.parse(host.config_bytes[:9])
    assert (cfg.wTotalLength, cfg.bNumInterfaces) == (len(host.config_bytes), 2)
    endpoints, at = [], 0
    raw = host.config_bytes
    while at < len(raw):
        if raw[at + 1] == 5:
            ep = standard.EndpointDescriptor.parse(raw[at:at + 7])
            endpoints.append((ep.bEndpointAddress, ep.bmAttributes & 3, ep.wMaxPacketSize))
        at += raw[at]
    assert endpoints == [(0x81, 3, 8), (0x02, 2, 64), (0x82, 2, 64)]


def test_two_chips_with_different_unique_ids_give_different_serial_numbers():
    other = (0x0012_3456, 0x789A_BCDE, 0xF012_3456, 0x789A_BCDE)
    _, a = _plugged_in(open_port=False)
    _, b = _plugged_in(other, open_port=False)
    assert a.strings[3] == usb_serial_number(EMULATED_UID)
    assert b.strings[3] == usb_serial_number(other) == "00123456789ABCDEF0123456789ABCDE"


def test_mavlink_over_usb_whole_messages_answers_and_per_link_figures():
    from heliquad.sim.base.dialect import dialect
    mav = dialect()
    board, host = _plugged_in()
    host.take_received()
    gcs = mav.MAVLink(None, srcSystem=255, srcComponent=190)
    ask = gcs.command_long_encode(1, 1, mav.MAV_CMD_COMPONENT_ARM_DISARM, 0, 1, 0, 0, 0, 0, 0, 0)
    host.send(ask.pack(gcs))
    board.run(seconds=1.5)
    usb, bad = _messages(host.take_received())
    assert not bad, bad[:3]
    kinds = {m.get_type() for m in usb}
    assert {"HEARTBEAT", "ATTITUDE", "HQ_SYSID_SAMPLE", "HQ_FW_STATUS"} <= kinds, kinds
    acks = [m for m in usb if m.get_type() == "COMMAND_ACK"]
    assert [(a.command, a.result) for a in acks] == \
        [(mav.MAV_CMD_COMPONENT_ARM_DISARM, mav.MAV_RESULT_DENIED)]   # answered on USB
    uart, _ = _messages(board.take_telemetry())
    assert not [m for m in uart if m.get_type() == "COMMAND_ACK"], "the ask came on USB"
    status = [m for m in usb if m.get_type() == "HQ_FW_STATUS"][-1]
    assert status.link_id == mav.HQ_LINK_USB
    assert status.link_bytes[mav.HQ_LINK_USB] > 0 and status.link_bytes[mav.HQ_LINK_UART0] > 0
    assert list(status.link_dropped) == [0, 0]
    uart_status = [m for m in uart if m.get_type() == "HQ_FW_STATUS"][-1]
    assert uart_status.link_id == mav.HQ_LINK_UART0
    seqs = [m.get_seq() for m in usb]
    assert all((b - a) % 256 == 1 for a, b in zip(seqs, seqs[1:])), "USB's own sequence"


class Flying:
    """The image on the simulated rig's inputs (an IMU sample and the RC pulses every loop, as
    the processor-in-the-loop drop-in gives them), with a host on its USB port and a ground
    station's HEARTBEAT on USB every 40 loops once the port is open."""

    RC_LOW = [1500, 1500, 1000, 1500, 2000, 1000]     # arm switch high, throttle low
    RC_MID = [1500, 1500, 1500, 1500, 2000, 1000]

    def __init__(self):
        from heliquad.sim.base.dialect import dialect
        from heliquad.sim.chip.pil.board import PilBoard
        from heliquad.sim.sensor.mpu6050_packets import raw_packet
        boot.require_image()
        pytest.importorskip("heliquad._firmware")
        self.mav = dialect()
        self.pil = PilBoard(str(boot.IMAGE), link="uart")     # its USB port: this test's own host
        self.host = UsbHost(self.pil.board.chip)
        self.pil.boot()
        self.sample = raw_packet([0.0, 0.0, 0.0], [0.0, 0.0, -9.80665])
        self.gcs = self.mav.MAVLink(None, srcSystem=255, srcComponent=190)
        self.frames = 0
        self.fly(200, self.RC_LOW)                       # enumerated, RC and IMU live
        self.host.open()
        self.fly(40, self.RC_LOW)

    def fly(self, n, rc=None):
        out = []
        heartbeat = self.gcs.heartbeat_encode(self.mav.MAV_TYPE_GCS,
                                              self.mav.MAV_AUTOPILOT_INVALID, 0, 0, 0)
        for _ in range(n):
            if self.frames % 40 == 0 and self.host.configured:
                self.host.send(heartbeat.pack(self.gcs))
            out.append(self.pil.frame(self.sample, False, rc or self.RC_LOW, 0, sync=False))
            self.frames += 1
        return out

    def arm(self):
        arm = self.gcs.command_long_encode(1, 1, self.mav.MAV_CMD_COMPONENT_ARM_DISARM, 0,
                                           1, 0, 0, 0, 0, 0, 0)
        self.host.send(arm.pack(self.gcs))
        self.fly(20)
        assert self.pil.report()[3] == 1, "armed"

    def overruns(self):
        return self.pil.report()[2]


def test_a_host_that_stops_reading_costs_messages_on_usb_only_never_a_loop():
    f = Flying()
    m = f.pil.machine
    f.host.take_received()
    f.host.reading = False
    start = m.cycles
    f.fly(1000)                                          # 5 s of loops not read
    assert (m.cycles - start) / 120e6 == pytest.approx(5.0, abs=0.006), "200 loops a second"
    assert f.overruns() == 0
    f.host.reading = True
    f.fly(300)
    usb, bad = _messages(f.host.take_received())
    assert not bad, bad[:3]
    assert {"HEARTBEAT", "ATTITUDE", "HQ_FW_STATUS"} <= {m.get_type() for m in usb}
    status = [m for m in usb if m.get_type() == "HQ_FW_STATUS"][-1]
    assert status.link_dropped[f.mav.HQ_LINK_USB] > 0
    assert status.link_dropped[f.mav.HQ_LINK_UART0] == 0
    assert status.loop_overruns == 0
    assert status.loop_cycles_max < 0.25 * 600_000, "a loop's work within a quarter of 5 ms"


@pytest.mark.parametrize("length", [7, 1], ids=["stty-7-bytes", "teensy-loader-1-byte"])
def test_134_baud_enters_the_bootloader_when_disarmed(length):
    board, host = _plugged_in()
    host.take_received()
    host.set_line_coding(134, length=length)
    stop = board.run(seconds=0.5)
    assert stop.reason == "bkpt", stop
    texts = [m.text for m in _messages(host.take_received())[0] if m.get_type() == "STATUSTEXT"]
    assert "entering the bootloader: disarmed, motors stopped" in texts
    assert all(pulse == pytest.approx(1.0e-3, abs=1e-6)
               for _, _, _, pulse in board.esc_outputs()), "the stop pulse on every ESC"


def test_other_line_codings_change_nothing():
    board, host = _plugged_in()
    for baud, length in ((115200, 7), (9600, 7), (134 + 256, 7)):
        host.set_line_coding(baud, length=length)
        settle(host, lambda s: board.run(seconds=s), timeout_s=1.0)
    assert board.run(seconds=0.3).reason != "bkpt"


def test_134_baud_is_refused_while_armed_and_the_motors_keep_flying():
    f = Flying()
    f.arm()
    f.fly(40, f.RC_MID)
    f.host.take_received()
    for length in (7, 1):
        f.host.set_line_coding(134, length=length)
        after = f.fly(60, f.RC_MID)
        assert all(armed for _, armed, _, _ in after)
        assert all(min(motors) > 0.05 for motors, _, _, _ in after), "no motor ever stopped"
    texts = [m.text for m in _messages(f.host.take_received())[0]
             if m.get_type() == "STATUSTEXT"]
    assert texts.count("bootloader refused: armed (disarm first)") == 2


@pytest.mark.parametrize("setup", [(0x00, 0, 2, b"\x01\x02"), (0x00, 8, 1, b"\x01"),
                                   (0x01, 10, 1, b"\x01"), (0x80, 5, 2, 2)],
                         ids=["GET_STATUS-out", "GET_CONFIGURATION-out", "GET_INTERFACE-out",
                              "SET_ADDRESS-in"])
def test_a_malformed_standard_request_is_stalled_and_the_port_goes_on(setup):
    """A standard request sent in the wrong direction, or with a data stage it has none of,
    is a request error (EP0 stalled) and never reaches the stack: TinyUSB would write such a
    request's OUT bytes into a returned function's stack frame. The next requests and the
    MAVLink stream are unharmed."""
    request_type, request, _, data = setup
    board, host = _plugged_in()
    host.control(request_type, request, 0, 0, data, name="malformed")
    settle(host, lambda s: board.run(seconds=s), timeout_s=1.0)
    assert host.transfers[-1].status == "stall"
    host.control(0x80, 8, 0, 0, 1, name="GET_CONFIGURATION")
    settle(host, lambda s: board.run(seconds=s), timeout_s=1.0)
    assert (host.transfers[-1].status, host.transfers[-1].received) == ("ok", b"\x01")
    host.take_received()
    board.run(seconds=1.2)
    usb, bad = _messages(host.take_received())
    assert not bad and "HEARTBEAT" in {m.get_type() for m in usb}


def test_a_sil_run_over_usb_gives_the_points_of_uart0(tmp_path):
    """The drop-in's two links (`--link usb|uart`): the same experiment read over the
    emulated USB port and over UART0 gives every sample (no sequence gap) and the same
    frequency-response point within 0.01 dB and 0.1 deg."""
    import math
    import numpy as np
    from heliquad.host.acquire.experiment import run_sil
    from heliquad.host.estimate.fsf import estimate_fsf
    from heliquad.host.records.run_csv import read_run_csv
    from heliquad.sim.rig.setup import SilConfig
    boot.require_image()
    pytest.importorskip("heliquad._firmware")
    points = {}
    for link in ("uart", "usb"):
        cfg = SilConfig(axis="roll", inject="mixer", freq_hz=1.0, amplitude=0.05, cycles=3,
                        fade_cycles=1, firmware="teensy35", firmware_image=str(boot.IMAGE),
                        firmware_link=link)
        r = run_sil(cfg, str(tmp_path / link), progress=lambda *_: None)
        assert r.seq_gaps == 0 and r.samples == 3 * 200, (link, r.seq_gaps, r.samples)
        fs, u, y = read_run_csv(r.csv_path)
        points[link] = estimate_fsf(u, y, fs)
    uart, usb = points["uart"], points["usb"]
    assert abs(20 * math.log10(usb.magnitude / uart.magnitude)) < 0.01
    assert abs(math.degrees(np.angle(usb.gain / uart.gain))) < 0.1


def test_parameters_list_and_set_over_the_emulated_usb_port(tmp_path):
    """`heliquad board --firmware teensy35 --link usb` publishes the board's USB port on its
    pty, and `heliquad params` lists and sets the image's parameters through it."""
    import os
    import subprocess
    import tool_runs
    boot.require_image()
    env = {**os.environ, "HQ_TEENSY35_ELF": str(boot.IMAGE)}
    with tool_runs.running_board(tmp_path, "--firmware", "teensy35", "--link", "usb",
                                 "--disarmed", env=env) as port:
        def params(*args):
            return subprocess.run([sys.executable, "-m", "heliquad.host.cli.parser", "params",
                                   "--port", str(port), *args], capture_output=True, text=True,
                                  timeout=tool_runs.HANG_GUARD_S, env=env)
        listed = params("list")
        assert listed.returncode == 0, listed.stderr
        names = [line.split()[0] for line in listed.stdout.splitlines()[2:]]
        assert "RATE_RLL_KC" in names and len(names) >= 40, listed.stdout
        changed = params("set", "EXC_MAX_DUR", "120")
        assert changed.returncode == 0 and changed.stdout.startswith("EXC_MAX_DUR: "), changed.stderr
        read = params("get", "EXC_MAX_DUR")
        assert read.stdout == "EXC_MAX_DUR 120\n", read.stderr


def test_armed_the_image_drives_eight_esc_outputs_those_past_its_rotors_at_the_stop_pulse():
    # FTM0's eight channels, pins 22, 23, 9, 10, 6, 20, 21, 5: the five rotors the image
    # flies get their thrust, the three past its rotor count the stop pulse (ESCn_MIN, 1 ms
    # by default), armed and flying as when disarmed.
    f = Flying()
    f.arm()
    flown = f.fly(40, f.RC_MID)
    assert f.pil.report()[7] == 5, "the rotor count the loop flies"
    assert all(len(motors) == 5 and min(motors) > 0.05 for motors, _, _, _ in flown)
    board = f.pil.board
    outputs = board.esc_outputs()
    assert [pin for pin, _, _, _ in outputs] == [22, 23, 9, 10, 6, 20, 21, 5]
    assert [sig for _, sig, _, _ in outputs] == [f"FTM0_CH{ch}" for ch in range(8)]
    assert all(period == pytest.approx(2.5e-3, abs=1e-9) for _, _, period, _ in outputs)
    pulses = [pulse for _, _, _, pulse in outputs]
    assert all(p > 1.05e-3 for p in pulses[:5]), pulses
    assert pulses[5:] == [pytest.approx(1.0e-3, abs=1e-9)] * 3, pulses
    assert f.pil.thrust()[5:] == [0.0, 0.0, 0.0]


def test_closing_reopening_and_re_enumerating_while_armed_keeps_the_vehicle_flying():
    """The host closes the port (DTR low) for 0.5 s and opens it again, then resets the bus
    and enumerates the board again, all while the vehicle is armed with its throttle up: it
    stays armed, no motor stops, the loop misses no tick, and what arrives after each is
    whole MAVLink."""
    f = Flying()
    f.arm()
    f.fly(40, f.RC_MID)
    f.host.close()
    f.fly(100, f.RC_MID)                               # closed: heartbeats still go out
    f.host.open()
    f.fly(60, f.RC_MID)
    f.host.take_received()
    f.host.bus_reset()                                 # reset, then the Linux enumeration
    f.host.open()
    flown = f.fly(200, f.RC_MID)
    assert all(armed for _, armed, _, _ in flown)
    assert all(min(motors) > 0.05 for motors, _, _, _ in flown), "no motor ever stopped"
    assert f.overruns() == 0
    assert [r.request for r in f.host.transfers[-12:-2]] == [n for n, _ in LINUX_SEQUENCE]
    usb, bad = _messages(f.host.take_received())
    assert not bad, bad[:3]
    assert {"HEARTBEAT", "ATTITUDE", "HQ_SYSID_SAMPLE"} <= {m.get_type() for m in usb}


def test_an_excitation_stops_by_the_host_heartbeat_rule_when_the_usb_host_goes_silent():
    """The ground station on USB starts an excitation, then its port closes and its
    heartbeats stop: the excitation stops by the host-heartbeat rule (1.5 s), as on any
    link."""
    f = Flying()
    f.arm()
    f.fly(40, f.RC_MID)
    start = f.gcs.hq_excitation_encode(1, 1, f.mav.HQ_EXCITATION_START, f.mav.HQ_AXIS_ROLL,
                                       f.mav.HQ_INJECTION_MIXER, 1.0, 0.05, 10, 1,
                                       f.mav.HQ_SIGNAL_SINE, [0] * 16, [0.0] * 16, [0.0] * 16)
    f.host.send(start.pack(f.gcs))
    f.fly(250, f.RC_MID)                               # past the fade-in's second
    assert f.pil.report()[6] == f.mav.HQ_EXCITATION_STATE_RUNNING
    f.host.close()
    for _ in range(400):                               # 2 s: no heartbeat at all
        f.pil.frame(f.sample, False, f.RC_MID, 0, sync=False)
    assert f.pil.report()[6] == f.mav.HQ_EXCITATION_STATE_IDLE


def test_a_ground_station_that_connects_30_s_after_boot_gets_the_boot_report_over_usb():
    from heliquad.sim.base.dialect import dialect
    mav = dialect()
    board, host = _plugged_in()
    host.reading = False                               # nobody reads for 30 s
    board.run(seconds=30.0)
    host.reading = True
    board.run(seconds=0.1)
    host.take_received()
    gcs = mav.MAVLink(None, srcSystem=255, srcComponent=190)
    host.send(gcs.heartbeat_encode(mav.MAV_TYPE_GCS, mav.MAV_AUTOPILOT_INVALID, 0, 0, 0)
              .pack(gcs))
    board.run(seconds=0.3)
    texts = [m.text for m in _messages(host.take_received())[0] if m.get_type() == "STATUSTEXT"]
    boot_lines = [t for t in texts if t.startswith("boot: ")]
    assert boot_lines[0] == "boot: reset by power-on", texts
    assert any(t.startswith("boot: params: ") for t in boot_lines)
    assert any(t.startswith("boot: IMU: ") for t in boot_lines)


def _usb_flight(reference: bool, loops: int):
    """The image booted with a host that enumerates it and opens its port, then ``loops``
    loops flown with the port read: what a run must reproduce exactly, with each loop's bytes
    received, when the last bulk IN poll was NAKed and the frame number, the USB0 registers
    the interrupt reads, all at the loop's cycle. ``reference``: every boundary attended
    outside unicorn, every peripheral access through Python, and the USB host's every poll
    made by its Python pump (``usb0.native`` off); and the Python events a loop made."""
    from heliquad.sim.sensor.mpu6050_packets import raw_packet
    boot.require_image()
    pytest.importorskip("heliquad._firmware")
    board = Teensy35(boot.IMAGE)
    m, usb = board.machine, board.chip.usb0
    if reference:
        m.core.inline_boundaries = False
        m.trace_enabled = True
        usb.native = False
    host = UsbHost(board.chip, debounce_s=0.0, open_port=True)
    sample = raw_packet([0.01, -0.02, 0.005], [0.0, 0.0, -9.80665])
    assert board.run_to_loop(1, instructions=boot.BOOT_BUDGET).reason == "loop"
    stamped, before = [], m.counts()["python_events"]
    for _ in range(loops):
        board.mpu.emu.push_fifo(sample, False)
        assert board.run_to_loop(board.loops + 1, instructions=1_000_000).reason == "loop"
        stamped.append((m.now(), host.take_received(), host.in_nak_cycle, host.frame,
                        [usb.peek(r) for r in ("ISTAT", "STAT", "ERRSTAT", "CTL", "ENDPT2")],
                        usb.odd))
    transfers = [(t.request, t.setup, t.received, t.status, t.start_s, t.end_s)
                 for t in host.transfers]
    run = (m.instructions, m.cycles, m.sleep_cycles, list(m.exception_log),
           sorted(m.exception_counts.items()), b"".join(s[1] for s in stamped), stamped,
           host.frame, transfers, board.loop_starts)
    return run, (m.counts()["python_events"] - before) / loops


def test_usb_runs_are_deterministic_and_the_native_paths_agree_with_the_reference():
    # The USB interrupt's register accesses, its NVIC writes (its IRQ masked and its
    # priority set around the stack's critical sections) and the host's NAKed bulk IN polls
    # are native on the fast path, Python's on the reference.
    first, python_events = _usb_flight(False, 40)
    assert _usb_flight(False, 40)[0] == first
    reference, reference_events = _usb_flight(True, 40)
    assert reference == first
    assert python_events < reference_events / 2, "the NAKed polls made natively"
    assert first[8][-1][0] == "SET_LINE_CODING" and len(first[5]) > 40 * 20
