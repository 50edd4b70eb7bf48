"""A firmware image: the ELF's loadable bytes, its symbols, vector table and sections."""

from __future__ import annotations

import bisect
import os
import struct
from dataclasses import dataclass

from elftools.elf.elffile import ELFFile
from elftools.elf.sections import SymbolTableSection

from .registers import irq_names

FLASH_BASE, FLASH_SIZE = 0x0000_0000, 512 * 1024
SRAM_BASE, SRAM_SIZE = 0x1FFF_0000, 192 * 1024          # SRAM_L 64 KiB + SRAM_U 128 KiB
SRAM_U_BASE = 0x2000_0000
FLASH_CONFIG = 0x400                                     # flash configuration field, 16 bytes
SYSTEM_EXCEPTIONS = {1: "Reset", 2: "NMI", 3: "HardFault", 4: "MemManage", 5: "BusFault",
                     6: "UsageFault", 11: "SVCall", 12: "DebugMonitor", 14: "PendSV",
                     15: "SysTick"}
N_VECTORS = 16 + 86


class ImageError(ValueError):
    pass


@dataclass(frozen=True)
class Symbol:
    name: str
    address: int        # Thumb bit cleared for functions
    size: int
    kind: str           # STT_FUNC, STT_OBJECT, STT_NOTYPE, ...

    @property
    def end(self) -> int:
        return self.address + self.size


def mangled_prefixes(qualified: str) -> tuple:
    """Itanium-ABI name prefixes of a C++ function named ``ns::Class::name`` (any parameters,
    const or not); a name without ``::`` is an extern "C" name and matches itself exactly."""
    parts = qualified.split("::")
    if len(parts) == 1:
        return ()
    nested = "".join(f"{len(p)}{p}" for p in parts)
    return (f"_ZN{nested}E", f"_ZNK{nested}E")


def exception_name(number: int) -> str:
    if number in SYSTEM_EXCEPTIONS:
        return SYSTEM_EXCEPTIONS[number]
    if number >= 16:
        return irq_names().get(number - 16, f"IRQ{number - 16}")
    return f"Reserved{number}"


