"""The emulated USB0 controller (sim/chip/usb.py), the system MPU's rule for it (mpu.py), the
host model (usb_host.py) and the descriptor record (usb_descriptors.py), with no program: the
test plays the firmware's part through the registers and a buffer descriptor table it writes
in the emulated RAM, as the TinyUSB driver for this controller does.

* Register level: reset values, ISTAT write-1-to-clear, the IRQ line, the BDT rules (NAK
  while not owned, ACK with the write-back, DATA0/1 checking, the ODD ping-pong and
  CTL.ODDRST, STALL and a SETUP clearing it), bus reset, SOF, the MPU's grant to master 4.
* The host against a scripted CDC-ACM device: the Linux enumeration, its record, the
  descriptors parsed by the project and independently by the usb-protocol package, the
  cdc_acm requests, bulk both ways, a reader that stops reading, re-enumeration.
"""

from __future__ import annotations

import pathlib
import struct
import sys

import pytest

from heliquad.sim.chip import Fault, Mk64
from heliquad.sim.chip import usb_descriptors as desc
from heliquad.sim.chip.usb import ACK, NAK, PID_IN, PID_OUT, PID_SETUP, STALL
from heliquad.sim.chip.usb_host import UsbError, UsbHost, settle

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parent))
import teensy35_boot_test as boot  # noqa: E402

BDT = 0x2000_0000                   # 512-byte aligned, in SRAM_U
BUFFERS = BDT + 0x400
OWN, DATA1, DTS, BDT_STALL = 0x80, 0x40, 0x08, 0x04
USB_IRQ_EXCEPTION = 16 + 53
VID, PID = 0x16C0, 0x0483
STRINGS = {1: "heliquad", 2: "heliquad flight controller", 3: "EMU0001"}


def _device_descriptor():
    return struct.pack("<BBHBBBBHHHBBBB", 18, 1, 0x0200, 0xEF, 0x02, 0x01, 64, VID, PID,
                       0x0100, 1, 2, 3, 1)


def _config_descriptor():
    body = (bytes([8, 0x0B, 0, 2, 2, 2, 0, 0]) +                        # IAD
            bytes([9, 4, 0, 0, 1, 2, 2, 0, 0]) +                        # CDC comm interface
            bytes([5, 0x24, 0x00, 0x20, 0x01]) + bytes([5, 0x24, 0x01, 0x00, 0x01]) +
            bytes([4, 0x24, 0x02, 0x02]) + bytes([5, 0x24, 0x06, 0, 1]) +
            bytes([7, 5, 0x81, 3, 8, 0, 16]) +                          # notification IN
            bytes([9, 4, 1, 0, 2, 0x0A, 0, 0, 0]) +                     # CDC data interface
            bytes([7, 5, 0x02, 2, 64, 0, 0]) + bytes([7, 5, 0x82, 2, 64, 0, 0]))
    return struct.pack("<BBHBBBBB", 9, 2, 9 + len(body), 2, 1, 0, 0x80, 50) + body


def _string(i):
    if i == 0:
        return bytes([4, 3, 0x09, 0x04])
    text = STRINGS[i].encode("utf-16-le")
    return bytes([2 + len(text), 3]) + text


def _chip():
    chip = Mk64()
    boot._wdog_off(chip)
    sim = chip.sim
    boot._write(sim, "SCGC4", sim.v["SCGC4"] | sim.map["SCGC4"].bit("USBOTG"))
    # The USB clock: IRC48M through the USB clock select (SOPT2.USBSRC, PLLFLLSEL = 3).
    boot._write(sim, "SOPT2", sim.v["SOPT2"] | sim.map["SOPT2"].bit("USBSRC") | 3 << 16)
    return chip


def _w(chip, name, value):
    boot._write(chip.usb0, name, value)


def _r(chip, name):
    return chip.usb0.read_register(name)


def _bd_address(ep, tx, odd):
    return BDT | ep << 5 | tx << 4 | odd << 3


def _arm(chip, ep, tx, odd, buffer, count, data1, flags=DTS):
    m = chip.machine
    m.write(_bd_address(ep, tx, odd) + 4, struct.pack("<I", buffer))
    m.write(_bd_address(ep, tx, odd), struct.pack("<I", count << 16 | flags | OWN |
                                                  (DATA1 if data1 else 0)))


def _bd(chip, ep, tx, odd):
    return struct.unpack("<I", chip.machine.read(_bd_address(ep, tx, odd), 4))[0]


