"""UART0 at line rate, after the reference manual's "Universal Asynchronous
Receiver/Transmitter" chapter.

* Baud = module clock / (16 x (SBR + BRFA/32)); UART0 and UART1 run from the core/system
  clock, the others from the bus clock. BDH is buffered until BDL is written.
* A frame is 1 start bit, 8 data bits (9 with C1[M]; parity takes the last one), 1 stop bit
  (2 with BDH[SBNS]): 10 bits in 8N1. Setting C2[TE] first sends an idle preamble of one
  frame. A byte written to D goes to the transmit FIFO (8 entries on UART0/UART1 with
  PFIFO[TXFE], else a 1-byte buffer); the shifter takes the next one when it is idle, and it
  leaves the pin one frame later. S1[TDRE] is set while the FIFO holds no more than
  TWFIFO[TXWATER] bytes, S1[TC] when the FIFO and the shifter are empty. A write to a full
  FIFO is lost and sets SFIFO[TXOF].
* Received bytes (:meth:`Uart.receive`) arrive one frame apart into the receive FIFO;
  S1[RDRF] is latched: it sets when the FIFO reaches RWFIFO[RXWATER] bytes, and clears only
  when S1 is read with RDRF set and then D is read, leaving fewer than RXWATER bytes. A D
  read without that S1 read leaves it set, even over an empty FIFO (the interrupt then fires
  again and again, as on the chip). Reading D from an empty FIFO sets SFIFO[RXUF]. A byte
  arriving to a full FIFO is lost and sets S1[OR]. S1[IDLE] sets one idle frame after the last byte. OR, IDLE,
  NF, FE and PF clear by reading S1 and then D.
* The RX/TX interrupt request is (TIE and TDRE) or (TCIE and TC) or (RIE and RDRF) or
  (ILIE and IDLE); the error request is OR with C3[ORIE].

What leaves the transmitter is kept with its time (``sent``: (cycle, byte) per byte), so
tests and a host model see the line, not the register writes.
"""

from __future__ import annotations

import collections

from .peripheral import RegisterDevice
from .registers import irq, peripheral

FIFO_DEPTH = {0: 8, 1: 8}           # UART0 and UART1 have 8-entry FIFOs; the others 1
FIFO_SIZE_CODE = {1: 0b000, 4: 0b001, 8: 0b010, 16: 0b011}
_MAP = peripheral("UART0")
_TIE, _TCIE, _RIE, _ILIE, _TE, _RE = (_MAP["C2"].bit(f) for f in
                                      ("TIE", "TCIE", "RIE", "ILIE", "TE", "RE"))
_TDRE, _TC, _RDRF, _IDLE, _OR = (_MAP["S1"].bit(f) for f in ("TDRE", "TC", "RDRF", "IDLE", "OR"))
_S1_CLEARED_BY_D = _MAP["S1"].field("IDLE").mask | _MAP["S1"].field("OR").mask | \
    _MAP["S1"].bit("NF") | _MAP["S1"].bit("FE") | _MAP["S1"].bit("PF")
_SBR_HIGH = _MAP["BDH"].field("SBR").mask
_SBNS = _MAP["BDH"].bit("SBNS")
_M = _MAP["C1"].bit("M")
_BRFA = _MAP["C4"].field("BRFA").mask
_ORIE = _MAP["C3"].bit("ORIE")
_TXFE, _RXFE = _MAP["PFIFO"].bit("TXFE"), _MAP["PFIFO"].bit("RXFE")
_TXFLUSH, _RXFLUSH = _MAP["CFIFO"].bit("TXFLUSH"), _MAP["CFIFO"].bit("RXFLUSH")
_CFIFO_ENABLES = _MAP["CFIFO"].bit("RXUFE") | _MAP["CFIFO"].bit("TXOFE") | \
    _MAP["CFIFO"].bit("RXOFE")
_TXEMPT, _RXEMPT = _MAP["SFIFO"].bit("TXEMPT"), _MAP["SFIFO"].bit("RXEMPT")
_TXOF = _MAP["SFIFO"].bit("TXOF")
_RXUF = _MAP["SFIFO"].bit("RXUF")
_SFIFO_W1C = _RXUF | _TXOF | _MAP["SFIFO"].bit("RXOF")


