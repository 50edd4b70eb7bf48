"""The Cortex-M4's system control space: NVIC, SCB (with CPACR and the FPU control
registers), SysTick, the debug block's DEMCR, and the DWT cycle counter.

Addresses come from the SVD tables (SystemControl, SysTick, NVIC) and, for DWT and DEMCR,
from the ARMv7-M Architecture Reference Manual (``registers.CORE_EXTRA``). The exception
state itself (enable, pending, active, priorities) lives in the Machine, which takes and
returns exceptions; these registers are its programmer's view.
"""

from __future__ import annotations

from .machine import DWT_DEVICE, NVIC_DEVICE, SYSTICK_DEVICE, ChipReset, Device, Fault
from .registers import peripheral

_NVIC = peripheral("NVIC")
_SCB = peripheral("SystemControl")
_SYST = peripheral("SysTick")
_DWT = peripheral("DWT")
_DBG = peripheral("CoreDebug")

ISER, ICER = _NVIC.address("NVICISER0"), _NVIC.address("NVICICER0")
ISPR, ICPR = _NVIC.address("NVICISPR0"), _NVIC.address("NVICICPR0")
IABR, IPR = _NVIC.address("NVICIABR0"), _NVIC.address("NVICIP0")
STIR = _NVIC.address("NVICSTIR")
N_IRQ_WORDS = 4
N_IPR = sum(1 for r in _NVIC.registers if r.startswith("NVICIP"))
PRIORITY_MASK = 0xF0            # the MK64F12 implements 4 priority bits (SVD nvicPrioBits)
ICTR = 0xE000_E004              # ARMv7-M ARM B3.4.2: interrupt controller type
MVFR0, MVFR1 = 0xE000_EF40, 0xE000_EF44
# Cortex-M4 FPU (TRM, "FPU programmers model"): media and VFP feature registers
MVFR0_VALUE, MVFR1_VALUE = 0x1011_0021, 0x1100_0011
AIRCR_VECTKEY = 0x05FA


class SysTick:
    """SYST_CSR/RVR/CVR/CALIB: a 24-bit down-counter on the core clock (CALIB.NOREF is set:
    the MK64F12 has no external SysTick reference, so CLKSOURCE reads 1). It counts every
    core cycle, sleeping included; reaching 0 sets COUNTFLAG and, with TICKINT, pends the
    SysTick exception; the next cycle reloads RVR (a period of RVR + 1 cycles). Reading CSR
    clears COUNTFLAG; any CVR write clears the counter and COUNTFLAG.

    The model is native (``heliquad._simcore.Mk64Core``, sim/chip/mk64_devices.cpp); this
    is its view."""

    def __init__(self, machine):
        self.m = machine
        self.base = _SYST.base
        machine.core.systick_setup(self.base, _SYST["CALIB"].reset, _SYST["CSR"].reset)
        machine.core.add_route(SYSTICK_DEVICE, self.base, self.base + 0x10)

    def reset(self):
        pass                                    # the core resets it with the machine

    def _state(self):
        return self.m.core.systick_state()      # (csr, rvr, zero_at, stopped value, wraps)

    csr = property(lambda self: self._state()[0])
    rvr = property(lambda self: self._state()[1])
    zero_at = property(lambda self: self._state()[2],
                       doc="next core cycle at which the counter reads 0 (None: stopped)")
    stopped_value = property(lambda self: self._state()[3])
    wraps = property(lambda self: self._state()[4], doc="core cycles of the last 64 wraps")

    @property
    def enabled(self):
        return bool(self.csr & 1)

    def value(self, now):
        return self.m.core.systick_value(now)

    def period_s(self):
        return (self.rvr + 1) / self.m.core_hz

    def read(self, address, size):
        return self.m.core.dev_read(SYSTICK_DEVICE, address, size)

    def write(self, address, size, value):
        self.m.core.dev_write(SYSTICK_DEVICE, address, size, value)