class Image:
    """An ELF for the MK64FX512: what a flash programmer writes and what a debugger knows."""

    def __init__(self, path: os.PathLike | str):
        self.path = os.fspath(path)
        with open(self.path, "rb") as f:
            elf = ELFFile(f)
            if elf["e_machine"] != "EM_ARM" or elf.elfclass != 32 or not elf.little_endian:
                raise ImageError(f"{self.path}: not a 32-bit little-endian ARM ELF")
            self.entry = elf["e_entry"]
            self.segments = []          # (load address, bytes), as a flash programmer writes them
            for seg in elf.iter_segments():
                if seg["p_type"] == "PT_LOAD" and seg["p_filesz"] > 0:
                    self.segments.append((seg["p_paddr"], seg.data()))
            self.sections = {}          # name -> (address, size, type, flags)
            for sec in elf.iter_sections():
                if sec["sh_flags"] & 0x2:           # SHF_ALLOC
                    self.sections[sec.name] = (sec["sh_addr"], sec["sh_size"], sec["sh_type"],
                                               sec["sh_flags"])
            self.symbols = {}
            symtab = elf.get_section_by_name(".symtab")
            if not isinstance(symtab, SymbolTableSection):
                raise ImageError(f"{self.path}: no symbol table (stripped?)")
            for sym in symtab.iter_symbols():
                kind = sym["st_info"]["type"]
                if not sym.name or kind in ("STT_FILE", "STT_SECTION"):
                    continue
                address = sym["st_value"]
                if kind == "STT_FUNC":
                    address &= ~1
                s = Symbol(sym.name, address, sym["st_size"], kind)
                # Keep a global definition over a local one of the same name.
                if sym.name not in self.symbols or sym["st_info"]["bind"] == "STB_GLOBAL":
                    self.symbols[sym.name] = s
        funcs = sorted((s for s in self.symbols.values() if s.kind == "STT_FUNC"),
                       key=lambda s: s.address)
        self._func_starts = [s.address for s in funcs]
        self._funcs = funcs
        for address, data in self.segments:
            if not (FLASH_BASE <= address and address + len(data) <= FLASH_BASE + FLASH_SIZE):
                raise ImageError(f"{self.path}: load segment 0x{address:08X}+{len(data)} is "
                                 "outside the 512 KiB flash")

    # --- symbols -------------------------------------------------------------------------
    def symbol(self, name: str) -> Symbol:
        """By exact (mangled) name, or by a C++ qualified name ``ns::Class::method`` when
        exactly one function matches."""
        if name in self.symbols:
            return self.symbols[name]
        matches = self.find_all(name)
        if len(matches) == 1:
            return matches[0]
        if not matches:
            raise KeyError(f"{os.path.basename(self.path)}: no symbol {name}")
        raise KeyError(f"{name} is ambiguous: {', '.join(sorted(m.name for m in matches))}")

    def find_all(self, qualified: str) -> list:
        prefixes = mangled_prefixes(qualified)
        if not prefixes:
            return [self.symbols[qualified]] if qualified in self.symbols else []
        return [s for s in self.symbols.values() if s.name.startswith(prefixes)]

    def has(self, name: str) -> bool:
        return name in self.symbols or bool(self.find_all(name))

    def function_at(self, address: int):
        """The function symbol containing ``address``, or None."""
        i = bisect.bisect_right(self._func_starts, address & ~1) - 1
        if i >= 0 and self._funcs[i].address <= address < self._funcs[i].end:
            return self._funcs[i]
        return None

    def describe(self, address: int) -> str:
        f = self.function_at(address)
        return f"0x{address:08X}" + (f" ({f.name}+0x{address - f.address:X})" if f else "")

    # --- flash contents ------------------------------------------------------------------
    def read(self, address: int, n: int) -> bytes:
        """Bytes of flash as programmed (0xFF where nothing is loaded)."""
        out = bytearray(b"\xff" * n)
        for base, data in self.segments:
            lo, hi = max(base, address), min(base + len(data), address + n)
            if lo < hi:
                out[lo - address:hi - address] = data[lo - base:hi - base]
        return bytes(out)

    def word(self, address: int) -> int:
        return struct.unpack("<I", self.read(address, 4))[0]

    @property
    def initial_sp(self) -> int:
        return self.word(0)

    def vector(self, number: int) -> int:
        """Handler address in vector slot ``number`` (exception number), Thumb bit cleared."""
        return self.word(4 * number) & ~1

    def vector_symbol(self, number: int):
        """Name of the function in vector slot ``number``, or None."""
        f = self.function_at(self.vector(number))
        return f.name if f and f.address == self.vector(number) else None

    @property
    def flash_config(self) -> dict:
        """The flash configuration field at 0x400 (reference manual, "Flash configuration
        field description"): backdoor key, FPROT0-3, FSEC, FOPT, FEPROT, FDPROT."""
        raw = self.read(FLASH_CONFIG, 16)
        return {"backdoor_key": raw[0:8], "FPROT": raw[8:12], "FSEC": raw[12], "FOPT": raw[13],
                "FEPROT": raw[14], "FDPROT": raw[15]}

    # --- RAM layout ----------------------------------------------------------------------
    def ram_sections(self) -> dict:
        """Allocated sections that live in SRAM (at their run addresses)."""
        return {name: (addr, size) for name, (addr, size, _, _) in self.sections.items()
                if SRAM_BASE <= addr < SRAM_BASE + SRAM_SIZE and size > 0}

    def ram_end(self) -> int:
        """First address above every statically allocated RAM section."""
        ends = [a + s for a, s in self.ram_sections().values()]
        return max(ends) if ends else SRAM_BASE

    def objects_straddling_sram_boundary(self) -> list:
        """Symbols spanning 0x2000_0000 (SRAM_L/SRAM_U): an access across it faults."""
        return [s for s in self.symbols.values()
                if s.size and s.address < SRAM_U_BASE < s.address + s.size]

    # --- the Intel hex the build ships ---------------------------------------------------
    def compare_hex(self, hex_path: os.PathLike | str) -> list:
        """Addresses where an Intel hex file differs from this ELF's loadable bytes (empty:
        the same image)."""
        # intelhex only to compare with a .hex file: the emulated board's runs never do
        from intelhex import IntelHex
        ih = IntelHex(os.fspath(hex_path))
        mine = {}
        for base, data in self.segments:
            for i, b in enumerate(data):
                mine[base + i] = b
        theirs = {a: ih[a] for a in ih.addresses()}
        return sorted(a for a in set(mine) | set(theirs) if mine.get(a) != theirs.get(a))
