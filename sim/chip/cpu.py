"""The CPU under the emulated chip, one of two behind one interface (:class:`Machine` holds
it as ``machine.cpu``; the native core ``machine.core`` is made by it):

* ``unicorn``: the unicorn library runs the instructions in translated blocks; the native
  core (sim/chip/mk64_core.cpp) counts time per block from a table Python decodes
  (timing.py), takes peripheral accesses through unicorn's MMIO callbacks (unicorn rolls its
  state back to find the PC at each) and exceptions at block boundaries.
* ``engine``: heliquad's own interpreter (sim/chip/thumb.hpp, proven equal to unicorn
  instruction by instruction by tests/thumb_engine_test.py) inside the native core
  (mk64_engine.cpp): it knows the exact PC and cycle at every instruction, so an event or
  an interrupt is taken at the first instruction boundary at or after its cycle, and a
  peripheral access is a call.

``HQ_CHIP_CPU`` (``unicorn`` or ``engine``) chooses for every machine made without an
explicit ``cpu``; the engine is the default (about twice as fast a loop), unicorn the
reference it was proven against (tests/chip_cpus_test.py flies the image on both; CI runs
the chip's tests on unicorn too).
Both expose the same: the memory (flash and SRAM) read and written from outside, the
registers by name, stopping a run from a callback, code breakpoints.
"""

from __future__ import annotations

import ctypes
import os

from unicorn import (UC_ARCH_ARM, UC_HOOK_CODE, UC_HOOK_MEM_UNMAPPED, UC_MODE_MCLASS,
                     UC_MODE_THUMB, UC_PROT_ALL, UC_PROT_EXEC, UC_PROT_NONE, UC_PROT_READ,
                     UC_TLB_VIRTUAL, Uc, UcError)
from unicorn import arm_const as A

from .errors import EmulationError
from .image import FLASH_BASE, FLASH_SIZE, SRAM_BASE, SRAM_SIZE, exception_name

PERIPHERAL_BASE, PERIPHERAL_SIZE = 0x4000_0000, 0x0010_0000    # AIPS0/1 bridges and GPIO
PPB_BASE, PPB_SIZE = 0xE000_0000, 0x0010_0000                  # private peripheral bus
N_EXCEPTIONS = 16 + 86

CPUS = ("unicorn", "engine")
DEFAULT_CPU = "engine"
CPU_VARIABLE = "HQ_CHIP_CPU"


def chosen_cpu(cpu: str | None = None) -> str:
    """``cpu``, else ``HQ_CHIP_CPU``, else the default; an unknown name is an error."""
    name = cpu or os.environ.get(CPU_VARIABLE) or DEFAULT_CPU
    if name not in CPUS:
        raise EmulationError(f"no CPU {name!r} for the emulated chip (choose one of "
                             f"{', '.join(CPUS)}; {CPU_VARIABLE} sets it for every chip)")
    return name


def make_cpu(machine, cpu: str | None = None):
    """The CPU ``cpu`` names (:func:`chosen_cpu`) for ``machine``, its native core made."""
    return (EngineCpu if chosen_cpu(cpu) == "engine" else UnicornCpu)(machine)


def _native_core():
    try:
        # a missing native core says so in one line (EmulationError)
        from heliquad._simcore import Mk64Core
    except ImportError as e:
        raise EmulationError(f"the emulator's native core (heliquad._simcore.Mk64Core) is "
                             f"not built: {e}") from None
    return Mk64Core


def _exception_names() -> list:
    return [exception_name(n) for n in range(N_EXCEPTIONS)]


def _address(fn) -> int:
    return ctypes.cast(fn, ctypes.c_void_p).value


class _Callbacks:
    """The ctypes callbacks the native core calls Python with (they take the GIL). An
    exception inside one is deferred to the machine (it stops the run; run() raises it)."""

    def __init__(self, machine, with_blocks: bool):
        m = machine

        def guarded(fn, failed):
            def call(*args):
                try:
                    return fn(*args)
                except BaseException as e:       # noqa: BLE001 - re-raised by run()
                    m._defer(e)
                    return failed
            return call

        read_t = ctypes.CFUNCTYPE(ctypes.c_uint64, ctypes.c_uint64, ctypes.c_uint32)
        write_t = ctypes.CFUNCTYPE(None, ctypes.c_uint64, ctypes.c_uint32, ctypes.c_uint64)
        self.functions = {"read": read_t(guarded(m._mmio_read, 0)),
                          "write": write_t(guarded(m._mmio_write, None))}
        if with_blocks:
            decode_t = ctypes.CFUNCTYPE(ctypes.c_int, ctypes.c_uint64, ctypes.c_uint32)
            fpu_t = ctypes.CFUNCTYPE(ctypes.c_int, ctypes.c_uint64)

            def decode(address, size):
                m._decode(address, size)
                return 0

            self.functions["decode"] = decode_t(guarded(decode, 1))
            self.functions["fpu_check"] = fpu_t(guarded(lambda a: 1 if m._fpu_block(a) else 0, 0))

    def addresses(self) -> dict:
        return {name: _address(fn) for name, fn in self.functions.items()}