class SystemControlSpace(Device):
    """0xE000_E000-0xE000_EFFF: ICTR, ACTLR, SysTick, NVIC, SCB, DEMCR, STIR, FPU control."""

    name = "SCS"
    base = 0xE000_E000
    size = 0x1000

    def __init__(self, machine):
        self.m = machine
        self.systick = SysTick(machine)
        # The set- and clear-enable words and the priority bytes are written natively
        # (mk64_core.cpp, Core::nvic_write: what _write_nvic does); reads come here.
        for lo, n in ((ISER, 4 * N_IRQ_WORDS), (ICER, 4 * N_IRQ_WORDS), (IPR, N_IPR)):
            machine.core.add_route(NVIC_DEVICE, lo, lo + n)
        self.reset()

    def reset(self):
        self.systick.reset()
        self.actlr = 0
        self.scr = 0
        self.shcsr = 0
        self.demcr = 0
        self.fpcar = 0
        self.fpdscr = 0
        self.shpr = [0, 0, 0]
        self.fault_status = {}

    # Word-wide registers; byte and halfword accesses are read-modify-write of the word.
    def read(self, address, size):
        if self.systick.base <= address < self.systick.base + 0x10:
            return self.systick.read(address, size)
        word = self._read_word(address & ~3)
        shift = 8 * (address & 3)
        return (word >> shift) & ((1 << (8 * size)) - 1)

    def write(self, address, size, value):
        if self.systick.base <= address < self.systick.base + 0x10:
            self.systick.write(address, size, value)
            return
        shift = 8 * (address & 3)
        mask = ((1 << (8 * size)) - 1) << shift
        self._write_word(address & ~3, (value << shift) & mask, mask)

    def _read_word(self, a):
        m = self.m
        if a == ICTR:
            return N_IRQ_WORDS - 2          # INTLINESNUM: (n + 1) * 32 lines, 86 IRQs -> 2
        if a == _SCB.address("ACTLR"):
            return self.actlr
        for base, kind in ((ISER, "en"), (ICER, "en"), (ISPR, "pend"), (ICPR, "pend"), (IABR, "act")):
            if base <= a < base + 4 * N_IRQ_WORDS:
                n = (a - base) // 4
                if kind == "en":
                    bits = m.enabled
                elif kind == "pend":
                    bits = m.pending
                else:
                    bits = sum(1 << x for x in m.active)
                return (bits >> (16 + 32 * n)) & 0xFFFF_FFFF
        if IPR <= a < IPR + N_IPR:
            n = a - IPR
            return sum((m.priority[16 + n + i] & 0xFF) << (8 * i) for i in range(4) if n + i < N_IPR)
        if a == _SCB.address("CPUID"):
            return _SCB["CPUID"].reset
        if a == _SCB.address("ICSR"):
            return self._icsr()
        if a == _SCB.address("VTOR"):
            return m.vtor
        if a == _SCB.address("AIRCR"):
            return 0xFA05_0000 | (m.prigroup << 8)
        if a == _SCB.address("SCR"):
            return self.scr
        if a == _SCB.address("CCR"):
            return m.ccr
        for i, name in enumerate(("SHPR1", "SHPR2", "SHPR3")):
            if a == _SCB.address(name):
                return sum((m.priority[4 + 4 * i + k] & 0xFF) << (8 * k) for k in range(4))
        if a == _SCB.address("SHCSR"):
            return self.shcsr
        for name in ("CFSR", "HFSR", "DFSR", "MMFAR", "BFAR", "AFSR"):
            if a == _SCB.address(name):
                return self.fault_status.get(name, 0)
        if a == _SCB.address("CPACR"):
            return m.cpacr
        if a == _DBG.address("DHCSR"):
            return 0                        # no debugger attached
        if a == _DBG.address("DEMCR"):
            return self.demcr
        if a == _SCB.address("FPCCR"):
            return m.fpccr
        if a == _SCB.address("FPCAR"):
            return self.fpcar
        if a == _SCB.address("FPDSCR"):
            return self.fpdscr
        if a == MVFR0:
            return MVFR0_VALUE
        if a == MVFR1:
            return MVFR1_VALUE
        if a == STIR:
            return 0
        raise Fault("BusFault", f"read of 0x{a:08X}: no system control register modelled there",
                    m.pc, a)

    def _icsr(self):
        m = self.m
        value = m.active[-1] if m.active else 0
        pend = m.pending_exception()
        if pend is not None:
            value |= (pend & 0x1FF) << 12
        if m.pending & ~0xFFFF:
            value |= 1 << 22                # ISRPENDING (an external interrupt)
        if len(m.active) <= 1:
            value |= 1 << 11                # RETTOBASE
        if m.pending & (1 << 15):
            value |= 1 << 26
        if m.pending & (1 << 14):
            value |= 1 << 28
        return value

    def _write_word(self, a, value, mask):
        """Write the bits of ``mask`` (``value`` already shifted into place) of the word at
        ``a``; an address with no register modelled is a bus fault."""
        if not (self._write_nvic(a, value, mask) or self._write_scb(a, value, mask)
                or self._write_fault_debug_fpu(a, value, mask)):
            raise Fault("BusFault", f"write to 0x{a:08X}: no system control register modelled "
                        "there", self.m.pc, a)

    def _write_nvic(self, a, value, mask) -> bool:
        """The NVIC's set/clear words, its priorities and STIR (False: not one of them)."""
        m = self.m
        if ISER <= a < ISER + 4 * N_IRQ_WORDS:
            m.enabled |= value << (16 + 32 * ((a - ISER) // 4))
            m.attention()
        elif ICER <= a < ICER + 4 * N_IRQ_WORDS:
            m.enabled &= ~(value << (16 + 32 * ((a - ICER) // 4)))
        elif ISPR <= a < ISPR + 4 * N_IRQ_WORDS:
            m.pending |= value << (16 + 32 * ((a - ISPR) // 4))
            m.attention()
        elif ICPR <= a < ICPR + 4 * N_IRQ_WORDS:
            m.pending &= ~(value << (16 + 32 * ((a - ICPR) // 4)))
        elif IABR <= a < IABR + 4 * N_IRQ_WORDS:
            pass                            # read-only
        elif IPR <= a < IPR + N_IPR:
            n = a - IPR
            for i in range(4):
                if (mask >> (8 * i)) & 0xFF and n + i < N_IPR:
                    m.priority[16 + n + i] = (value >> (8 * i)) & PRIORITY_MASK
            m.attention()
        elif a == STIR:
            m.pend(16 + (value & 0x1FF))
        else:
            return False
        return True

    def _write_scb(self, a, value, mask) -> bool:
        """ACTLR and the SCB's control words: ICSR, VTOR, AIRCR, SCR, CCR, SHPR1-3, SHCSR, and
        the read-only ICTR and CPUID (False: not one of them)."""
        m = self.m
        if a == _SCB.address("ACTLR"):
            self.actlr = (self.actlr & ~mask) | value
        elif a == _SCB.address("ICSR"):
            self._write_icsr(value)
        elif a == _SCB.address("VTOR"):
            m.vtor = ((m.vtor & ~mask) | value) & 0xFFFF_FF80
        elif a == _SCB.address("AIRCR"):
            if mask == 0xFFFF_FFFF and (value >> 16) == AIRCR_VECTKEY:
                m.prigroup = (value >> 8) & 7
                if value & (1 << 2):
                    raise ChipReset("SYSRESETREQ", "AIRCR.SYSRESETREQ written")
        elif a == _SCB.address("SCR"):
            self.scr = ((self.scr & ~mask) | value) & 0x16
        elif a == _SCB.address("CCR"):
            m.ccr = ((m.ccr & ~mask) | value) & 0x31B
        elif a in (_SCB.address("SHPR1"), _SCB.address("SHPR2"), _SCB.address("SHPR3")):
            first = 4 + 4 * ((a - _SCB.address("SHPR1")) // 4)
            for k in range(4):
                if (mask >> (8 * k)) & 0xFF and first + k in (4, 5, 6, 11, 14, 15):
                    m.priority[first + k] = (value >> (8 * k)) & PRIORITY_MASK
            m.attention()
        elif a == _SCB.address("SHCSR"):
            self.shcsr = (self.shcsr & ~mask) | value
        elif a in (ICTR, _SCB.address("CPUID")):
            pass
        else:
            return False
        return True

    def _write_icsr(self, value):
        """ICSR's set and clear bits: PendSV (28, 27), SysTick (26, 25), NMI (31)."""
        m = self.m
        if value & (1 << 26):
            m.pend(15)
        if value & (1 << 25):
            m.unpend(15)
        if value & (1 << 28):
            m.pend(14)
        if value & (1 << 27):
            m.unpend(14)
        if value & (1 << 31):
            m.pend(2)

    def _write_fault_debug_fpu(self, a, value, mask) -> bool:
        """The fault status and address registers, CPACR, the debug block's DHCSR and DEMCR,
        the FPU's control words and the read-only MVFR0/1 (False: not one of them)."""
        m = self.m
        if a in (_SCB.address(n) for n in ("CFSR", "HFSR", "DFSR")):
            name = next(n for n in ("CFSR", "HFSR", "DFSR") if _SCB.address(n) == a)
            self.fault_status[name] = self.fault_status.get(name, 0) & ~value   # write 1 to clear
        elif a in (_SCB.address("MMFAR"), _SCB.address("BFAR"), _SCB.address("AFSR")):
            pass
        elif a == _SCB.address("CPACR"):
            m.grant_fpu(((m.cpacr & ~mask) | value) & (0xF << 20))
        elif a == _DBG.address("DHCSR"):
            pass                            # debug halting: no debugger
        elif a == _DBG.address("DEMCR"):
            self.demcr = ((self.demcr & ~mask) | value) & 0x010F_07F1
            m.dwt.trace_changed(self.trace_enabled, m.now())
        elif a == _SCB.address("FPCCR"):
            m.fpccr = ((m.fpccr & ~mask) | value) & 0xC000_0000 | (m.fpccr & 0x1FB)
        elif a == _SCB.address("FPCAR"):
            self.fpcar = ((self.fpcar & ~mask) | value) & ~7
        elif a == _SCB.address("FPDSCR"):
            self.fpdscr = ((self.fpdscr & ~mask) | value) & 0x07C0_0000
        elif a in (MVFR0, MVFR1):
            pass
        else:
            return False
        return True

    @property
    def trace_enabled(self):
        return bool(self.demcr & _DBG["DEMCR"].bit("TRCENA"))


class Dwt(Device):
    """DWT_CTRL and DWT_CYCCNT: the cycle counter counts core cycles while DEMCR.TRCENA and
    CTRL.CYCCNTENA are both set (sleep included, like SysTick); it wraps at 2^32. Other DWT
    registers are not modelled (a bus fault).

    The model is native (the I2C and loop timing read CYCCNT all the time); this is its view."""

    name = "DWT"
    base = _DWT.base
    size = 0x1000
    _CTRL = _DWT.address("CTRL")
    _CYCCNT = _DWT.address("CYCCNT")

    def __init__(self, machine, scs: SystemControlSpace):
        self.m, self.scs = machine, scs
        machine.core.dwt_setup(self._CTRL, self._CYCCNT, _DWT["CTRL"].reset)
        machine.core.add_route(DWT_DEVICE, min(self._CTRL, self._CYCCNT),
                               max(self._CTRL, self._CYCCNT) + 4)

    def reset(self):
        pass                                    # the core resets it with the machine

    ctrl = property(lambda self: self.m.core.dwt_state()[0])
    base_value = property(lambda self: self.m.core.dwt_state()[1])
    since = property(lambda self: self.m.core.dwt_state()[2],
                     doc="core cycle at which base_value held (None: stopped)")

    def running(self):
        return bool(self.ctrl & 1) and self.scs.trace_enabled

    def cyccnt(self, now=None):
        return self.m.core.dwt_cyccnt(self.m.now() if now is None else now)

    def trace_changed(self, trcena: bool, now):
        """DEMCR.TRCENA written: freeze or resume the counter."""
        self.m.core.dwt_trace(trcena, now)

    def read(self, address, size):
        value = self.m.core.dev_read(DWT_DEVICE, address, size)
        if value is None:
            raise Fault("BusFault", f"read of 0x{address:08X}: DWT register not modelled",
                        self.m.pc, address)
        return value

    def write(self, address, size, value):
        if not self.m.core.dev_write(DWT_DEVICE, address, size, value):
            raise Fault("BusFault", f"write to 0x{address:08X}: DWT register not modelled",
                        self.m.pc, address)