def _enable(chip, mpu_off=True):
    if mpu_off:
        boot._write(chip.mpu, "CESR", 0)
    _w(chip, "USBTRC0", 0x80)
    _w(chip, "USBTRC0", 0x40)
    for page, shift in (("BDTPAGE1", 8), ("BDTPAGE2", 16), ("BDTPAGE3", 24)):
        _w(chip, page, BDT >> shift & 0xFF)
    _w(chip, "USBCTRL", 0)
    _w(chip, "CTL", 1)
    _w(chip, "ENDPT0", 0x0D)


# ------------------------------------------------------------------ register level ----------

def test_reset_values_gate_and_the_write_1_to_clear_status():
    chip = Mk64()
    assert chip.machine.device_at(0x4007_2000) is chip.usb0 and chip.usb0.irq == 53
    assert not chip.usb0.clocked() and chip.usb0.gate_name() == "SIM_SCGC4.USBOTG"
    chip = _chip()
    assert [_r(chip, n) for n in ("PERID", "IDCOMP", "REV", "USBCTRL", "OBSERVE", "ISTAT")] \
        == [0x04, 0xFB, 0x33, 0xC0, 0x50, 0]
    chip.usb0.v["ISTAT"] = 0x0D
    _w(chip, "ISTAT", 0x08)
    assert _r(chip, "ISTAT") == 0x05, "only the bits written as 1 clear"
    _w(chip, "PERID", 0)
    assert _r(chip, "PERID") == 0x04
    _w(chip, "USBTRC0", 0x80)
    assert _r(chip, "USBTRC0") == 0 and _r(chip, "ISTAT") == 0, "USBRESET: reset values, reads 0"
    _w(chip, "CONTROL", 0x10)
    _w(chip, "USBCTRL", 0x00)
    assert _r(chip, "OBSERVE") == 0x80, "pull-up on, pull-downs off"


def test_irq_line_is_istat_and_inten():
    chip = _chip()
    m = chip.machine
    _enable(chip)
    chip.usb0.bus_reset(True)           # attached? no: nothing flagged without the pull-up
    assert _r(chip, "ISTAT") == 0
    _w(chip, "CONTROL", 0x10)
    chip.usb0.bus_reset(True)
    assert _r(chip, "ISTAT") & 0x01
    assert not m.irq_lines >> USB_IRQ_EXCEPTION & 1, "USBRSTEN clear: no request"
    _w(chip, "INTEN", 0x01)
    assert m.irq_lines >> USB_IRQ_EXCEPTION & 1
    _w(chip, "ISTAT", 0x01)
    assert not m.irq_lines >> USB_IRQ_EXCEPTION & 1
    chip.usb0.bus_reset(False)
    chip.usb0.sof(0x123)
    assert _r(chip, "ISTAT") & 0x04 and (_r(chip, "FRMNUMH"), _r(chip, "FRMNUML")) == (1, 0x23)


def test_bdt_nak_ack_writeback_toggles_and_ping_pong():
    chip = _chip()
    usb, m = chip.usb0, chip.machine
    _enable(chip)
    _w(chip, "CONTROL", 0x10)
    _w(chip, "ENDPT2", 0x1C)                        # TX, RX, no SETUP
    assert usb.token(PID_OUT, 0, 2, b"ab", False).handshake == NAK, "BD not owned"
    _arm(chip, 2, 0, 0, BUFFERS, 64, data1=False)
    tok = usb.token(PID_OUT, 0, 2, b"xy", True)
    assert tok.handshake == ACK and tok.commit is None, "wrong DATA1: ACKed and dropped"
    tok = usb.token(PID_OUT, 0, 2, b"hello", False)
    assert tok.handshake == ACK
    usb.complete(tok)
    assert m.read(BUFFERS, 5) == b"hello"
    word = _bd(chip, 2, 0, 0)
    assert not word & OWN and word >> 16 & 0x3FF == 5 and word >> 2 & 0xF == PID_OUT
    assert _r(chip, "STAT") == 2 << 4 and _r(chip, "ISTAT") & 0x08
    assert usb.token(PID_OUT, 0, 2, b"z", True).handshake == NAK, "now the ODD BD: not owned"
    _arm(chip, 2, 1, 0, BUFFERS + 64, 3, data1=True)    # IN, even
    m.write(BUFFERS + 64, b"abc")
    tok = usb.token(PID_IN, 0, 2)
    assert tok.handshake == ACK and tok.data1 and tok.data == b"abc"
    usb.complete(tok)
    assert _r(chip, "STAT") == 2 << 4 | 1 << 3
    _w(chip, "CTL", 0x03)                               # ODDRST
    _w(chip, "CTL", 0x01)
    assert usb.odd[2] == [0, 0]
    assert usb.token(PID_OUT, 1, 2, b"a", False).handshake is None, "another address"


