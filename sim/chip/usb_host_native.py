"""The USB host's (``usb_host.py``) half in the native core (sim/chip/mk64_usb.cpp): the state
its frames and bulk IN polls share with it (``_link``, the core's ``usb0.host``), the gate its
pump opens when nothing but the bulk IN poll is left to do (and every other piece of work
shuts), and the transfer jobs its pump runs, the bulk IN one with its NAK frame in the core.
"""

from __future__ import annotations

import dataclasses

from .usb import PID_IN, native_field


@dataclasses.dataclass
class Tx:
    pid: int
    endpoint: int
    data: bytes = b""
    data1: bool = False


class Job:
    """A transfer in progress: its transactions come from ``gen``."""

    def __init__(self, gen, deadline_s=None, record=None):
        self.gen, self.deadline_s, self.record = gen, deadline_s, record
        self.tx = next(gen)
        self.nak_frame = -1
        self.silences = 0


class BulkIn(Job):
    """The bulk IN job: its state is the core's (which makes its polls while the gate is
    open), and its next transaction is an IN with the DATA0/1 the core expects next."""

    def __init__(self, gen, link):
        self._link = link
        link.new_job()
        super().__init__(gen)

    nak_frame = native_field("_link", "nak_frame", "the frame its last poll was NAKed in")
    silences = native_field("_link", "silences", "polls in a row with no answer")

    @property
    def tx(self) -> Tx:
        return Tx(PID_IN, self._endpoint, b"", self._link.toggle)

    @tx.setter
    def tx(self, tx: Tx):
        self._endpoint = tx.endpoint


class NativeLink:
    """The part of :class:`~.usb_host.UsbHost` the native core shares: ``_link`` is set
    first; the frames, the gate and the pump's scheduling."""

    frame = native_field("_link", "frame", "the last SOF's frame number")
    in_nak = native_field("_link", "in_nak",
                          "the last bulk IN poll was NAKed: nothing was waiting")
    in_nak_cycle = native_field("_link", "in_nak_cycle",
                                "when a bulk IN poll was last NAKed (-1: never)")
    _in_flight = native_field("_link", "in_flight", "a transaction is on the bus")
    _waiting_tokdne = native_field("_link", "waiting", "a pump found ISTAT.TOKDNE set")
    _next_sof = native_field("_link", "next_sof", "the next SOF's cycle")
    _sof_end = native_field("_link", "sof_end", "when this frame's SOF has crossed the bus")
    toggle_errors = native_field("_link", "toggle_errors",
                                 "IN packets with the wrong DATA0/1 (ACKed and dropped)")

    @property
    def reading(self) -> bool:
        """The port is read: the bulk IN endpoint is polled."""
        return self._link.reading

    @reading.setter
    def reading(self, on: bool):
        self._link.reading = bool(on)
        self._shut_gate()

    @property
    def _bulk_in(self):
        return self._bulk_in_job if self._link.job else None

    @_bulk_in.setter
    def _bulk_in(self, job):
        self._bulk_in_job = job
        if job is None:
            self._link.drop_job()

    def _shut_gate(self):
        """Work other than the bulk IN poll may be queued: the next pump is Python's."""
        self._link.gate = False

    def _update_gate(self):
        """Open the gate when nothing but the bulk IN poll is left to do."""
        link = self._link
        link.gate = bool(self.port_enabled and self.configured and self.reading and
                         self._control is None and self._bulk_out is None and
                         not self._to_send and self._bulk_in is not None)
        if link.gate:
            link.address, link.endpoint = self.address, self._bulk_in.tx.endpoint & 0xF

    def take_received(self) -> bytes:
        return self._link.take_received()

    def _clear_toggles(self):
        """Every endpoint's DATA0/1 back to DATA0 (a reset, a new configuration)."""
        self._toggles.clear()
        self._link.toggle = False

    def tokens_free(self):
        self.machine.core.usb_tokens_free()

    def _stop_frames(self):
        if self._frames:
            self.machine.core.usb_host_stop_frames()
        self._frames = False

    def _frame(self):
        """The first frame: the core schedules the next one (usb_host.FRAME_S on, each one the
        next), makes the SOF (usb_host.TOKEN_BITS long) and keeps the frame's bounds; then the
        pump."""
        self._frames = True
        self.machine.core.usb_host_frame()
        self._pump()

    def _write_back(self):
        """A bulk IN packet the core sent ended after the MPU changed: its BD's write-back
        is checked here (the fault usb.py raises), then the core ends the packet."""
        self.usb.check_write_back(self._link.flight_bd)
        if not self.machine.core.usb_end_data():
            self._pump()

    def _pump_soon(self):
        self.machine.core.usb_pump_soon()       # shuts the gate; the pump is an event now
