"""I2C master (I2C0) with byte-level timing, and the slaves on its bus.

The module follows the reference manual's "Inter-Integrated Circuit" chapter:

* SCL = bus clock / (mul x SCL divider); mul = 1, 2, 4 for F[MULT] = 0, 1, 2; the divider
  comes from F[ICR] through the manual's "I2C divider and hold values" table (:data:`SCL_DIVIDER`).
* Setting C1[MST] sends a START (S[BUSY] sets), clearing it a STOP; C1[RSTA] a repeated
  START. Writing D in transmit mode (C1[TX]) sends a byte; reading D in receive mode
  returns the last byte and starts receiving the next one (the first read is the "dummy
  read"). A byte takes 9 SCL periods (8 bits and the acknowledge bit); S[TCF] is clear
  meanwhile, then S[TCF] and S[IICIF] set and, after a sent byte, S[RXAK] holds the
  slave's answer (1 = no acknowledge). The master acknowledges a received byte unless
  C1[TXAK] was set when its reception started (FACK clear).
* IICIF (and STOPF/STARTF in FLT) are write-1-to-clear; with C1[IICIE] the I2C0 interrupt
  request follows IICIF.
* Erratum e6070 of the K-series masks: a repeated START is not generated when F[MULT] is
  not 0. The model ignores RSTA then and records it.

The bus reaches the slaves only through the pins muxed to I2C0 (SCL/SDA); a byte sent
with no slave answering (wrong address, pins not muxed) is not acknowledged.

A slave can hold SCL low (:meth:`I2c.hold_scl`, a stuck bus for tests): no byte and no STOP
completes while it does, so S[TCF]/S[IICIF] never set and S[BUSY], once set by a START,
stays set; bytes in flight are lost. Releasing it frees the bus (BUSY clears unless the
master holds it).
"""

from __future__ import annotations

from dataclasses import dataclass, field

from .peripheral import RegisterDevice
from .registers import irq, peripheral

# Reference manual, "I2C divider and hold values": SCL divider by ICR.
SCL_DIVIDER = (
    20, 22, 24, 26, 28, 30, 34, 40, 28, 32, 36, 40, 44, 48, 56, 68,
    48, 56, 64, 72, 80, 88, 104, 128, 80, 96, 112, 128, 144, 160, 192, 240,
    160, 192, 224, 256, 288, 320, 384, 480, 320, 384, 448, 512, 576, 640, 768, 960,
    640, 768, 896, 1024, 1152, 1280, 1536, 1920, 1280, 1536, 1792, 2048, 2304, 2560, 3072, 3840,
)
BITS_PER_BYTE = 9
_MAP = peripheral("I2C0")
_C1_IICEN, _C1_IICIE, _C1_MST, _C1_TX, _C1_TXAK, _C1_RSTA = (
    _MAP["C1"].bit(f) for f in ("IICEN", "IICIE", "MST", "TX", "TXAK", "RSTA"))
_S_TCF, _S_BUSY, _S_ARBL, _S_IICIF, _S_RXAK = (
    _MAP["S"].bit(f) for f in ("TCF", "BUSY", "ARBL", "IICIF", "RXAK"))
_FLT_STOPF, _FLT_SSIE, _FLT_STARTF, _FLT_SHEN = (
    _MAP["FLT"].bit(f) for f in ("STOPF", "SSIE", "STARTF", "SHEN"))
_FLT_FLT = _MAP["FLT"].field("FLT").mask


class I2cSlave:
    """A device on the bus, at the byte level."""
    address = 0

    def start(self, read: bool) -> None:
        """Addressed after a START or repeated START."""

    def write_byte(self, byte: int) -> bool:
        """A byte from the master; returns the acknowledge."""
        return True

    def read_byte(self) -> int:
        """The next byte for the master."""
        return 0xFF

    def stop(self) -> None:
        """STOP, or a repeated START ending the current transfer."""


@dataclass
class Transfer:
    """One addressed transfer (START or repeated START up to the next one or STOP)."""
    address: int
    read: bool
    acked: bool
    start_cycle: int
    data: bytearray = field(default_factory=bytearray)
    end_cycle: int | None = None
    start_s: float = 0.0


