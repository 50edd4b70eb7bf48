"""The Cortex-M4 core of the emulated chip: a CPU for the instructions (``cpu.py``: the
engine's own interpreter by default, or unicorn), this module and its native half
(``heliquad._simcore.Mk64Core``, sim/chip/mk64_core.cpp and, on the engine,
mk64_engine.cpp) for everything a CPU alone leaves out on an M-profile core. What follows
describes the unicorn path where the two differ; docs/teensy35-emulator.md ("The engine's
own CPU") says how the engine's differs (events and interrupts at instruction boundaries).

* Memory map: flash (read/execute), SRAM, and the peripheral spaces as MMIO dispatched to
  device models by address (:meth:`Machine.attach`). An access to a peripheral whose clock is
  gated, or to an address no register occupies, is a bus fault, as on the chip.
* Time base: core clock cycles from retired instructions (``timing.py`` states the cycle
  model), counted per translated block, exact to the instruction at every peripheral access
  (a memory hook on the peripheral spaces makes unicorn keep the PC precise there). No wall
  clock is ever read: runs are deterministic. Sleeping in WFI advances time to the next event.
* Events: device models schedule callbacks at a core cycle count; they run at the first
  block boundary at or after that count.
* Exceptions: the NVIC's enable, pending and active state, priorities with PRIGROUP,
  PRIMASK, BASEPRI and FAULTMASK; entry stacks a basic or extended (FP) frame with the 8-byte
  alignment flag and sets EXC_RETURN; the handler's return to EXC_RETURN reaches the harness
  (unicorn raises its exception-exit trap there), which unstacks the frame. Tail-chaining
  and nesting follow from taking the highest-priority pending exception at every boundary.
* Checks the chip would enforce or a test wants: FPU instructions before CPACR grants
  CP10/CP11 (a NOCP UsageFault on the chip), the first peripheral accesses, and an
  instruction budget on every run.

What runs at every block, every busy peripheral access and every interrupt is native: the
block accounting and the event deadline, the event queue (Python's events included, so
every event runs in one order), the NVIC's state, exception entry and return, WFI, and the
models of DWT, SysTick, UART0, I2C0, FTM0, FTM3, the watchdog and the flash module (their
Python classes are views), and the flash module's read-collision check. The native core calls back into Python (through ctypes function pointers, which take
the GIL) for a block not decoded yet, the FPU-enable check until the first FPU instruction and
an access to a device modelled in Python; it returns from a run for a Python event, a
breakpoint, a fault or a reset a native model caused (raised as :class:`ChipReset`). This
module keeps the rest: decoding (timing.py), the memory map, the Python devices, breakpoints,
faults and their messages, and the logs of the first accesses.
"""

from __future__ import annotations

import collections
import struct
from dataclasses import dataclass, field

from unicorn import UcError

from .cpu import (N_EXCEPTIONS, PERIPHERAL_BASE, PERIPHERAL_SIZE, PPB_BASE, PPB_SIZE,
                  make_cpu)
from .errors import ChipReset, EmulationError, Fault
from .image import FLASH_BASE, FLASH_SIZE, Image

__all__ = ["ChipReset", "EmulationError", "Fault", "Machine", "Stop", "Access", "Event",
           "Device", "PERIPHERAL_BASE", "PERIPHERAL_SIZE", "PPB_BASE", "PPB_SIZE", "N_EXCEPTIONS"]

_INTR_UNDEF = 1
# Why Mk64Core.run() returned (sim/chip/mk64_core.hpp, enum Run).
(_RUN_PY_EVENT, _RUN_STOP, _RUN_BUDGET, _RUN_TIME, _RUN_SLEEP_FOREVER, _RUN_PY_ERROR,
 _RUN_UC_ERROR, _RUN_FAULT, _RUN_BKPT, _RUN_INTR_FAULT, _RUN_RESET, _RUN_STOP_AT,
 _RUN_CPU_STOP, _RUN_DRAINED) = range(1, 15)
#: What a run may wait to leave the board (Machine.run's ``drain``; Core::Drain).
_DRAINS = {"usb": 1, "uart": 2}
# Native device numbers (Core::Device).
(DWT_DEVICE, SYSTICK_DEVICE, UART0_DEVICE, I2C0_DEVICE, FTM0_DEVICE, FTM3_DEVICE, WDOG_DEVICE,
 GPIO_IN_DEVICE, FTFE_DEVICE, NVIC_DEVICE, USB0_DEVICE, GPIO_OUT_DEVICE) = range(12)
