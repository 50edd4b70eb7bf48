"""Register-file base for the peripheral models: storage with the SVD's reset values,
accesses of any width split onto registers, a clock gate, and per-register handlers.

A model subclasses :class:`RegisterDevice` with the SVD name of its peripheral and defines,
for registers with behaviour, ``r_<NAME>(self) -> int`` (the value a read returns; it may
have side effects, as reading D does on a UART) and ``w_<NAME>(self, value, mask)`` (``value``
is the register after the write, the old contents where ``mask`` has no bits; store what
the register should hold in ``self.v[name]``). Registers without handlers store what is
written. An access to an offset no register occupies is a bus fault.

A model that lives in native code (``heliquad._simcore.Mk64Core``: UART0, I2C0, FTM0, FTM3,
WDOG) subclasses :class:`NativeRegisters` instead: the same map, gate and field helpers, its
registers read from the native model (``v`` is a read-only view), its accesses passed to it.
"""

from __future__ import annotations

from .machine import ChipReset, Device, Fault
from .registers import peripheral


class _RegisterMap(Device):
    """A peripheral's SVD register map, its clock gate and the field helpers."""

    def _map(self, machine, svd_name: str, gate, span: int | None, name: str | None):
        self.machine = machine
        self.map = peripheral(svd_name)
        self.name = name or svd_name
        self.base = self.map.base
        self.size = span or self.map.size
        self.gate = gate            # (SIM device, register name, field name) or None
        self._gate_mask = gate[0].map[gate[1]].bit(gate[2]) if gate else 0
        self._at = {}               # byte offset -> Register
        for reg in self.map.registers.values():
            for i in range(reg.bits // 8):
                self._at.setdefault(reg.offset + i, reg)

    # -- the clock gate --------------------------------------------------------------------
    def clocked(self) -> bool:
        if self.gate is None:
            return True
        return bool(self.gate[0].v[self.gate[1]] & self._gate_mask)

    def gate_name(self) -> str:
        return f"SIM_{self.gate[1]}.{self.gate[2]}" if self.gate else "no gate"

    def reg(self, name):
        return self.map[name]

    def field(self, reg: str, fld: str) -> int:
        return self.map[reg].field(fld).get(self.v[reg])

    def bit(self, reg: str, fld: str) -> int:
        return self.map[reg].bit(fld)

    def peek(self, name: str) -> int:
        """A register's stored value, without a read's side effects."""
        return self.v[name]

    def layout(self) -> dict:
        """The register map for the native model, from the SVD: the register each byte
        belongs to (``reg_at``, by byte offset), each register's width in bytes and reset
        value (by its offset), and every register's offset ("REG") and field's mask
        ("REG.FIELD")."""
        reg_at, width, reset, k = [-1] * self.size, [0] * self.size, [0] * self.size, {}
        for reg in self.map.registers.values():
            if reg.bits not in (8, 16, 32):
                raise ValueError(f"{self.name}_{reg.name}: native models take 8-, 16- and "
                                 "32-bit registers")
            if reg.offset + reg.bits // 8 <= self.size:
                for i in range(reg.bits // 8):
                    reg_at[reg.offset + i] = reg.offset
                width[reg.offset] = reg.bits // 8
                reset[reg.offset] = reg.reset & ((1 << reg.bits) - 1)
            k[reg.name] = reg.offset
            for fld in reg.fields:
                k[f"{reg.name}.{fld}"] = reg.field(fld).mask
        return {"base": self.base, "span": self.size, "reg_at": reg_at, "width": width,
                "reset": reset, "k": k}

    def _reg_for(self, offset, size, write):
        reg = self._at.get(offset)
        if reg is None:
            raise Fault("BusFault", f"{'write to' if write else 'read of'} "
                        f"0x{self.base + offset:08X}: no {self.name} register there",
                        self.machine.pc, self.base + offset)
        return reg


class RegisterDevice(_RegisterMap):
    #: registers whose writes the chip ignores (read-only)
    READ_ONLY: tuple = ()

    def __init__(self, machine, svd_name: str, *, gate=None, span: int | None = None,
                 name: str | None = None):
        self._map(machine, svd_name, gate, span, name)
        self._readers = {}
        self._writers = {}
        for reg in self.map.registers.values():
            r = getattr(self, f"r_{reg.name}", None)
            w = getattr(self, f"w_{reg.name}", None)
            if r:
                self._readers[reg.name] = r
            if w:
                self._writers[reg.name] = w
        self.v = {}
        self.reset()

    # -- state -----------------------------------------------------------------------------
    WRITE_LOG = 4096                # writes kept per device (the first ones: boot order)

    def reset(self):
        self.v = {reg.name: reg.reset for reg in self.map.registers.values()}
        self.writes = []            # (instruction count, register, value) of the first writes

    def read_register(self, name: str) -> int:
        """A register's value as the program would read it (handlers run: side effects)."""
        r = self._readers.get(name)
        return r() if r else self.v[name]

    # -- bus side --------------------------------------------------------------------------
    def read(self, address: int, size: int) -> int:
        offset = address - self.base
        value, done = 0, 0
        while done < size:
            reg = self._reg_for(offset + done, size, False)
            width = reg.bits // 8
            shift = offset + done - reg.offset
            take = min(width - shift, size - done)
            full = self.read_register(reg.name)
            part = (full >> (8 * shift)) & ((1 << (8 * take)) - 1)
            value |= part << (8 * done)
            done += take
        return value

    def write(self, address: int, size: int, value: int):
        offset = address - self.base
        done = 0
        while done < size:
            reg = self._reg_for(offset + done, size, True)
            width = reg.bits // 8
            shift = offset + done - reg.offset
            take = min(width - shift, size - done)
            part = (value >> (8 * done)) & ((1 << (8 * take)) - 1)
            mask = ((1 << (8 * take)) - 1) << (8 * shift)
            merged = (self.v[reg.name] & ~mask) | (part << (8 * shift))
            if len(self.writes) < self.WRITE_LOG:
                self.writes.append((self.machine.instructions_now(), reg.name, merged))
            if reg.name not in self.READ_ONLY:
                w = self._writers.get(reg.name)
                if w:
                    w(merged, mask)
                else:
                    self.v[reg.name] = merged
            done += take


class _NativeValues:
    """``v`` of a native model: its registers by name, as stored (no read side effects)."""

    def __init__(self, device):
        self._device = device

    def __getitem__(self, name: str) -> int:
        dev = self._device
        return dev._stored(dev.map[name].offset)

    def __contains__(self, name):
        return name in self._device.map.registers

    def keys(self):
        return self._device.map.registers.keys()


class NativeRegisters(_RegisterMap):
    """A peripheral whose model is native: ``device`` is its number in the native core,
    ``stored(offset)`` reads a register as stored. Accesses reach it here only while the
    machine logs every access (or when it is gated or the offset holds no register);
    otherwise the native core takes them directly. A write that resets the chip (the
    watchdog's rules) raises :class:`ChipReset` here."""

    def __init__(self, machine, svd_name: str, device: int, stored, *, gate=None,
                 span: int | None = None, name: str | None = None):
        self._map(machine, svd_name, gate, span, name)
        self.device = device
        self._stored = stored
        self.v = _NativeValues(self)
        machine.core.add_route(device, self.base, self.base + self.size)

    def read_register(self, name: str) -> int:
        """A register's value as the program would read it (side effects included)."""
        reg = self.map[name]
        return self.read(self.base + reg.offset, reg.bits // 8)

    def _first_hole(self, address, size):
        for i in range(size):
            if address - self.base + i not in self._at:
                return address - self.base + i
        return address - self.base

    def read(self, address: int, size: int) -> int:
        value = self.machine.core.dev_read(self.device, address, size)
        if value is None:
            self._reg_for(self._first_hole(address, size), size, False)
        return value

    def write(self, address: int, size: int, value: int):
        core = self.machine.core
        if not core.dev_write(self.device, address, size, value):
            self._reg_for(self._first_hole(address, size), size, True)
        if core.reset_pending:
            raise ChipReset(*core.take_reset())