class UnicornCpu:
    """Unicorn runs the instructions; the native core keeps time per translated block."""

    name = "unicorn"

    def __init__(self, machine):
        uc = Uc(UC_ARCH_ARM, UC_MODE_THUMB | UC_MODE_MCLASS)
        uc.ctl_set_cpu_model(A.UC_CPU_ARM_CORTEX_M4)        # before anything else
        uc.mem_map(FLASH_BASE, FLASH_SIZE, UC_PROT_READ | UC_PROT_EXEC)
        uc.mem_write(FLASH_BASE, b"\xff" * FLASH_SIZE)            # an erased chip
        uc.mem_map(SRAM_BASE, SRAM_SIZE, UC_PROT_ALL)
        self.uc = uc
        self._callbacks = _Callbacks(machine, with_blocks=True)
        self.core = self._make_core()
        self.core.install(PERIPHERAL_BASE, PERIPHERAL_SIZE, PPB_BASE, PPB_SIZE)
        # The core fills unicorn's TLB itself (mk64_core.hpp, install_tlb): the default
        # memory map's permissions, and RAM stores on unicorn's fast path.
        uc.ctl_set_tlb_mode(UC_TLB_VIRTUAL)
        self.core.install_tlb(SRAM_BASE, SRAM_SIZE)
        for base, size in ((PERIPHERAL_BASE, PERIPHERAL_SIZE), (PPB_BASE, PPB_SIZE)):
            # No access rights: every access there calls the core's protection hook, with the
            # PC brought up to date first, and then goes to the MMIO callbacks (install()).
            uc.mem_protect(base, size, UC_PROT_NONE)
        # The unmapped-access hook covers only the holes of the map: unicorn never lets a
        # page that any memory hook covers take the fast store path, so a hook over all of
        # the address space would send every RAM store through its slow path.
        mapped = sorted((lo, hi) for lo, hi, _ in uc.mem_regions())
        edge = 0
        for lo, hi in mapped + [(1 << 32, 1 << 32)]:
            if lo > edge:
                uc.hook_add(UC_HOOK_MEM_UNMAPPED, machine._on_unmapped, begin=edge, end=lo - 1)
            edge = max(edge, hi + 1)

    def _make_core(self):
        """The native core with unicorn's entry points (taken from the library the binding
        loaded; nothing is linked) and its register numbers."""
        try:
            # a missing binding says so in one line (EmulationError)
            from unicorn.unicorn_py3 import unicorn as binding
            lib, handle = binding.uclib, self.uc._uch
        except (ImportError, AttributeError) as e:
            raise EmulationError(
                "the emulator needs the unicorn Python binding's internals (unicorn_py3.unicorn."
                f"uclib, Uc._uch; unicorn>=2.1.4,<3 is pinned): {e}") from None
        functions = {name: _address(getattr(lib, name)) for name in
                     ("uc_emu_start", "uc_emu_stop", "uc_reg_read", "uc_reg_write", "uc_reg_write2",
                      "uc_reg_read_batch", "uc_reg_write_batch",
                      "uc_mem_read", "uc_mem_write", "uc_hook_add", "uc_mmio_map")}
        functions["handle"] = handle.value
        regs = {name: getattr(A, f"UC_ARM_REG_{name}") for name in
                ("R0", "R1", "R2", "R3", "R12", "LR", "PC", "SP", "XPSR", "EPSR", "CONTROL", "FPSCR",
                 "PRIMASK", "BASEPRI", "FAULTMASK")}
        regs.update({f"D{i}": getattr(A, f"UC_ARM_REG_D{i}") for i in range(8)})
        return _native_core()(functions, regs, self._callbacks.addresses(), _exception_names())

    def read(self, address: int, n: int) -> bytes:
        return bytes(self.uc.mem_read(address, n))

    def write(self, address: int, data: bytes):
        self.uc.mem_write(address, bytes(data))

    def reg(self, name: str) -> int:
        return self.uc.reg_read(getattr(A, f"UC_ARM_REG_{name.upper()}"))

    def set_reg(self, name: str, value: int):
        self.uc.reg_write(getattr(A, f"UC_ARM_REG_{name.upper()}"), value)

    def stop(self):
        """Stop the run in progress (from a callback inside it)."""
        try:
            self.uc.emu_stop()
        except UcError:
            pass

    def add_breakpoint(self, address: int, hook):
        """``hook(uc, address, size, user)`` before the instruction at ``address`` runs."""
        self.uc.hook_add(UC_HOOK_CODE, hook, None, address, address)
        self.code_changed(address)

    def code_changed(self, address: int):
        """Translate the instruction at ``address`` again (a hook added there)."""
        self.uc.ctl_remove_cache(address, address + 4)


class EngineCpu:
    """The engine runs the instructions inside the native core (mk64_engine.cpp)."""

    name = "engine"

    def __init__(self, machine):
        self._callbacks = _Callbacks(machine, with_blocks=False)
        core_type = _native_core()
        self.core = core_type.with_engine(self._callbacks.addresses(), _exception_names())
        self._regs = core_type.engine_registers()
        self.core.install(PERIPHERAL_BASE, PERIPHERAL_SIZE, PPB_BASE, PPB_SIZE)
        self.core.install_tlb(SRAM_BASE, SRAM_SIZE)
        self.uc = None

    def read(self, address: int, n: int) -> bytes:
        return self.core.mem_read(address, n)

    def write(self, address: int, data: bytes):
        self.core.mem_write(address, bytes(data))

    def _number(self, name: str) -> int:
        try:
            return self._regs[name.upper()]
        except KeyError:
            raise EmulationError(f"no register {name!r} on the engine") from None

    def reg(self, name: str) -> int:
        return self.core.reg(self._number(name))

    def set_reg(self, name: str, value: int):
        self.core.set_reg(self._number(name), value & 0xFFFF_FFFF)

    def stop(self):
        self.core.stop_now()

    def add_breakpoint(self, address: int, hook):
        """A stop address: the run stops before the instruction and Machine.run calls the
        breakpoint's callbacks (``hook`` is unicorn's; the engine needs none)."""
        del hook
        self.core.add_stop_at(address)

    def code_changed(self, address: int):
        del address                     # the engine's stop addresses need no retranslation
