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

The model is native (``heliquad._simcore.Mk64Core``, sim/chip/mk64_devices.cpp), and so is
the MPU6050 slave's byte protocol on the project's register model: a flight loop moves a
couple of dozen bytes and the driver touches S, D and C1 for each. These classes are views.
"""

from __future__ import annotations

from dataclasses import dataclass, field

from .machine import I2C0_DEVICE
from .peripheral import NativeRegisters
from .registers import irq

# Reference manual, "I2C divider and hold values": SCL divider by ICR.
SCL_DIVIDER = (
    20, 22, 24, 26, 28, 30, 34, 40, 28, 32, 36, 40, 44, 48, 56, 68,
    48, 56, 64, 72, 80, 88, 104, 128, 80, 96, 112, 128, 144, 160, 192, 240,
    160, 192, 224, 256, 288, 320, 384, 480, 320, 384, 448, 512, 576, 640, 768, 960,
    640, 768, 896, 1024, 1152, 1280, 1536, 1920, 1280, 1536, 1792, 2048, 2304, 2560, 3072, 3840,
)


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


def _transfer(record) -> Transfer:
    address, read, acked, start, data, end, start_s = record
    return Transfer(address, read, acked, start, bytearray(data), end, start_s)


class I2cSlave:
    """A device on the bus, at the byte level: its behaviour is native (``Mk64Core``); the
    Python object is its handle (``native`` is its number in the core)."""
    address = 0
    native: int


class _Slaves(list):
    """The bus's slaves; appending one connects the native model to the bus."""

    def __init__(self, i2c):
        super().__init__()
        self._i2c = i2c

    def append(self, slave):
        if not isinstance(slave, I2cSlave):
            raise TypeError("I2C slaves are native models (Mpu6050Slave)")
        self._i2c.machine.core.mpu_attach(slave.native)
        super().append(slave)


class I2c(NativeRegisters):
    def __init__(self, machine, chip, instance=0):
        if instance != 0:
            raise ValueError("only I2C0 is modelled")
        self.chip = chip
        self.irq = irq(f"I2C{instance}")
        core = machine.core
        super().__init__(machine, f"I2C{instance}", I2C0_DEVICE, core.i2c_reg,
                         gate=(chip.sim, "SCGC4", f"I2C{instance}"), span=0xC)
        core.i2c_setup(dict(self.layout(), irq=self.irq, scl_divider=list(SCL_DIVIDER)))
        self.slaves = _Slaves(self)
        self._pins_connected = lambda: True
        # The bus reaches the slaves through the pins: re-evaluated whenever a pin's
        # function changes, so the native model knows at every byte.
        chip.ports.listeners.append(lambda letter, n: self._refresh_pins())
        self._transfers, self._open, self._errors = [], None, []

    def reset(self):
        self._transfers, self._open, self._errors = [], None, []
        self._refresh_pins()

    @property
    def pins_connected(self):
        """A callable: are SCL and SDA muxed to this I2C (the board's wiring)?"""
        return self._pins_connected

    @pins_connected.setter
    def pins_connected(self, fn):
        self._pins_connected = fn
        self._refresh_pins()

    def _refresh_pins(self):
        if self.chip.ready:
            self.machine.core.i2c_pins_connected = bool(self._pins_connected())

    @property
    def transfers(self) -> list:
        """Transfer records in order since reset (clearing the list forgets them); the last
        one may still be in progress."""
        lst, core = self._transfers, self.machine.core
        if self._open is not None and lst and lst[-1] is self._open:
            lst.pop()
        lst.extend(_transfer(t) for t in core.i2c_take_transfers())
        current = core.i2c_open_transfer()
        self._open = _transfer(current) if current is not None else None
        if self._open is not None:
            lst.append(self._open)
        return lst

    @property
    def errors(self) -> list:
        """(instruction count, text) of the misuse the model saw."""
        self._errors.extend(self.machine.core.i2c_take_errors())
        return self._errors

    def scl_hz(self) -> float:
        return self.machine.core.i2c_scl_hz()

    def hold_scl(self, held: bool):
        """A slave holds SCL low (True) or lets it go: see the module's notes."""
        self.machine.core.i2c_hold_scl(bool(held))

    @property
    def scl_held(self) -> bool:
        return self.machine.core.i2c_scl_held

    def byte_in_flight(self) -> bool:
        return self.machine.core.i2c_byte_in_flight()


class Mpu6050Slave(I2cSlave):
    """The project's MPU6050 register model (``heliquad._firmware.Mpu6050Emulator``) at the
    I2C byte level: the first byte written after the address sets the register pointer,
    later bytes are written from it; reads return bytes from the pointer. The pointer
    auto-increments except on FIFO_R_W and MEM_R_W. A write's data bytes reach the model
    together at the STOP (or repeated START) that ends the transfer; a read takes one byte
    from the model per byte clocked out, so FIFO and INT_STATUS side effects happen per byte.
    Every completed register write and read is logged with its time (``log``: (seconds,
    'W'|'R', register, bytes), until cleared)."""

    def __init__(self, emulator, machine, address=0x68):
        self.emu = emulator
        self.machine = machine
        self.address = address
        self.native = machine.core.mpu_new(emulator, address)
        self._log = []

    @property
    def present(self) -> bool:
        """False: the chip does not answer (no acknowledge)."""
        return self.machine.core.mpu_present(self.native)

    def set_present(self, present: bool):
        self.machine.core.mpu_set_present(self.native, bool(present))
        self.emu.set_present(present)

    @property
    def log(self) -> list:
        self._log.extend(self.machine.core.mpu_take_log(self.native))
        return self._log