class I2c(RegisterDevice):
    def __init__(self, machine, chip, instance=0):
        self.chip = chip
        self.slaves = []
        self.pins_connected = lambda: True
        self.irq = irq(f"I2C{instance}")
        super().__init__(machine, f"I2C{instance}", gate=(chip.sim, "SCGC4", f"I2C{instance}"),
                         span=0xC)

    def reset(self):
        super().reset()
        self.transfers = []             # Transfer records, in order
        self.errors = []                # (instruction count, text)
        self._slave = None              # the addressed slave, None when none acknowledged
        self._expect_address = False
        self._busy_until = 0            # cycle the bus is free for the next byte
        self._event = None
        self._free_event = None
        self._current = None
        self._reading = False
        self._line = False
        self.scl_held = False

    # -- timing -----------------------------------------------------------------------------
    def scl_hz(self) -> float:
        mult = self.field("F", "MULT")
        if mult == 3:
            return 0.0
        return self.chip.bus_hz() / ((1 << mult) * SCL_DIVIDER[self.field("F", "ICR")])

    def _bit_cycles(self) -> int:
        hz = self.scl_hz()
        return max(1, int(round(self.machine.core_hz / hz))) if hz else 1 << 40

    def hold_scl(self, held: bool):
        """A slave holds SCL low (True) or lets it go: see the module's notes."""
        self.scl_held = held
        if held:
            for ev in (self._event, self._free_event):
                if ev is not None:
                    ev.cancel()
            self._event = self._free_event = None
        elif not self.v["C1"] & _C1_MST:
            self.v["S"] &= ~_S_BUSY

    # -- interrupt ---------------------------------------------------------------------------
    def _update_irq(self):
        level = bool(self.v["C1"] & _C1_IICIE and self.v["S"] & _S_IICIF)
        if level != self._line:
            self._line = level
            self.machine.set_irq(self.irq, level)

    def _flag(self, bits):
        self.v["S"] |= bits
        self._update_irq()

    # -- registers ---------------------------------------------------------------------------
    def r_C1(self):
        return self.v["C1"] & ~_C1_RSTA

    def w_S(self, value, mask):
        old = self.v["S"]
        self.v["S"] = old & ~(value & (_S_ARBL | _S_IICIF))
        self._update_irq()

    def w_FLT(self, value, mask):
        old = self.v["FLT"]
        keep = old & (_FLT_STOPF | _FLT_STARTF) & ~value
        self.v["FLT"] = (value & (_FLT_SHEN | _FLT_SSIE | _FLT_FLT)) | keep

    def w_C1(self, value, mask):
        old = self.v["C1"]
        self.v["C1"] = value & ~_C1_RSTA
        now = self.machine.now()
        if not value & _C1_IICEN:
            if old & _C1_MST:
                self._stop(now)
            self._update_irq()
            return
        if value & _C1_MST and not old & _C1_MST:
            self._start(now, repeated=False)
        elif old & _C1_MST and not value & _C1_MST:
            self._stop(now)
        elif value & _C1_RSTA and value & _C1_MST:
            if self.field("F", "MULT") != 0:
                self.errors.append((self.machine.instructions_now(),
                                    "repeated START with F[MULT] != 0 is not generated (e6070)"))
            else:
                self._start(now, repeated=True)
        self._update_irq()

    def _start(self, now, repeated):
        if self._free_event is not None:        # a START before the last STOP finished
            self._free_event.cancel()
            self._free_event = None
        self._end_transfer(now)
        self.v["S"] |= _S_BUSY
        self._busy_until = max(self._busy_until, now) + self._bit_cycles()
        self._expect_address = True
        self._slave = None
        self.v["FLT"] |= _FLT_STARTF
        if self.v["FLT"] & _FLT_SSIE:
            self._flag(_S_IICIF)

    def _stop(self, now):
        self._end_transfer(now)
        self._expect_address = False
        self._slave = None
        done = max(self._busy_until, now) + self._bit_cycles()
        self._busy_until = done
        if self.scl_held:
            return

        def bus_free():
            self._free_event = None
            self.v["S"] &= ~_S_BUSY
            self.v["FLT"] |= _FLT_STOPF
            if self.v["FLT"] & _FLT_SSIE:
                self._flag(_S_IICIF)
        self._free_event = self.machine.at(done, bus_free)

    def _end_transfer(self, now):
        if self._current is not None:
            self._current.end_cycle = now
            self._current = None
        for s in self.slaves:
            s.stop()

    def r_D(self):
        data = self.v["D"]
        c1 = self.v["C1"]
        if c1 & _C1_MST and not c1 & _C1_TX and c1 & _C1_IICEN:
            self._begin_byte(receive=True, byte=None, ack=not c1 & _C1_TXAK)
        return data

    def w_D(self, value, mask):
        value &= 0xFF
        self.v["D"] = value
        c1 = self.v["C1"]
        if c1 & _C1_MST and c1 & _C1_TX and c1 & _C1_IICEN:
            self._begin_byte(receive=False, byte=value, ack=None)

    def _begin_byte(self, receive, byte, ack):
        m = self.machine
        now = m.now()
        if self._event is not None:
            self.errors.append((m.instructions_now(), "D accessed while a byte was in transfer"))
            self._event.cancel()
        start = max(now, self._busy_until)
        done = start + BITS_PER_BYTE * self._bit_cycles()
        self._busy_until = done
        self.v["S"] &= ~_S_TCF
        if self.scl_held:
            return
        self._event = m.at(done, lambda: self._finish_byte(receive, byte, ack, start))

    def _finish_byte(self, receive, byte, ack, start):
        self._event = None
        if receive:
            slave = self._slave
            value = slave.read_byte() if slave is not None and self._reading else 0xFF
            self.v["D"] = value
            if self._current is not None:
                self._current.data.append(value)
            self.v["S"] &= ~_S_RXAK
        elif self._expect_address:
            self._expect_address = False
            address, read = byte >> 1, bool(byte & 1)
            slave = None
            if self.pins_connected():
                slave = next((s for s in self.slaves
                              if s.address == address and getattr(s, "present", True)), None)
            if slave is not None:
                slave.start(read)
            self._slave = slave
            self._reading = read
            self._current = Transfer(address, read, slave is not None, start,
                                     start_s=self.machine.seconds(start))
            self.transfers.append(self._current)
            self._set_rxak(slave is not None)
        else:
            acked = False
            if self._slave is not None and not self._reading:
                acked = self._slave.write_byte(byte)
                if self._current is not None:
                    self._current.data.append(byte)
            self._set_rxak(acked)
        self._flag(_S_TCF | _S_IICIF)

    def _set_rxak(self, acked):
        if acked:
            self.v["S"] &= ~_S_RXAK
        else:
            self.v["S"] |= _S_RXAK