class Uart(RegisterDevice):
    READ_ONLY = ("S1", "ED", "TCFIFO", "RCFIFO")

    def __init__(self, machine, chip, instance=0):
        self.chip = chip
        self.instance = instance
        self.depth = FIFO_DEPTH.get(instance, 1)
        self.irq_rxtx = irq(f"UART{instance}_RX_TX")
        self.irq_err = irq(f"UART{instance}_ERR")
        self.on_byte = []               # fn(byte, cycle) for each byte on the TX line
        super().__init__(machine, f"UART{instance}",
                         gate=(chip.sim, "SCGC4", f"UART{instance}"), span=0x20)

    def reset(self):
        super().reset()
        self.tx = collections.deque()
        self.rx = collections.deque()
        self.sent = []                  # (cycle, byte) as each stop bit ends
        self.shifting = None            # byte (or 'preamble') in the shifter
        self._tx_event = None
        self._rx_queue = collections.deque()
        self._rx_event = None
        self._idle_event = None
        self._bdh_buffer = self.v["BDH"]
        self._s1_seen = 0
        self._rdrf = False              # S1[RDRF], latched (see the module's notes)
        self.flags = 0                  # OR, IDLE (and errors) latched in S1
        self.overruns = 0
        self.tx_overflows = 0
        self._lines = (False, False)

    # -- line rate ------------------------------------------------------------------------------
    def module_hz(self) -> float:
        return self.chip.core_hz() if self.instance in (0, 1) else self.chip.bus_hz()

    def sbr(self) -> int:
        return ((self.v["BDH"] & _SBR_HIGH) << 8) | self.v["BDL"]

    def baud(self) -> float:
        sbr, brfa = self.sbr(), self.v["C4"] & _BRFA
        if sbr == 0:
            return 0.0
        return self.module_hz() / (16 * (sbr + brfa / 32))

    def frame_bits(self) -> int:
        data = 9 if self.v["C1"] & _M else 8
        stop = 2 if self.v["BDH"] & _SBNS else 1
        return 1 + data + stop

    def frame_cycles(self) -> int:
        baud = self.baud()
        if not baud:
            return 1 << 40
        return max(1, int(round(self.frame_bits() * self.machine.core_hz / baud)))

    # -- status -----------------------------------------------------------------------------
    def _tx_depth(self):
        return self.depth if self.v["PFIFO"] & _TXFE else 1

    def _rx_depth(self):
        return self.depth if self.v["PFIFO"] & _RXFE else 1

    def tdre(self) -> bool:
        water = self.v["TWFIFO"] if self.v["PFIFO"] & _TXFE else 0
        return len(self.tx) <= water

    def tc(self) -> bool:
        return not self.tx and self.shifting is None

    def _rx_water(self) -> int:
        return max(1, self.v["RWFIFO"]) if self.v["PFIFO"] & _RXFE else 1

    def _latch_rdrf(self):
        if len(self.rx) >= self._rx_water():
            self._rdrf = True

    def rdrf(self) -> bool:
        return self._rdrf

    def s1(self) -> int:
        return (_TDRE if self.tdre() else 0) | (_TC if self.tc() else 0) | \
            (_RDRF if self.rdrf() else 0) | self.flags

    def _update_irq(self):
        c2, s1 = self.v["C2"], self.s1()
        rxtx = bool((c2 & _TIE and s1 & _TDRE) or (c2 & _TCIE and s1 & _TC) or
                    (c2 & _RIE and s1 & _RDRF) or (c2 & _ILIE and s1 & _IDLE))
        err = bool(self.v["C3"] & _ORIE and s1 & _OR)
        if (rxtx, err) != self._lines:
            self._lines = (rxtx, err)
            self.machine.set_irq(self.irq_rxtx, rxtx)
            self.machine.set_irq(self.irq_err, err)

    # -- transmitter --------------------------------------------------------------------------
    def _kick(self):
        """The shifter takes the next byte if it is idle."""
        if self.shifting is not None or not self.v["C2"] & _TE or not self.tx:
            return
        self.shifting = self.tx.popleft()
        self._tx_event = self.machine.at(self.machine.now() + self.frame_cycles(), self._shifted)

    def _shifted(self):
        byte, self.shifting = self.shifting, None
        self._tx_event = None
        if byte != "preamble":
            cycle = self.machine.cycles
            self.sent.append((cycle, byte))
            for fn in self.on_byte:
                fn(byte, cycle)
        self._kick()
        self._update_irq()

    def sent_bytes(self) -> bytes:
        return bytes(b for _, b in self.sent)

    # -- receiver ---------------------------------------------------------------------------
    def receive(self, data: bytes):
        """Bytes arriving on the RX pin back to back at the current baud rate, from now (or
        after the ones already on their way)."""
        for b in data:
            self._rx_queue.append(b)
        if self._rx_event is None and self._rx_queue:
            self._rx_event = self.machine.at(self.machine.now() + self.frame_cycles(), self._arrived)

    def _arrived(self):
        self._rx_event = None
        byte = self._rx_queue.popleft()
        if self.v["C2"] & _RE:
            if len(self.rx) >= self._rx_depth():
                self.flags |= _OR
                self.overruns += 1
            else:
                self.rx.append(byte)
                self._latch_rdrf()
        if self._idle_event:
            self._idle_event.cancel()
        self._idle_event = self.machine.at(self.machine.cycles + self.frame_cycles(), self._idle)
        if self._rx_queue:
            self._rx_event = self.machine.at(self.machine.cycles + self.frame_cycles(), self._arrived)
        self._update_irq()

    def _idle(self):
        self._idle_event = None
        self.flags |= _IDLE
        self._update_irq()

    # -- registers --------------------------------------------------------------------------
    def w_BDH(self, value, mask):
        self._bdh_buffer = value & 0xFF

    def w_BDL(self, value, mask):
        self.v["BDH"] = self._bdh_buffer
        self.v["BDL"] = value & 0xFF

    def r_S1(self):
        value = self.s1()
        self._s1_seen = value & (_S1_CLEARED_BY_D | _RDRF)
        return value

    def r_D(self):
        if self.rx:
            value = self.rx.popleft()
        else:
            value = 0
            self.v["SFIFO"] |= _RXUF
        if self._s1_seen:
            if self._s1_seen & _RDRF and len(self.rx) < self._rx_water():
                self._rdrf = False
            self.flags &= ~(self._s1_seen & ~_RDRF)
            self._s1_seen = 0
        self._update_irq()
        return value

    def w_D(self, value, mask):
        if len(self.tx) >= self._tx_depth():
            self.v["SFIFO"] |= _TXOF
            self.tx_overflows += 1
        else:
            self.tx.append(value & 0xFF)
        self._kick()
        self._update_irq()

    def w_C2(self, value, mask):
        old = self.v["C2"]
        self.v["C2"] = value
        if value & _TE and not old & _TE:
            if self.shifting is None:               # a preamble (idle frame) first
                self.shifting = "preamble"
                self._tx_event = self.machine.at(self.machine.now() + self.frame_cycles(),
                                                 self._shifted)
        self._kick()
        self._update_irq()

    def w_C3(self, value, mask):
        self.v["C3"] = value
        self._update_irq()

    def r_PFIFO(self):
        code = FIFO_SIZE_CODE[self.depth]
        return (self.v["PFIFO"] & (_TXFE | _RXFE)) | (code << 4) | code

    def w_PFIFO(self, value, mask):
        if self.v["C2"] & (_TE | _RE):
            self.chip.note(f"UART{self.instance}_PFIFO written with TE or RE set (the "
                           "manual allows changing the FIFO enables only with both clear)")
        self.v["PFIFO"] = value & (_TXFE | _RXFE)
        self._update_irq()

    def w_CFIFO(self, value, mask):
        if value & _TXFLUSH:
            self.tx.clear()
        if value & _RXFLUSH:
            self.rx.clear()
        self.v["CFIFO"] = value & _CFIFO_ENABLES
        self._update_irq()

    def r_SFIFO(self):
        return (self.v["SFIFO"] & _SFIFO_W1C) | (_TXEMPT if not self.tx else 0) | \
            (_RXEMPT if not self.rx else 0)

    def w_SFIFO(self, value, mask):
        self.v["SFIFO"] &= ~(value & _SFIFO_W1C)

    def w_TWFIFO(self, value, mask):
        self.v["TWFIFO"] = value & 0xFF
        self._update_irq()

    def w_RWFIFO(self, value, mask):
        self.v["RWFIFO"] = value & 0xFF
        self._latch_rdrf()
        self._update_irq()

    def r_TCFIFO(self):
        return len(self.tx)

    def r_RCFIFO(self):
        return len(self.rx)
