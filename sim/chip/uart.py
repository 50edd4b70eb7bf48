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

What leaves the transmitter is kept with its time (``sent``: (cycle, byte) per byte) until
taken (:meth:`Uart.take_sent`), so tests and a host model see the line, not the register
writes, and a long run need not keep every byte.

The model is native (``heliquad._simcore.Mk64Core``, sim/chip/mk64_devices.cpp): the
telemetry handler touches S1, TCFIFO and D hundreds of times a loop. This class is its view.
The transmitter is worked out when looked at (each byte leaves one frame after the one
before, from the cycle that one left), with an event only where TDRE (under TIE) or the
end of transmission can change unseen, not one a byte.
"""

from __future__ import annotations

from .machine import UART0_DEVICE
from .peripheral import NativeRegisters
from .registers import irq

FIFO_DEPTH = {0: 8, 1: 8}           # UART0 and UART1 have 8-entry FIFOs; the others 1
FIFO_SIZE_CODE = {1: 0b000, 4: 0b001, 8: 0b010, 16: 0b011}


class Uart(NativeRegisters):
    def __init__(self, machine, chip, instance=0):
        if instance != 0:
            raise ValueError("only UART0 is modelled")
        self.chip = chip
        self.instance = instance
        self.depth = FIFO_DEPTH.get(instance, 1)
        self.irq_rxtx = irq(f"UART{instance}_RX_TX")
        self.irq_err = irq(f"UART{instance}_ERR")
        core = machine.core
        super().__init__(machine, f"UART{instance}", UART0_DEVICE, core.uart_reg,
                         gate=(chip.sim, "SCGC4", f"UART{instance}"), span=0x20)
        layout = self.layout()
        layout["k"]["FIFO_CODE"] = FIFO_SIZE_CODE[self.depth]
        core.uart_setup(dict(layout, irq_rxtx=self.irq_rxtx, irq_err=self.irq_err,
                             depth=self.depth))
        self._sent = []

    def reset(self):
        self._sent = []                 # the core resets the model with the machine

    def _state(self) -> dict:
        return self.machine.core.uart_state()

    # -- what the model holds ----------------------------------------------------------------
    tx = property(lambda self: self._state()["tx"], doc="bytes in the transmit FIFO")
    rx = property(lambda self: self._state()["rx"], doc="bytes in the receive FIFO")
    shifting = property(lambda self: self._state()["shifting"],
                        doc="the byte in the shifter, 'preamble', or None")
    overruns = property(lambda self: self._state()["overruns"])
    tx_overflows = property(lambda self: self._state()["tx_overflows"])
    flags = property(lambda self: self._state()["flags"], doc="OR, IDLE latched in S1")

    @property
    def sent(self) -> list:
        """(cycle, byte) of each byte on the TX line, as each stop bit ends, since reset or
        the last :meth:`take_sent` (clearing this list forgets them too)."""
        self._sent.extend(self.machine.core.uart_take_sent())
        return self._sent

    def sent_bytes(self) -> bytes:
        return bytes(b for _, b in self.sent)

    def take_sent(self) -> bytes:
        """The bytes that left the TX pin since the last call (or reset), forgotten here."""
        data = bytes(b for _, b in self._sent) + self.machine.core.uart_take_sent_bytes()
        self._sent.clear()
        return data

    def take_notes(self) -> list:
        return self.machine.core.uart_take_notes()

    # -- line rate ------------------------------------------------------------------------------
    def module_hz(self) -> float:
        return self.chip.core_hz()

    def sbr(self) -> int:
        return ((self.v["BDH"] & self.map["BDH"].field("SBR").mask) << 8) | self.v["BDL"]

    def baud(self) -> float:
        return self.machine.core.uart_baud()

    def frame_bits(self) -> int:
        return self.machine.core.uart_frame_bits()

    def frame_cycles(self) -> int:
        return self.machine.core.uart_frame_cycles()

    # -- status -----------------------------------------------------------------------------
    def tdre(self) -> bool:
        return self._state()["tdre"]

    def tc(self) -> bool:
        return self._state()["tc"]

    def rdrf(self) -> bool:
        return self._state()["rdrf"]

    def tx_idle(self) -> bool:
        """Nothing left to send: the FIFO and the shifter are empty and the transmit
        interrupt is not enabled (a driver enables it while its own queue holds bytes)."""
        return self.tc() and not self.v["C2"] & self.map["C2"].bit("TIE")

    def s1(self) -> int:
        return self._state()["s1"]

    # -- receiver ---------------------------------------------------------------------------
    def receive(self, data: bytes):
        """Bytes arriving on the RX pin back to back at the current baud rate, from now (or
        after the ones already on their way)."""
        self.machine.core.uart_receive(bytes(data))