def test_stall_and_a_setup_clearing_it():
    chip = _chip()
    usb = chip.usb0
    _enable(chip)
    _w(chip, "CONTROL", 0x10)
    _w(chip, "ENDPT0", 0x0F)                            # EPSTALL
    assert usb.token(PID_IN, 0, 0).handshake == STALL and _r(chip, "ISTAT") & 0x80
    _arm(chip, 0, 0, 0, BUFFERS, 8, data1=False)
    tok = usb.token(PID_SETUP, 0, 0, bytes(8), False)
    assert tok.handshake == ACK and _r(chip, "ENDPT0") == 0x0D
    usb.complete(tok)
    assert _r(chip, "CTL") & 0x20, "SETUP sets TXSUSPENDTOKENBUSY"
    _w(chip, "ISTAT", 0xFF)
    _arm(chip, 0, 1, 0, BUFFERS, 0, data1=True, flags=DTS | BDT_STALL)
    assert usb.token(PID_IN, 0, 0).handshake == NAK, "TXSUSPENDTOKENBUSY: NAK"
    _w(chip, "CTL", 0x01)
    assert usb.token(PID_IN, 0, 0).handshake == STALL and _bd(chip, 0, 1, 0) & OWN


def test_dma_outside_ram_or_not_granted_by_the_mpu_is_a_fault():
    chip = _chip()
    usb = chip.usb0
    _enable(chip, mpu_off=False)
    _w(chip, "CONTROL", 0x10)
    with pytest.raises(Fault, match="bus master 4"):
        usb.token(PID_SETUP, 0, 0, bytes(8), False)
    boot._write(chip.mpu, "RGDAAC0", chip.mpu.v["RGDAAC0"] | 3 << 24)   # M4RE | M4WE
    _arm(chip, 0, 0, 0, 0x1000_0000, 8, data1=False)
    with pytest.raises(Fault, match="not RAM"):
        usb.complete(usb.token(PID_SETUP, 0, 0, bytes(8), False))


# ------------------------------------------------------------------ a scripted device -------