# What a native event asks Python to do (Core::PyCall): the USB host's pump; the check of a
# bulk IN BD's write-back after the MPU changed.
PY_CALL_USB_PUMP, PY_CALL_USB_WRITE_BACK = 1, 2
# Block flags in the native table (Block::kMaskOp ...).
_MASK_OP, _ISB, _VFP, _WFI = 1, 2, 4, 8


@dataclass
class Stop:
    """Why a run returned."""
    reason: str         # budget | time | breakpoint | stop-at | bkpt | sleep-forever | <name>
    pc: int
    detail: dict = field(default_factory=dict)

    def __str__(self):
        return f"{self.reason} at 0x{self.pc:08X} {self.detail or ''}".strip()


@dataclass
class Access:
    """One peripheral access, for logs."""
    instruction: int
    cycle: int
    pc: int
    address: int
    size: int
    value: int
    write: bool
    device: str


class Event:
    """A Python callback at a core cycle (:meth:`Machine.at`), queued natively with every
    other event. ``due`` follows a core clock change when the event is in seconds."""
    __slots__ = ("_core", "seq", "fn", "scaled", "cancelled", "_due")

    def __init__(self, core, seq, due, fn, scaled):
        self._core, self.seq, self.fn, self.scaled, self._due = core, seq, fn, scaled, due
        self.cancelled = False

    @property
    def due(self) -> int:
        due = self._core.event_due(self.seq)
        if due is not None:
            self._due = due
        return self._due

    def cancel(self):
        self.cancelled = True
        self._core.cancel(self.seq)


class Device:
    """A memory-mapped model. Subclasses implement read/write of ``size`` bytes at an
    absolute address; ``clocked()`` False makes every access a bus fault."""

    name = "device"
    base = 0
    size = 0

    def clocked(self) -> bool:
        return True

    def gate_name(self) -> str:
        return "its clock gate"

    def read(self, address: int, size: int) -> int:
        raise NotImplementedError

    def write(self, address: int, size: int, value: int) -> None:
        raise NotImplementedError

    def reset(self) -> None:
        pass


