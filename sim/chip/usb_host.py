"""A USB host on the emulated chip's USB0 (``usb.py``): one full-speed root port, the
enumeration a Linux host performs, the cdc_acm driver's requests, and bulk transfers, timed on
the emulator's clock. docs/teensy35-emulator.md lists what is and is not modelled.

* Bus: 12 Mbit/s; a transaction takes the bits of its packets (token 35, data 35 + 8 per
  byte, handshake 19: SYNC, PID, fields, CRC, EOP; bit stuffing and inter-packet gaps
  ignored); one transaction at a time, and none while the device's ISTAT.TOKDNE is set (the
  host waits for the firmware to take the last token). A SOF starts every 1 ms frame while
  the port is enabled (after the first reset); a transaction that would cross the next SOF
  waits for that frame.
* Attach: the device's pull-up, then 100 ms of debounce (Linux's hub_port_debounce), then
  the enumeration: reset (10 ms of SE0, 10 ms of recovery), GET_DESCRIPTOR(device, 64) at
  address 0, reset, SET_ADDRESS, GET_DESCRIPTOR(device, 18), GET_DESCRIPTOR(configuration,
  9) then its wTotalLength, the strings (0 for the languages, then product, manufacturer,
  serial; 255 bytes each; a stalled string is left out), SET_CONFIGURATION.
* cdc_acm: :meth:`UsbHost.open` (SET_CONTROL_LINE_STATE DTR|RTS, SET_LINE_CODING 7 bytes),
  :meth:`UsbHost.close` (SET_CONTROL_LINE_STATE 0), :meth:`UsbHost.set_line_coding` (7 or
  1 data bytes, as teensy_loader_cli's reboot request sends).
* A NAKed or unanswered transaction is retried in the next frame; a control transfer not
  done 5 s after it started (Linux's USB_CTRL_GET_TIMEOUT) fails, as does a transaction the
  device does not answer three times (the host controller's error count). A failure ends the queued work
  and is kept in ``error``; :func:`settle` raises it.
* Bulk: while ``reading`` (and configured) the host polls the bulk IN endpoint every frame,
  again at once after a full packet; a reader that stops reading stops polling, so the
  device's IN endpoint backs up. :meth:`UsbHost.send` queues bytes for bulk OUT in packets of
  the endpoint's size. Bytes in wait in :meth:`UsbHost.take_received`.

The frames (SOF, the next one's time) are native events, and while the host has nothing to do
but poll the bulk IN endpoint (the gate its pump opens: no control transfer, no bulk OUT) the
native core makes the polls whose answer is plain, a NAK or data from RAM
(sim/chip/mk64_usb.cpp); a frame, a finished poll or a freed STAT calls :meth:`UsbHost._pump`
here only when the gate is shut or a poll's answer is anything else. The state they share (the
frame, the poll in flight, the last NAK, the bulk IN job's DATA0/1 and bytes) is the core's
(``_link``, ``usb_host_native.py``).
"""

from __future__ import annotations

import collections
import dataclasses
import struct

from ..base.errors import InputError
from . import usb_descriptors as desc
from .machine import PY_CALL_USB_PUMP, PY_CALL_USB_WRITE_BACK, EmulationError
from .usb import ACK, NAK, PID_IN, PID_OUT, PID_SETUP, STALL
from .usb_host_native import BulkIn, Job, NativeLink, Tx

BIT_RATE_HZ = 12e6                  # full speed (USB 2.0, 7.1.11)
FRAME_S = 1e-3
TOKEN_BITS = 8 + 8 + 11 + 5 + 3     # SYNC, PID, ADDR+ENDP, CRC5, EOP
HANDSHAKE_BITS = 8 + 8 + 3          # SYNC, PID, EOP
DATA_OVERHEAD_BITS = 8 + 8 + 16 + 3   # SYNC, PID, CRC16, EOP
DEBOUNCE_S = 0.100                  # Linux hub_port_debounce (HUB_DEBOUNCE_STABLE)
RESET_S = 0.010                     # TDRST, the minimum reset (USB 2.0, 7.1.7.5)
RESET_RECOVERY_S = 0.010            # TRSTRCY (USB 2.0, 9.2.6.2)
SET_ADDRESS_RECOVERY_S = 0.002      # TDSETADDR (USB 2.0, 9.2.6.3)
CONTROL_TIMEOUT_S = 5.0             # Linux USB_CTRL_GET_TIMEOUT
NO_RESPONSE_LIMIT = 3               # transaction errors before the host gives up (USB 2.0, 11.17)
FIRST_EP0_PACKET = 64               # Linux's first guess at a full-speed EP0's packet size
DEVICE_ADDRESS = 1
STRING_LENGTH = 255                 # Linux reads strings with wLength 255
DTR, RTS = 1, 2
CDC_SET_LINE_CODING, CDC_SET_CONTROL_LINE_STATE = 0x20, 0x22