class ScriptedDevice:
    """The firmware's part, from Python: TinyUSB's order of register and BDT writes, a
    CDC-ACM function answering the standard requests and echoing bulk OUT to bulk IN."""

    def __init__(self, chip):
        self.chip, self.m = chip, chip.machine
        self.odd = {}
        self.address = 0
        self.requests = []
        self.received = bytearray()
        self.status_in = False
        self.out2 = self.in2 = 0
        _enable(chip)
        _w(chip, "ISTAT", 0xFF)
        _w(chip, "INTEN", 0x09)
        _w(chip, "CONTROL", 0x10)

    def _next(self, ep, tx):
        return self.odd.get((ep, tx), 0)

    def _arm(self, ep, tx, data, data1):
        odd = self._next(ep, tx)
        buffer = BUFFERS + ep * 0x100 + tx * 0x80 + odd * 0x40
        if tx:
            self.m.write(buffer, data)
        _arm(self.chip, ep, tx, odd, buffer, len(data) if tx else 64, data1)

    def service(self):
        istat = _r(self.chip, "ISTAT")
        if istat & 0x01:
            _w(self.chip, "ISTAT", 0xFF)
            _w(self.chip, "ADDR", 0)
            _w(self.chip, "CTL", 0x03)
            self.odd.clear()
            self._arm(0, 0, b"", False)
            _w(self.chip, "CTL", 0x01)
            return
        if istat & 0x08:
            stat = _r(self.chip, "STAT")
            _w(self.chip, "ISTAT", 0x08)
            self._token(stat >> 4, stat >> 3 & 1, stat >> 2 & 1)

    def _token(self, ep, tx, odd):
        word = _bd(self.chip, ep, tx, odd)
        self.odd[(ep, tx)] = odd ^ 1
        pid, n = word >> 2 & 0xF, word >> 16 & 0x3FF
        buffer = struct.unpack("<I", self.m.read(_bd_address(ep, tx, odd) + 4, 4))[0]
        if pid == PID_SETUP:
            self._setup(self.m.read(buffer, 8))
            _w(self.chip, "CTL", 0x01)
        elif ep == 2 and not tx:
            self.received += self.m.read(buffer, n)
            self.out2 += 1
            self._arm(2, 0, b"", self.out2 & 1)
        elif ep == 0 and tx and self.status_in:     # the status stage's IN ZLP went
            self.status_in = False
            if self.address:
                _w(self.chip, "ADDR", self.address)
                self.address = 0
            self._arm(0, 0, b"", False)             # the next SETUP
        elif ep == 0 and not tx and n:              # an OUT data stage
            self.requests[-1] += (self.m.read(buffer, n),)
            self._status_in()
        elif ep == 0 and not tx:                    # the status stage's OUT ZLP
            self._arm(0, 0, b"", False)

    def _status_in(self):
        self.status_in = True
        self._arm(0, 1, b"", True)

    def _setup(self, packet):
        request_type, request, value, index, length = struct.unpack("<BBHHH", packet)
        self.requests.append((request_type, request, value, index, length))
        if request == 6:
            kind, i = value >> 8, value & 0xFF
            data = {1: _device_descriptor(), 2: _config_descriptor()}.get(kind) \
                if kind != 3 else _string(i)
            data = data[:length]
            self._arm(0, 1, data[:64], True)
            if len(data) >= 64:
                self.odd[(0, 1)] ^= 1
                self._arm(0, 1, data[64:128], False)
                self.odd[(0, 1)] ^= 1
            self._arm(0, 0, b"", True)              # the status stage's OUT ZLP
            return
        if request == 5:
            self.address = value
        if request == 9:
            self.out2 = self.in2 = 0
            _w(self.chip, "ENDPT2", 0x1D)           # bulk both ways, no SETUP
            self._arm(2, 0, b"", False)
        if request_type & 0x80 == 0 and length:
            self._arm(0, 0, b"", True)              # the data stage's OUT
            return
        self._status_in()

    def send(self, data):
        self._arm(2, 1, data, self.in2 & 1)
        self.in2 += 1


def _run(chip, device):
    m = chip.machine
    step = m.cycles_after(20e-6) - m.now()

    def run_for(seconds):
        end = m.cycles_after(seconds)
        while m.now() < end:
            m.advance(min(step, end - m.now()))
            device.service()
    return run_for


def _enumerated():
    chip = _chip()
    host = UsbHost(chip)
    device = ScriptedDevice(chip)
    run_for = _run(chip, device)
    settle(host, run_for, timeout_s=2.0)
    return chip, host, device, run_for


def test_the_host_enumerates_as_linux_does_and_records_every_transfer():
    chip, host, device, _ = _enumerated()
    asked = [(r.request, struct.unpack("<H", r.setup[6:8])[0], r.status) for r in host.transfers]
    assert asked == [
        ("GET_DESCRIPTOR(device)", 64, "ok"), ("SET_ADDRESS", 0, "ok"),
        ("GET_DESCRIPTOR(device)", 18, "ok"), ("GET_DESCRIPTOR(configuration)", 9, "ok"),
        ("GET_DESCRIPTOR(configuration)", len(_config_descriptor()), "ok"),
        ("GET_DESCRIPTOR(string 0)", 255, "ok"), ("GET_DESCRIPTOR(string 2)", 255, "ok"),
        ("GET_DESCRIPTOR(string 1)", 255, "ok"), ("GET_DESCRIPTOR(string 3)", 255, "ok"),
        ("SET_CONFIGURATION", 0, "ok")]
    assert [r[1] for r in device.requests] == [6, 5, 6, 6, 6, 6, 6, 6, 6, 9]
    assert host.transfers[0].received == _device_descriptor()
    assert host.configured and _r(chip, "ADDR") == 1
    ident = host.identity()
    assert (ident.device.vid, ident.device.pid, ident.device.ep0_max_packet) == (VID, PID, 64)
    assert ident.strings == STRINGS
    comm, data = ident.configuration.interfaces
    assert (comm.interface_class, comm.interface_subclass) == (2, 2)
    assert [f.name for f in comm.functional] == ["header", "call management",
                                                 "abstract control management", "union"]
    assert [(e.address, e.transfer_type, e.max_packet) for e in comm.endpoints + data.endpoints] \
        == [(0x81, "interrupt", 8), (0x02, "bulk", 64), (0x82, "bulk", 64)]
    assert any("VID 0x16C0, PID 0x0483" in line for line in desc.describe(ident))