# MPU-6000/6050 register map: the two data ports whose address does not auto-increment.
MPU6050_MEM_R_W, MPU6050_FIFO_R_W = 0x6F, 0x74


class Mpu6050Slave(I2cSlave):
    """The project's MPU6050 register model (``heliquad._firmware.Mpu6050Emulator``) at the
    I2C byte level: the first byte written after the address sets the register pointer,
    later bytes are written from it; reads return bytes from the pointer. The pointer
    auto-increments except on FIFO_R_W and MEM_R_W. A write's data bytes reach the model
    together at the STOP (or repeated START) that ends the transfer; a read takes one byte
    from the model per byte clocked out, so FIFO and INT_STATUS side effects happen per byte.
    Every completed register write and read is logged with its time."""

    def __init__(self, emulator, machine, address=0x68):
        self.emu = emulator
        self.machine = machine
        self.address = address
        self.present = True     # False: the chip does not answer (no acknowledge)
        self.log = []           # (seconds, 'W'|'R', register, bytes)
        self._pointer = None
        self._pointer_set = False
        self._pending = bytearray()
        self._read_reg = None
        self._read_bytes = bytearray()

    def set_present(self, present: bool):
        self.present = present
        self.emu.set_present(present)

    def start(self, read):
        self._flush()
        if read:
            self._read_reg = self._pointer
            self._read_bytes = bytearray()
        else:
            self._pointer_set = False

    def write_byte(self, byte):
        if not self._pointer_set:
            self._pointer = byte
            self._pointer_set = True
        else:
            self._pending.append(byte)
        return True

    def read_byte(self):
        reg = self._pointer if self._pointer is not None else 0
        value = self.emu.read(reg, 1)[0]
        self._read_bytes.append(value)
        if reg not in (MPU6050_FIFO_R_W, MPU6050_MEM_R_W):
            self._pointer = (reg + 1) & 0x7F
        return value

    def _flush(self):
        now = self.machine.seconds()
        if self._pending:
            self.emu.write(self._pointer, bytes(self._pending))
            self.log.append((now, "W", self._pointer, bytes(self._pending)))
            if self._pointer not in (MPU6050_FIFO_R_W, MPU6050_MEM_R_W):
                self._pointer = (self._pointer + len(self._pending)) & 0x7F
            self._pending = bytearray()
        elif self._read_bytes:
            self.log.append((now, "R", self._read_reg, bytes(self._read_bytes)))
            self._read_bytes = bytearray()

    def stop(self):
        self._flush()