class UsbError(EmulationError):
    """The host gave up: a timeout, a stall where none may be, a device that went silent."""


@dataclasses.dataclass
class ControlRecord:
    """One control transfer: what was asked, what came back."""
    request: str
    setup: bytes
    sent: bytes = b""
    received: bytes = b""
    status: str = "pending"         # ok, stall, timeout, no response, detached
    start_s: float = 0.0
    end_s: float = 0.0


def setup_packet(request_type, request, value, index, length) -> bytes:
    return struct.pack("<BBHHH", request_type, request, value, index, length)


class UsbHost(NativeLink):
    """The host on ``chip.usb0``'s bus. ``auto_enumerate``: enumerate at attach."""

    def __init__(self, chip, *, auto_enumerate: bool = True, debounce_s: float = DEBOUNCE_S,
                 open_port: bool = False):
        self.chip, self.usb, self.machine = chip, chip.usb0, chip.machine
        self._link = self.machine.core.usb0.host
        self.auto_enumerate = auto_enumerate
        self.debounce_s = debounce_s
        self.open_port = open_port      # open the port (cdc_acm) once enumerated
        self.usb.listeners.append(self)
        self.machine.reset_listeners.append(self._forget)
        self.machine.native_calls[PY_CALL_USB_PUMP] = self._pump
        self.machine.native_calls[PY_CALL_USB_WRITE_BACK] = self._write_back
        self._forget()

    def _forget(self):
        self._bulk_in = None
        self._shut_gate()
        self.device_attached = False
        self.port_enabled = False
        self.address = 0
        self.frame = 0
        self.ep0_packet = FIRST_EP0_PACKET
        self.configured = False
        self.transfers = []         # ControlRecord of every control transfer
        self.error = None
        self.device_bytes = self.config_bytes = b""
        self.strings = {}
        self.reading = True
        self.in_nak = True
        self.in_nak_cycle = -1
        self.toggle_errors = 0
        self._link.take_received()
        self._link.toggle = False
        self._to_send = bytearray()
        self._toggles = {}
        self._scripts = collections.deque()
        self._script = None
        self._control = self._bulk_in = self._bulk_out = None
        self._in_flight = self._waiting_tokdne = self._debouncing = False
        self._next_sof = self._sof_end = 0
        self._frames = False
        self._timer = None

    # -- what the device does -------------------------------------------------------------
    def attached(self, now_attached: bool):
        self.device_attached = now_attached
        if not now_attached:
            self._detach()
        elif self.auto_enumerate:
            self._debouncing = True
            self._timer = self.machine.after(self.debounce_s, self.enumerate)

    def _detach(self):
        self._shut_gate()
        self._stop_frames()
        if self._timer is not None:
            self._timer.cancel()
        self._timer = None
        self.port_enabled = self.configured = self._debouncing = False
        if self._control is not None and self._control.record is not None:
            self._control.record.status = "detached"
        self._control = self._bulk_in = self._bulk_out = None
        self._scripts.clear()
        self._script = None
        self._in_flight = False

    # -- requests -------------------------------------------------------------------------
    def enumerate(self):
        """Enumerate as Linux does (a bus reset first, so it re-enumerates too); then open
        the port if ``open_port``."""
        self._timer, self._debouncing = None, False
        self._queue(self._enumeration())
        if self.open_port:
            self.open()

    def bus_reset(self):
        """A bus reset now, then the enumeration again."""
        self.enumerate()

    def open(self, baud: int = 115200):
        """The cdc_acm driver's open: DTR and RTS on, then the line coding."""
        self._queue(self._requests([self._line_state(DTR | RTS), self._coding(baud, 7)]))

    def close(self):
        self._queue(self._requests([self._line_state(0)]))

    def set_line_coding(self, baud: int, length: int = 7):
        """SET_LINE_CODING with the first ``length`` bytes of its 7 (1: teensy_loader_cli's)."""
        self._queue(self._requests([self._coding(baud, length)]))

    def control(self, request_type: int, request: int, value: int = 0, index: int = 0,
                data_or_length=0, name: str = "CONTROL"):
        """Any control transfer, queued: ``data_or_length`` the OUT data or the IN length; its
        record (status ``stall`` allowed) in ``transfers``."""
        def script():
            yield from self._request(name, request_type, request, value, index, data_or_length,
                                     may_stall=True)
        self._queue(script())

    def send(self, data: bytes):
        self._to_send += data
        self._pump_soon()

    def idle(self) -> bool:
        """Nothing queued: no enumeration waiting for its debounce, no script and no control
        transfer (bulk may go on)."""
        return not self._debouncing and self._script is None and not self._scripts and \
            self._control is None

    def identity(self) -> desc.Identity:
        return desc.Identity(desc.parse_device(self.device_bytes),
                             desc.parse_configuration(self.config_bytes), dict(self.strings))

    def _comm_interface(self) -> int:
        for i in desc.parse_configuration(self.config_bytes).interfaces:
            if i.interface_class == 0x02:
                return i.number
        return 0

    def _line_state(self, bits):
        return ("SET_CONTROL_LINE_STATE", 0x21, CDC_SET_CONTROL_LINE_STATE, bits, None, b"")

    def _coding(self, baud, length):
        coding = struct.pack("<IBBB", baud, 0, 0, 8)[:length]
        return ("SET_LINE_CODING", 0x21, CDC_SET_LINE_CODING, 0, None, coding)

    # -- scripts --------------------------------------------------------------------------
    def _queue(self, script):
        self._shut_gate()
        self._scripts.append(script)
        if self._script is None:
            self._next_script()

    def _next_script(self):
        self._script = self._scripts.popleft() if self._scripts else None
        if self._script is not None:
            self._step(None)

    def _step(self, value):
        """Run the current script to its next action: ("reset",), ("wait", s),
        ("control", record, data or length)."""
        try:
            action = self._script.send(value)
        except StopIteration:
            self._next_script()
            return
        except (UsbError, InputError) as e:     # a failed request, a descriptor that is not one
            self.error = e if isinstance(e, UsbError) else UsbError(f"USB host: {e}")
            self._scripts.clear()
            self._script = None
            return
        if action[0] == "reset":
            self._start_reset()
        elif action[0] == "wait":
            self._timer = self.machine.after(action[1], lambda: self._step(None))
        else:
            self._start_control(action[1], action[2])

    def _requests(self, requests):
        for name, request_type, request, value, index, data in requests:
            index = self._comm_interface() if index is None else index
            yield from self._request(name, request_type, request, value, index, data)

    def _request(self, name, request_type, request, value, index, data_or_length,
                 may_stall=False):
        """A control transfer in a script; its record, or UsbError if it failed."""
        length = data_or_length if isinstance(data_or_length, int) else len(data_or_length)
        record = ControlRecord(name, setup_packet(request_type, request, value, index, length))
        yield ("control", record, data_or_length)
        if record.status == "ok" or (record.status == "stall" and may_stall):
            return record
        raise UsbError(f"USB host: {name} failed ({record.status}) after "
                       f"{1e3 * (record.end_s - record.start_s):.0f} ms of emulated time")

    def _get_descriptor(self, name, kind, index, length, lang=0, may_stall=False):
        return (yield from self._request(f"GET_DESCRIPTOR({name})", 0x80, 6, kind << 8 | index,
                                         lang, length, may_stall))

    def _enumeration(self):
        self.configured = False
        yield ("reset",)
        first = yield from self._get_descriptor("device", desc.DEVICE, 0, 64)
        if len(first.received) < 8:
            raise UsbError(f"USB host: the first device descriptor read gave "
                           f"{len(first.received)} bytes (8 at least)")
        yield ("reset",)
        yield from self._request("SET_ADDRESS", 0x00, 5, DEVICE_ADDRESS, 0, b"")
        yield ("wait", SET_ADDRESS_RECOVERY_S)
        self.address, self.ep0_packet = DEVICE_ADDRESS, first.received[7]
        self.device_bytes = (yield from self._get_descriptor("device", desc.DEVICE, 0, 18)).received
        device = desc.parse_device(self.device_bytes)
        head = yield from self._get_descriptor("configuration", desc.CONFIGURATION, 0, 9)
        total = struct.unpack_from("<H", head.received, 2)[0]
        config = yield from self._get_descriptor("configuration", desc.CONFIGURATION, 0, total)
        self.config_bytes = config.received
        indices = [i for i in (device.i_product, device.i_manufacturer, device.i_serial) if i]
        if indices:
            langs = yield from self._get_descriptor("string 0", desc.STRING, 0, STRING_LENGTH)
            lang = desc.parse_languages(langs.received)[0]
            for i in indices:
                s = yield from self._get_descriptor(f"string {i}", desc.STRING, i, STRING_LENGTH,
                                                    lang, may_stall=True)
                if s.status == "ok":
                    self.strings[i] = desc.parse_string(s.received)
        value = desc.parse_configuration(self.config_bytes).value
        yield from self._request("SET_CONFIGURATION", 0x00, 9, value, 0, b"")
        self._clear_toggles()
        self.configured = True
        self._pump_soon()

    # -- bus reset and frames -------------------------------------------------------------
    def _start_reset(self):
        self._shut_gate()
        self._stop_frames()
        self.port_enabled, self.address, self.ep0_packet = False, 0, FIRST_EP0_PACKET
        self._clear_toggles()
        self._bulk_in = self._bulk_out = None
        self.usb.bus_reset(True)
        self._timer = self.machine.after(RESET_S, self._end_reset)

    def _end_reset(self):
        self.usb.bus_reset(False)
        self.port_enabled = True
        self._frame()
        self._timer = self.machine.after(RESET_RECOVERY_S, lambda: self._step(None))

    # -- transactions ---------------------------------------------------------------------
    def _start_control(self, record, data_or_length):
        record.start_s = self.machine.seconds()
        self._control = Job(self._control_stages(record, data_or_length),
                             record.start_s + CONTROL_TIMEOUT_S, record)
        self.transfers.append(record)
        self._pump_soon()

    def _control_stages(self, record, data_or_length):
        yield Tx(PID_SETUP, 0, record.setup, False)
        toggle = True
        if record.setup[0] & 0x80:
            length = data_or_length
            while len(record.received) < length:
                got = yield Tx(PID_IN, 0, b"", toggle)
                record.received += got
                toggle = not toggle
                if len(got) < self.ep0_packet:
                    break
            record.received = record.received[:length]
            yield Tx(PID_OUT, 0, b"", True)
            return
        data = data_or_length
        for at in range(0, len(data), self.ep0_packet):
            yield Tx(PID_OUT, 0, data[at:at + self.ep0_packet], toggle)
            record.sent += data[at:at + self.ep0_packet]
            toggle = not toggle
        yield Tx(PID_IN, 0, b"", True)

    def _jobs(self):
        if self.configured and self.port_enabled:
            if self._bulk_out is None and self._to_send:
                self._bulk_out = Job(self._bulk_out_packets())
            if self._bulk_in is None and self.reading:
                self._bulk_in = BulkIn(self._bulk_in_packets(), self._link)
        return [j for j in (self._control, self._bulk_out, self._bulk_in) if j is not None]

    def _pump(self):
        self._pump_once()
        self._update_gate()

    def _pump_once(self):
        if self._in_flight or not self.port_enabled:
            return
        if self.usb.token_busy():
            self._waiting_tokdne = True
            return
        now = self.machine.now()
        for job in self._jobs():
            if job.deadline_s is not None and self.machine.seconds(now) > job.deadline_s:
                self._done(job, "timeout")
                return self._pump_once()
            if job.nak_frame == self.frame:
                continue
            if job is self._bulk_in and not self.reading:
                continue
            self._transact(job, now)
            return

    def _transact(self, job, now):
        """The token goes out now (the SIE answers at once); the transaction ends, and the
        SIE writes back, when its packets have crossed the bus (after this frame's SOF)."""
        tx = job.tx
        now = max(now, self._sof_end)
        bits = TOKEN_BITS + (DATA_OVERHEAD_BITS + 8 * len(tx.data) if tx.pid != PID_IN else 0)
        worst = bits + DATA_OVERHEAD_BITS + 8 * 64 + HANDSHAKE_BITS
        if self.machine.cycles_after(worst / BIT_RATE_HZ, now) >= self._next_sof:
            return                      # the frame is full: the next SOF pumps again
        endpoint = tx.endpoint & 0xF
        tok = self.usb.token(tx.pid, self.address, endpoint, tx.data, tx.data1)
        if tok.handshake is None:
            bits = bits + 16 * 8        # the host's timeout (16-18 bit times) and no answer
        elif tx.pid == PID_IN and tok.handshake == ACK:
            bits += DATA_OVERHEAD_BITS + 8 * len(tok.data) + HANDSHAKE_BITS
        else:
            bits += HANDSHAKE_BITS
        self._in_flight = True
        self.machine.at(self.machine.cycles_after(bits / BIT_RATE_HZ, now),
                        lambda: self._finish(job, tok))

    def _finish(self, job, tok):
        self._in_flight = False
        self.usb.complete(tok)
        if job not in (self._control, self._bulk_in, self._bulk_out):
            return self._pump()         # dropped meanwhile (a reset, a detach)
        if job is self._bulk_in:
            self.in_nak = tok.handshake == NAK
            if self.in_nak:
                self.in_nak_cycle = self.machine.now()
        if tok.handshake == NAK:
            job.nak_frame = self.frame
        elif tok.handshake == STALL:
            self._done(job, "stall")
        elif tok.handshake is None:
            job.silences += 1
            job.nak_frame = self.frame      # tried again in the next frame
            if job.silences >= NO_RESPONSE_LIMIT:
                self._done(job, "no response")
        elif tok.pid == PID_IN and tok.data1 != job.tx.data1:
            self.toggle_errors += 1     # ACKed and dropped: the device sent it again
        else:
            job.silences = 0
            self._advance(job, tok.data if tok.pid == PID_IN else None)
        self._pump()

    def _advance(self, job, value):
        try:
            job.tx = job.gen.send(value)
        except StopIteration:
            self._done(job, "ok")

    def _done(self, job, status):
        self._shut_gate()
        if job is self._control:
            self._control = None
            job.record.status = status
            job.record.end_s = self.machine.seconds()
            self._step(None)
        elif job is self._bulk_in:
            self._bulk_in = None
        elif job is self._bulk_out:
            self._bulk_out = None
        if status != "ok" and job.record is None:
            self.error = UsbError(f"USB host: bulk transfer failed ({status})")

    # -- bulk -----------------------------------------------------------------------------
    def _bulk_endpoint(self, direction):
        for i in desc.parse_configuration(self.config_bytes).interfaces:
            for e in i.endpoints:
                if e.transfer_type == "bulk" and e.direction == direction:
                    return e
        raise UsbError(f"USB host: the configuration has no bulk {direction} endpoint")

    def _bulk_in_packets(self):
        """The bulk IN job's steps (the core takes the same steps for the packets it polls:
        mk64_usb.cpp's took_packet); its DATA0/1 and the bytes are the core's."""
        ep, link = self._bulk_endpoint("in"), self._link
        link.max_packet = ep.max_packet
        while True:
            got = yield Tx(PID_IN, ep.address, b"", link.toggle)
            link.receive(got)
            link.toggle = not link.toggle
            if len(got) < ep.max_packet:
                self._bulk_in.nak_frame = self.frame     # a short packet: next frame
            if not self.reading:
                return

    def _bulk_out_packets(self):
        ep = self._bulk_endpoint("out")
        while self._to_send:
            toggle = self._toggles.get(ep.address, False)
            yield Tx(PID_OUT, ep.address, bytes(self._to_send[:ep.max_packet]), toggle)
            del self._to_send[:ep.max_packet]
            self._toggles[ep.address] = not toggle


def settle(host: UsbHost, run_for, timeout_s: float, step_s: float = 1e-3):
    """Let emulated time pass (``run_for(seconds)``) until the host has nothing queued;
    UsbError if it failed or is still busy after ``timeout_s``."""
    waited = 0.0
    while not host.idle():
        if host.error is not None:
            raise host.error
        if waited >= timeout_s:
            raise UsbError(f"USB host: still busy after {timeout_s} s of emulated time "
                           f"(last request: {host.transfers[-1].request if host.transfers else 'none'})")
        run_for(step_s)
        waited += step_s
    if host.error is not None:
        raise host.error