def test_descriptors_agree_with_an_independent_parser():
    usb_protocol = pytest.importorskip("usb_protocol.types.descriptors.standard")
    _, host, _, _ = _enumerated()
    parsed = usb_protocol.DeviceDescriptor.parse(host.device_bytes)
    ident = host.identity()
    d = ident.device
    assert (parsed.idVendor, parsed.idProduct, parsed.bMaxPacketSize0, parsed.iProduct) == \
        (d.vid, d.pid, d.ep0_max_packet, d.i_product)
    assert parsed.bcdUSB == d.bcd_usb / 256         # usb-protocol gives BCD 0x0200 as 2.0
    config = usb_protocol.ConfigurationDescriptor.parse(host.config_bytes[:9])
    assert (config.wTotalLength, config.bNumInterfaces) == \
        (ident.configuration.total_length, len(ident.configuration.interfaces))


def test_cdc_requests_and_bulk_both_ways_with_a_reader_that_stops():
    chip, host, device, run_for = _enumerated()
    host.open(115200)
    host.set_line_coding(134, length=1)
    host.close()
    settle(host, run_for, timeout_s=1.0)
    cdc = [r for r in device.requests if r[0] == 0x21]
    assert cdc[0][1:3] == (0x22, 3) and cdc[1][1] == 0x20 and cdc[1][5] == \
        struct.pack("<IBBB", 115200, 0, 0, 8)
    assert cdc[2][4] == 1 and cdc[2][5] == bytes([134]) and cdc[3][1:3] == (0x22, 0)
    host.send(bytes(range(150)))
    run_for(0.01)
    assert bytes(device.received) == bytes(range(150)), "three OUT packets, toggles agreed"
    device.send(b"telemetry")
    run_for(0.003)
    assert host.take_received() == b"telemetry"
    host.reading = False
    device.send(b"more")
    run_for(0.01)
    assert host.take_received() == b"" and _bd(chip, 2, 1, device._next(2, 1)) & OWN, \
        "not reading: the IN BD stays owned"
    host.reading = True
    host.send(b"")
    run_for(0.003)
    assert host.take_received() == b"more"


def test_a_bus_reset_re_enumerates_and_a_silent_device_times_out():
    chip, host, device, run_for = _enumerated()
    host.bus_reset()
    settle(host, run_for, timeout_s=2.0)
    assert [r.request for r in host.transfers].count("SET_ADDRESS") == 2 and host.configured
    _w(chip, "CTL", 0)                                  # the SIE stops answering
    host.open()
    with pytest.raises(UsbError, match="no response"):
        settle(host, run_for, timeout_s=1.0)


def _grant_revoked_during_an_in_packet(native: bool):
    """A bulk IN packet on the bus (the core's, or Python's with ``native`` off) while the
    image takes master 4's write grant away: what the BD's write-back at its end raises."""
    chip, host, device, run_for = _enumerated()
    chip.usb0.native = native
    m, mpu = chip.machine, chip.mpu
    word2 = mpu.v["RGD0_WORD2"]
    granted = word2 | mpu.bit("RGDAAC0", "M4RE") | mpu.bit("RGDAAC0", "M4WE")
    boot._write(mpu, "RGDAAC0", granted)
    boot._write(mpu, "CESR", mpu.bit("CESR", "VLD"))
    run_for(0.002)
    device.send(b"telemetry")
    step = m.cycles_after(1e-6) - m.now()
    while host._in_flight:                  # a NAKed poll still on the bus
        m.advance(step)
    while not host._in_flight:              # the next poll: the packet
        m.advance(step)
    assert m.core.usb0.host.flight_data == native, "the core sent it (native path)"
    boot._write(mpu, "RGDAAC0", granted & ~mpu.bit("RGDAAC0", "M4WE"))
    with pytest.raises(Fault) as fault:
        m.advance(m.cycles_after(100e-6) - m.now())
    return str(fault.value), host.take_received()


def test_a_write_grant_taken_away_during_an_in_packet_faults_on_both_paths():
    # The core sends a bulk IN packet only with all of SRAM granted to master 4; if the
    # image revokes the write grant while the packet is on the bus, the BD's write-back at
    # its end is Python's to check, and faults as the Python model does.
    native = _grant_revoked_during_an_in_packet(True)
    assert native == _grant_revoked_during_an_in_packet(False)
    assert "USB0 DMA write of a buffer descriptor" in native[0] and native[1] == b""