class Machine:
    """One Cortex-M4F with the MK64FX512's memories. Peripherals attach as Devices."""

    TRACE_LENGTH = 256          # recent peripheral accesses kept for error messages
    FIRST_ACCESSES = 64         # the first accesses after reset, kept for boot-order checks

    def __init__(self, image: Image | None = None, *, core_hz: float = 20_971_520.0,
                 cpu: str | None = None):
        self.image = image
        self.cpu = make_cpu(self, cpu)      # unicorn or the engine (cpu.py)
        self.uc = self.cpu.uc               # unicorn's, when it is the CPU (None otherwise)
        self.core = self.cpu.core
        self._engine = self.cpu.name == "engine"
        self._decoder = None                # unicorn's block decoder, made at its first block
        self._blocks = {}                               # start -> timing.Block (decoded once)
        self._pages = collections.defaultdict(list)     # 4 KiB page -> [(lo, hi, device)]
        self.devices = []
        self._breakpoints = {}                         # address -> [callback]
        self._bp_hooks = set()
        self._stop_ats = set()
        self._py_events = {}                           # native event number -> Event
        self.native_calls = {}                         # Core::PyCall -> its Python part
        self._reset_core_hz = core_hz
        self.reset_listeners = []           # called after the devices reset
        self.pre_reset_listeners = []       # called before
        self.clock_listeners = []
        self.priority = _Priorities(self.core)
        self.exception_log = _ExceptionLog(self.core)
        self.reset()

    # ------------------------------------------------------------------ native state ----
    # The NVIC's state and the time base live in the native core; these are its views.
    cycles = property(lambda self: self.core.cycles, lambda self, v: setattr(self.core, "cycles", v),
                      doc="core cycles before the current block")
    instructions = property(lambda self: self.core.instructions,
                            doc="instructions retired before the current block")
    sleep_cycles = property(lambda self: self.core.sleep_cycles)
    handler_instructions = property(lambda self: self.core.handler_instructions,
                                    doc="instructions retired in handler mode (all handlers)")
    handler_cycles = property(lambda self: self.core.handler_cycles,
                              doc="core cycles in handlers, entry and return included")
    core_hz = property(lambda self: self.core.core_hz)
    enabled = property(lambda self: self.core.enabled,
                       lambda self, v: setattr(self.core, "enabled", v),
                       doc="bit n: exception n enabled (IRQs; system ones always)")
    pending = property(lambda self: self.core.pending,
                       lambda self, v: setattr(self.core, "pending", v))
    irq_lines = property(lambda self: self.core.irq_lines,
                         doc="level of each peripheral's interrupt request, by exception number")
    prigroup = property(lambda self: self.core.prigroup,
                        lambda self, v: setattr(self.core, "prigroup", v))
    vtor = property(lambda self: self.core.vtor, lambda self, v: setattr(self.core, "vtor", v))
    ccr = property(lambda self: self.core.ccr, lambda self, v: setattr(self.core, "ccr", v))
    fpccr = property(lambda self: self.core.fpccr, lambda self, v: setattr(self.core, "fpccr", v))
    active = property(lambda self: self.core.active,
                      doc="active exception numbers, innermost last")

    @property
    def exception_counts(self) -> collections.Counter:
        return collections.Counter({n: c for n, c in enumerate(self.core.exception_counts()) if c})

    @property
    def trace_enabled(self) -> bool:
        return self._trace_enabled

    @trace_enabled.setter
    def trace_enabled(self, on: bool):
        self._trace_enabled = bool(on)
        self._update_log_all()

    def _update_log_all(self):
        """Peripheral accesses go through Python while something logs them all."""
        self.core.log_all = len(self.first_accesses) < self.FIRST_ACCESSES or \
            self._trace_enabled or bool(self.access_listeners)

    # ------------------------------------------------------------------ memory map ----
    def attach(self, device: Device) -> Device:
        lo, hi = device.base, device.base + device.size
        if not ((PERIPHERAL_BASE <= lo and hi <= PERIPHERAL_BASE + PERIPHERAL_SIZE) or
                (PPB_BASE <= lo and hi <= PPB_BASE + PPB_SIZE)):
            raise ValueError(f"{device.name} at 0x{lo:08X} is outside the peripheral spaces")
        for page in range(lo >> 12, ((hi - 1) >> 12) + 1):
            for a, b, other in self._pages[page]:
                if a < hi and lo < b:
                    raise ValueError(f"{device.name} overlaps {other.name}")
            self._pages[page].append((lo, hi, device))
        self.devices.append(device)
        return device

    def device_at(self, address: int):
        for lo, hi, dev in self._pages.get(address >> 12, ()):
            if lo <= address < hi:
                return dev
        return None

    def _mmio_read(self, address, size):
        dev = self.device_at(address)
        if dev is None:
            self._bus_fault(address, size, False, "no peripheral is modelled at this address")
            return 0
        if not dev.clocked():
            self._bus_fault(address, size, False, f"{dev.name} is clock-gated ({dev.gate_name()} = 0)")
            return 0
        try:
            value = dev.read(address, size)
        except EmulationError as e:
            self._defer(e)
            return 0
        self._log_access(address, size, value, False, dev)
        return value

    def _mmio_write(self, address, size, value):
        dev = self.device_at(address)
        if dev is None:
            self._bus_fault(address, size, True, "no peripheral is modelled at this address")
            return
        if not dev.clocked():
            self._bus_fault(address, size, True, f"{dev.name} is clock-gated ({dev.gate_name()} = 0)")
            return
        value &= (1 << (8 * size)) - 1
        self._log_access(address, size, value, True, dev)
        try:
            dev.write(address, size, value)
        except EmulationError as e:
            self._defer(e)

    def _log_access(self, address, size, value, write, dev):
        if len(self.first_accesses) < self.FIRST_ACCESSES or self._trace_enabled:
            a = Access(self.instructions_now(), self.now(), self.pc, address, size, value, write,
                       dev.name)
            if len(self.first_accesses) < self.FIRST_ACCESSES:
                self.first_accesses.append(a)
                if len(self.first_accesses) == self.FIRST_ACCESSES:
                    self._update_log_all()
            if self._trace_enabled:
                self.trace.append(a)
        for listener in self.access_listeners:
            listener(address, size, value, write, dev)

    def _bus_fault(self, address, size, write, why):
        kind = "write" if write else "read"
        self._defer(Fault("BusFault", f"{size}-byte {kind} of 0x{address:08X} at "
                          f"{self.describe(self.pc)}: {why}", self.pc, address))

    def _defer(self, error: BaseException):
        """Stop at once; run() raises the error (a fault of the program, or a Python error
        inside a hook). The access's instruction does not retire."""
        if self._error is None:
            self._error = error
        self.core.request_error()
        self.cpu.stop()

    def _on_unmapped(self, uc, access, address, size, value, _):
        kinds = {19: "read", 20: "write", 21: "fetch"}     # UC_MEM_*_UNMAPPED
        self._unmapped = (kinds.get(access, str(access)), address, size)
        return False

    # ------------------------------------------------------------------ breakpoints ---
    def break_at(self, where, callback=None):
        """Call ``callback(machine)`` when the instruction at ``where`` (address or symbol)
        is about to execute. A callback returning a truthy value (or no callback) stops the
        run there with reason ``breakpoint`` (or the value, if it is a string)."""
        address = self._code_address(where)
        self._breakpoints.setdefault(address, []).append(callback)
        if address not in self._bp_hooks:
            self._bp_hooks.add(address)
            self.cpu.add_breakpoint(address, self._on_breakpoint)
        return address

    def stop_at(self, where) -> int:
        """Stop every run that reaches the instruction at ``where`` (address or symbol)
        before it executes, with reason ``stop-at``; the next run goes on through it. As a
        breakpoint with no callback, but native: no call into Python at the stop, for the
        stops a lockstep driver makes every loop."""
        address = self._code_address(where)
        self._stop_ats.add(address)
        self.core.add_stop_at(address)
        self.cpu.code_changed(address)      # unicorn: retranslate with the hook
        return address

    def _code_address(self, where) -> int:
        """An instruction's address: a symbol's, or an address with its Thumb bit cleared."""
        return self.image.symbol(where).address if isinstance(where, str) else where & ~1

    def _breakpoint_stop(self, address: int):
        """The breakpoint callbacks at ``address`` called; the Stop they ask for, or None."""
        stop = None
        for cb in self._breakpoints.get(address, ()):
            result = True if cb is None else cb(self)
            if result and stop is None:
                stop = result
        if not stop:
            return None
        return stop if isinstance(stop, Stop) else \
            Stop(stop if isinstance(stop, str) else "breakpoint", address)

    def _on_breakpoint(self, uc, address, size, _):
        """Unicorn's code hook at a breakpoint (the engine stops there instead: run())."""
        if address == self._bp_resume:
            self._bp_resume = None
            return
        try:
            stop = self._breakpoint_stop(address)
        except BaseException as e:           # noqa: BLE001 - re-raised by run()
            self._defer(e)
            return
        if stop:
            self._stop = stop
            self.core.request_stop()
            uc.emu_stop()

    # ------------------------------------------------------------------ reset ---------
    def load(self, image: Image):
        self.image = image
        self.write(FLASH_BASE, b"\xff" * FLASH_SIZE)
        for address, data in image.segments:
            self.write(address, data)
        self._blocks.clear()
        self.core.clear_blocks()
        self.reset()

    def reset(self):
        """Power-on reset: core registers, NVIC, time, every attached device."""
        self.core.reset(self._reset_core_hz)    # time, events, NVIC, the native devices
        self._py_events.clear()
        self._stop = None
        self._error = None
        self._unmapped = None
        self._bp_resume = None
        self.cpacr = 0
        self.fpu_granted_at = None      # instruction count of the CPACR write granting CP10/CP11
        self.fpu_synced_at = None       # instruction count of the first ISB after that
        self.first_fpu = None           # (instruction count, pc) of the first FPU instruction
        self.fpu_violation = None       # (instruction count, pc) of an FPU instruction before the grant
        self._fpu_watch = True
        self.first_accesses = []
        self.trace = collections.deque(maxlen=self.TRACE_LENGTH)   # with trace_enabled
        self.access_listeners = []
        self._trace_enabled = False
        self._update_log_all()
        for n in range(13):
            self.set_reg(f"r{n}", 0)
        for name, value in (("lr", 0xFFFF_FFFF), ("control", 0), ("primask", 0), ("basepri", 0),
                            ("faultmask", 0), ("xpsr", 1 << 24)):
            self.set_reg(name, value)
        for listener in self.pre_reset_listeners:
            listener()
        for dev in self.devices:
            dev.reset()
        for listener in self.reset_listeners:
            listener()
        if self.image is not None:
            self.set_reg("msp", self._read32(0))
            self.set_reg("sp", self._read32(0))
            self.set_reg("pc", self._read32(4) & ~1)

    # ------------------------------------------------------------------ time ----------
    @property
    def pc(self) -> int:
        return self.core.pc()

    def now(self) -> int:
        """Core cycles since reset, exact at the instruction executing now."""
        return self.core.now()

    def instructions_now(self) -> int:
        return self.core.instructions_now()

    def seconds(self, cycles: int | None = None) -> float:
        """Simulated time since reset at ``cycles`` (now by default)."""
        return self.core.seconds(self.core.now() if cycles is None else cycles)

    def cycles_after(self, seconds: float, start: int | None = None) -> int:
        """The core cycle count ``seconds`` after ``start`` (now) at the current clock."""
        start = self.now() if start is None else start
        return start + max(1, int(-(-seconds * self.core_hz // 1)))

    def set_clocks(self, core_hz: float, bus_hz: float):
        """The core (and bus) clock changed now: time stays continuous, and events scheduled
        in seconds keep their time (their cycle counts are rescaled)."""
        changed = core_hz != self.core.core_hz
        self.core.set_clocks(core_hz, bus_hz)
        if changed:
            for listener in self.clock_listeners:
                listener()

    def at(self, cycle: int, fn, *, scaled: bool = True) -> Event:
        """Run ``fn()`` at the first block boundary at or after core cycle ``cycle``.
        ``scaled``: the event is a time in seconds (moves with a core clock change);
        False for events counted in core cycles (SysTick)."""
        seq = self.core.at(cycle, scaled)
        ev = Event(self.core, seq, max(cycle, self.now()), fn, scaled)
        self._py_events[seq] = ev
        return ev

    def after(self, seconds: float, fn) -> Event:
        return self.at(self.cycles_after(seconds), fn)

    def attention(self):
        """Stop at the next block boundary to re-evaluate interrupts."""
        self.core.attention()

    def advance(self, cycles: int):
        """Let ``cycles`` core cycles pass without running any code (tests of the device
        models on a chip with no program): the events due meanwhile run in order."""
        target = self.core.cycles + cycles
        while True:
            seq = self.core.advance(target)
            if self.core.reset_pending:
                raise ChipReset(*self.core.take_reset())
            if not seq:
                return
            self._python_event(seq)

    # ------------------------------------------------------------------ decoding -------
    def _decode(self, address: int, size: int):
        """A block unicorn is about to run for the first time: decode it once (capstone)
        and give the native table its costs."""
        if self._decoder is None:
            # capstone only where unicorn runs: the engine decodes itself, and capstone's
            # library cannot be loaded under the sanitizers (RTLD_DEEPBIND), which the
            # engine's chip then runs under (.ci/sanitize)
            from .timing import BlockDecoder
            self._decoder = BlockDecoder()
        block = self._decoder.decode(bytes(self.uc.mem_read(address, size)), address)
        self._blocks[address] = block
        flags = (_MASK_OP if block.mask_op else 0) | (_ISB if block.isb else 0) | \
            (_VFP if block.vfp_at >= 0 else 0) | (_WFI if block.wfi else 0)
        self.core.add_block(address, size, block.n, block.cycles, flags, block.addrs, block.cum)

    def _fpu_block(self, address: int) -> bool:
        """Until the first FPU instruction: note the ISB that synchronises a CPACR grant,
        and judge the first FPU instruction when it comes."""
        block = self._blocks[address]
        if block.vfp_at >= 0:
            self._fpu_watch = False
            self.core.fpu_watch = False
            return self._check_fpu(block)
        if block.isb and self.fpu_granted_at is not None and self.fpu_synced_at is None:
            self.fpu_synced_at = self.instructions + block.n
        return True

    def _check_fpu(self, block) -> bool:
        """The first FPU instruction is about to run. Not granted: a NOCP UsageFault on the
        chip (False: the run stops with that fault). Granted but no ISB since: recorded."""
        error = self._first_fpu((self.instructions + block.vfp_at, block.addrs[block.vfp_at]))
        if error is not None:
            self._error = error
            self.core.request_error()
            return False
        return True

    def _first_fpu(self, at):
        """The first FPU instruction, ``at`` = (instruction count, pc), is about to run: the
        NOCP fault the chip would take if CPACR does not grant CP10/CP11 (else None, and
        recorded when no ISB has come since the grant)."""
        self.first_fpu = at
        if (self.cpacr >> 20) & 0xF != 0xF:
            self.fpu_violation = at
            return Fault("UsageFault", f"NOCP: FPU instruction at {self.describe(at[1])} "
                         f"(instruction {at[0]}) before CPACR granted CP10 and CP11 "
                         f"(CPACR = 0x{self.cpacr:08X}; a grant in the same block has "
                         "no ISB before it either)", at[1])
        if self.fpu_synced_at is None:
            self.fpu_violation = at
        return None

    def _cpu_stop(self):
        """The engine stopped for Python's judgement: the ISB after a CPACR grant (noted),
        the first FP instruction (judged: the engine then runs FP instructions), or a fault
        of the program (returned, for run() to raise)."""
        reason, pc, address, detail = self.core.cpu_stop()
        if reason == "isb":
            if self.fpu_granted_at is not None and self.fpu_synced_at is None:
                self.fpu_synced_at = self.core.instructions
            self.core.engine_watch_isb = False
            return None
        if reason == "no_fpu":
            error = self._first_fpu((self.core.instructions, pc))
            if error is None:
                self._fpu_watch = False
                self.core.fpu_watch = False
                self.core.engine_fpu = True
                self.core.engine_watch_isb = False
            return error
        return _engine_fault(reason, pc, address, detail, self.describe(pc))

    def grant_fpu(self, cpacr: int):
        """SCB_CPACR written (from the SCS model)."""
        self.cpacr = cpacr
        if (cpacr >> 20) & 0xF == 0xF and self.fpu_granted_at is None:
            self.fpu_granted_at = self.instructions_now()
            if self._engine:                # the engine stops after the next ISB
                self.core.engine_watch_isb = self._fpu_watch
                return
            cur = self.core.cur_start()
            if cur >= 0 and self._blocks[cur].isb:
                # ISB ends a block, so it follows this write in the same block
                self.fpu_synced_at = self.instructions + self._blocks[cur].n

    # ------------------------------------------------------------------ NVIC ----------
    def set_irq(self, irq: int, level: bool):
        """A peripheral's interrupt request line (level), by IRQ number."""
        self.core.set_irq(irq, bool(level))

    def pend(self, number: int):
        """Set an exception pending by exception number (SysTick 15, PendSV 14, IRQ n 16+n)."""
        self.core.pend(number)

    def unpend(self, number: int):
        self.core.unpend(number)

    def execution_priority(self, ignore_primask: bool = False) -> int:
        return self.core.execution_priority(ignore_primask)

    def pending_exception(self):
        """The pending, enabled exception the NVIC would present, or None."""
        return self.core.pending_exception()

    # ------------------------------------------------------------------ run ------------
    def run(self, instructions: int | None = None, seconds: float | None = None, *,
            drain: tuple | None = None, until: int | None = None) -> Stop:
        """Run until a breakpoint or BKPT stops it, ``instructions`` more instructions have
        retired (at a block boundary, never more) or ``seconds`` more of simulated time have
        passed (or the core cycle ``until``, instead of ``seconds``). Faults and resets
        raise. One of the limits is required. ``drain``:
        ``("usb", cycle)`` also ends the run (reason ``drained``) at the first boundary after
        the USB host's bulk IN poll found the board's IN endpoint empty after ``cycle``;
        ``("uart", None)`` once UART0 has nothing left to send and its transmit interrupt
        is off."""
        if instructions is None and seconds is None and until is None:
            raise ValueError("give an instruction budget or a simulated time")
        core = self.core
        if drain is not None:
            core.set_drain(_DRAINS[drain[0]], drain[1] or 0)
        instr_limit = core.instructions + instructions if instructions is not None else 1 << 62
        # The time limit is an event in seconds: it keeps its time if the clock changes.
        limit = core.time_limit(until if until is not None else
                                self.cycles_after(seconds, core.cycles)) \
            if seconds is not None or until is not None else None
        core.time_up = False
        self._stop = None
        core.clear_stop()
        self._update_log_all()
        try:
            while True:
                stop = self._after_run(core.run(instr_limit))
                if stop is not None:
                    return stop
        finally:
            if limit is not None:
                core.cancel(limit)
            core.time_up = False
            if drain is not None:
                core.set_drain(0, 0)

    def after_run(self, code: int):
        """What ``code``, returned by a run of the native core that its caller made itself
        (sim/chip/pil_frames.hpp), means: the Stop, or None to run on; faults and resets
        raise, as from :meth:`run`."""
        return self._after_run(code)

    def _after_run(self, code: int):
        """What a native run's return ``code`` means: the Stop to return, None to run on
        (a Python event run, a breakpoint that did not stop, the engine's FPU judgement);
        faults and resets raise."""
        core = self.core
        if code == _RUN_PY_EVENT:
            self._python_event(core.py_event)
            return None
        if code == _RUN_STOP:
            self._bp_resume = self._stop.pc
            return self._stop
        if code == _RUN_STOP_AT:
            pc = core.stop_at_pc
            if self._engine and pc in self._bp_hooks:    # the engine's breakpoints
                stop = self._breakpoint_stop(pc)
                if stop or pc not in self._stop_ats:
                    return stop
            return Stop("stop-at", pc)
        if code == _RUN_CPU_STOP:
            error = self._cpu_stop()
            if error is not None:
                raise error
            return None
        if code == _RUN_BKPT:
            pc = core.bkpt_pc
            return Stop("bkpt", pc, {"imm": self.read(pc, 2)[0]})
        if code == _RUN_BUDGET:
            return Stop("budget", self.pc, {"instructions": self.instructions})
        if code == _RUN_TIME:
            return Stop("time", self.pc, {"seconds": self.seconds()})
        if code == _RUN_DRAINED:
            return Stop("drained", self.pc)
        if code == _RUN_SLEEP_FOREVER:
            return Stop("sleep-forever", self.pc, {
                "detail": "WFI with no enabled interrupt and no event to come"})
        raise self._run_error(code)

    def _python_event(self, seq: int):
        """A Python event is due (its callback runs), or a native event needs its Python
        part (``native_calls``)."""
        ev = self._py_events.pop(seq, None)
        if ev is not None:
            ev.fn()
        call = self.core.take_py_call()
        if call:
            self.native_calls[call]()

    def _run_error(self, code: int) -> EmulationError:
        """The error a run stopped with (native codes, deferred Python errors)."""
        core = self.core
        error, self._error = self._error, None
        core.clear_error()
        if code == _RUN_PY_ERROR and error is not None:
            return error
        if code == _RUN_UC_ERROR:
            return error or self._uc_error(UcError(core.uc_error))
        if code == _RUN_FAULT:
            kind, message, pc, address = core.fault()
            return Fault(kind, message, pc, address)
        if code == _RUN_RESET:
            return ChipReset(*core.take_reset())
        if code == _RUN_INTR_FAULT:
            pc = core.intr_pc
            if core.intr_number == _INTR_UNDEF:
                return Fault("UsageFault", f"undefined instruction at {self.describe(pc)}", pc)
            return Fault("UsageFault", f"exception {core.intr_number} from the core at "
                         f"{self.describe(pc)}", pc)
        return error or EmulationError(f"run stopped with code {code}")

    def _uc_error(self, e: UcError) -> EmulationError:
        pc = self.pc
        if self._unmapped:
            kind, address, size = self._unmapped
            self._unmapped = None
            return Fault("BusFault" if kind != "fetch" else "MemManage",
                         f"{size}-byte {kind} of unmapped 0x{address:08X} at {self.describe(pc)}",
                         pc, address)
        text = str(e)
        if self.core.xn_fetched:
            address = self.core.xn_fetch
            return Fault("MemManage", f"instruction fetch from 0x{address:08X}, an execute-never "
                         f"region of the memory map, at {self.describe(pc)}", pc, address)
        if "WRITE_PROT" in text:
            return Fault("BusFault", f"write to flash at {self.describe(pc)}", pc)
        if "INSN_INVALID" in text:
            return Fault("UsageFault", f"undefined instruction at {self.describe(pc)}", pc)
        return Fault("Fault", f"{text} at {self.describe(pc)}", pc)

    def counts(self) -> dict:
        """What the native core has done since the machine was made: blocks entered, blocks
        decoded, peripheral accesses handled natively and in Python, events run natively and
        in Python, exceptions taken, emu_start calls, FPU-watch callbacks (for benchmarks)."""
        return self.core.counts()

    # ------------------------------------------------------------------ helpers -------
    def _read32(self, address: int) -> int:
        return struct.unpack("<I", self.read(address, 4))[0]

    def read(self, address: int, n: int) -> bytes:
        """Bytes of flash or SRAM (as a debugger reads them: no peripheral, no time)."""
        return self.cpu.read(address, n)

    def write(self, address: int, data: bytes):
        """Flash or SRAM written from outside (loading, a test's set-up)."""
        self.cpu.write(address, data)

    def describe(self, pc: int) -> str:
        return self.image.describe(pc) if self.image is not None else f"0x{pc:08X}"

    def reg(self, name: str) -> int:
        """A core register by name (r0-r12, sp, lr, pc, msp, psp, xpsr, control, primask,
        basepri, faultmask, fpscr, s0-s31)."""
        return self.cpu.reg(name)

    def set_reg(self, name: str, value: int):
        self.cpu.set_reg(name, value)

    def paint(self, lo: int, hi: int, word: int = 0xDEADBEEF):
        """Fill [lo, hi) with a 32-bit pattern (stack painting)."""
        lo, hi = (lo + 3) & ~3, hi & ~3
        self.write(lo, struct.pack("<I", word) * ((hi - lo) // 4))

    def painted_high_water(self, lo: int, hi: int, word: int = 0xDEADBEEF) -> int:
        """Lowest address in [lo, hi) whose painted word was overwritten (hi if none)."""
        lo, hi = (lo + 3) & ~3, hi & ~3
        data = self.read(lo, hi - lo)
        pattern = struct.pack("<I", word)
        for off in range(0, len(data), 4):
            if data[off:off + 4] != pattern:
                return lo + off
        return hi


def _engine_fault(reason: str, pc: int, address: int, detail: str, where: str) -> Fault:
    """The fault the chip would take for what stopped the engine (Core::engine_stopped)."""
    if reason == "bus_fault":
        if address == pc:
            return Fault("MemManage", f"instruction fetch from 0x{address:08X}, outside flash "
                         f"and SRAM, at {where}", pc, address)
        kind = "write" if "write" in detail else "read"
        if kind == "write" and address < FLASH_BASE + FLASH_SIZE:
            return Fault("BusFault", f"write to flash at {where}", pc, address)
        return Fault("BusFault", f"{kind} of unmapped 0x{address:08X} at {where}", pc, address)
    if reason == "unaligned":
        return Fault("UsageFault", f"UNALIGNED: {detail} 0x{address:08X} at {where}", pc, address)
    if reason == "div_by_zero":
        return Fault("UsageFault", f"DIVBYZERO: a division by zero at {where}", pc)
    if reason == "inv_state":
        return Fault("UsageFault", f"INVSTATE: {detail} at {where}", pc, address)
    return Fault("Fault", f"the engine stopped ({reason} {detail}) at {where}", pc)


class _Priorities:
    """The NVIC's priority of each exception (by number), a view onto the native core."""

    def __init__(self, core):
        self._core = core

    def __getitem__(self, n: int) -> int:
        return self._core.priority(n)

    def __setitem__(self, n: int, value: int):
        self._core.set_priority(n, value)

    def __len__(self):
        return N_EXCEPTIONS

    def __iter__(self):
        return iter(self._core.priorities())


class _ExceptionLog:
    """(cycle, 'enter'|'return', number) of the last 4096 exception entries and returns."""

    def __init__(self, core):
        self._core = core

    def __iter__(self):
        return iter(self._core.exception_log())

    def __len__(self):
        return len(self._core.exception_log())

    def __getitem__(self, i):
        return self._core.exception_log()[i]
