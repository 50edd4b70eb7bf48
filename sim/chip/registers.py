"""Register addresses, widths, reset values and fields, in one place.

Everything on the MK64F12's peripheral bus, and the parts of the Cortex-M4 system control
space the SVD describes (SCB, SysTick, NVIC, FPU control), comes from ``regmap.py``, which is
generated from NXP's SVD (``svd.py``; checked against the SVD by the tests). The two core
blocks the SVD leaves out (DWT, CoreDebug) are described in ``armv7m_debug.svd``, written from
the ARMv7-M Architecture Reference Manual, which the firmware's register generator reads too:
:data:`CORE_EXTRA`.
"""

from __future__ import annotations

import pathlib
from dataclasses import dataclass
from functools import lru_cache

from . import regmap, svd

# The two core blocks the SVD leaves out, from armv7m_debug.svd (written from the ARMv7-M
# ARM: C1.8.7 DWT_CTRL, C1.8.8 DWT_CYCCNT, C1.6.5 DEMCR), read by the same SVD reader.
CORE_EXTRA_SVD = pathlib.Path(__file__).with_name("armv7m_debug.svd")
CORE_EXTRA = svd.parse(CORE_EXTRA_SVD.read_bytes(), ("DWT", "CoreDebug"))


@dataclass(frozen=True)
class Field:
    lsb: int
    width: int

    @property
    def mask(self) -> int:
        return ((1 << self.width) - 1) << self.lsb

    def get(self, value: int) -> int:
        return (value >> self.lsb) & ((1 << self.width) - 1)

    def put(self, value: int, field_value: int) -> int:
        return (value & ~self.mask) | ((field_value << self.lsb) & self.mask)


@dataclass(frozen=True)
class Register:
    peripheral: str
    name: str
    address: int
    offset: int
    bits: int
    reset: int
    fields: dict

    def field(self, name: str) -> Field:
        try:
            return Field(*self.fields[name])
        except KeyError:
            raise KeyError(f"{self.peripheral}_{self.name} has no field {name}") from None

    def bit(self, name: str) -> int:
        """Mask of a one-bit field."""
        f = self.field(name)
        if f.width != 1:
            raise ValueError(f"{self.peripheral}_{self.name}.{name} is {f.width} bits wide")
        return f.mask


@dataclass(frozen=True)
class Peripheral:
    name: str
    base: int
    registers: dict     # name -> Register

    def __getitem__(self, name: str) -> Register:
        try:
            return self.registers[name]
        except KeyError:
            raise KeyError(f"{self.name} has no register {name}") from None

    def address(self, name: str) -> int:
        return self[name].address

    @property
    def size(self) -> int:
        """Bytes from the base to the end of the last register."""
        return max(r.offset + r.bits // 8 for r in self.registers.values())


@lru_cache(maxsize=None)
def peripheral(name: str) -> Peripheral:
    """A modelled peripheral's register map, by its SVD name (or DWT, CoreDebug)."""
    table = CORE_EXTRA.get(name) or regmap.PERIPHERALS.get(name)
    if table is None:
        raise KeyError(f"no register table for {name}: add it to svd.MODELLED and regenerate")
    base, regs = table
    return Peripheral(name, base, {
        rname: Register(name, rname, base + off, off, bits, reset, fields)
        for rname, (off, bits, reset, fields) in regs.items()})


def irq(name: str) -> int:
    """IRQ number (exception number - 16) of an interrupt, by its SVD name."""
    return regmap.INTERRUPTS[name]


def irq_names() -> dict:
    """{IRQ number: SVD name}."""
    return {n: name for name, n in regmap.INTERRUPTS.items()}
