"""The Cortex-M4 core of the emulated chip: unicorn for the instructions, this module for
everything unicorn leaves out on an M-profile core.

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
"""

from __future__ import annotations

import collections
import ctypes
import heapq
import itertools
import struct
from dataclasses import dataclass, field

from unicorn import (UC_ARCH_ARM, UC_HOOK_BLOCK, UC_HOOK_CODE, UC_HOOK_INTR,
                     UC_HOOK_MEM_READ, UC_HOOK_MEM_WRITE, UC_HOOK_MEM_UNMAPPED, UC_MODE_MCLASS,
                     UC_MODE_THUMB, UC_PROT_ALL, UC_PROT_EXEC, UC_PROT_READ, Uc, UcError)
from unicorn import arm_const as A

from .image import FLASH_BASE, FLASH_SIZE, SRAM_BASE, SRAM_SIZE, Image, exception_name
from .timing import EXCEPTION_ENTRY_CYCLES, EXCEPTION_RETURN_CYCLES, BlockDecoder

PERIPHERAL_BASE, PERIPHERAL_SIZE = 0x4000_0000, 0x0010_0000    # AIPS0/1 bridges and GPIO
PPB_BASE, PPB_SIZE = 0xE000_0000, 0x0010_0000                  # private peripheral bus

N_EXCEPTIONS = 16 + 86
THREAD_PRIORITY = 1 << 16           # lower than any configurable priority
EXC_RETURN_TRAP = 8                 # unicorn/QEMU EXCP_EXCEPTION_EXIT
_INTR_UNDEF, _INTR_SVC, _INTR_BKPT = 1, 2, 7
_FRAME_REGS = (A.UC_ARM_REG_R0, A.UC_ARM_REG_R1, A.UC_ARM_REG_R2, A.UC_ARM_REG_R3,
               A.UC_ARM_REG_R12, A.UC_ARM_REG_LR)
_S_REGS = tuple(getattr(A, f"UC_ARM_REG_S{i}") for i in range(16))
_CONTROL_SPSEL, _CONTROL_FPCA = 1 << 1, 1 << 2
_XPSR_ALIGN = 1 << 9


class EmulationError(RuntimeError):
    """Something the emulated chip cannot continue from."""


class Fault(EmulationError):
    """A fault the chip would raise (BusFault, UsageFault, MemManage, ...). The harness stops
    instead of entering the fault handler, so a test sees the cause and the instruction."""

    def __init__(self, kind: str, message: str, pc: int | None = None, address: int | None = None):
        self.kind, self.pc, self.address = kind, pc, address
        super().__init__(f"{kind}: {message}")


class ChipReset(EmulationError):
    """A reset the chip would perform (watchdog, SYSRESETREQ)."""

    def __init__(self, source: str, message: str):
        self.source = source
        super().__init__(f"reset by {source}: {message}")


@dataclass
class Stop:
    """Why a run returned."""
    reason: str                 # budget | time | breakpoint | bkpt | sleep-forever | <name>
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
    __slots__ = ("due", "seq", "fn", "scaled", "cancelled")

    def __init__(self, due, seq, fn, scaled):
        self.due, self.seq, self.fn, self.scaled, self.cancelled = due, seq, fn, scaled, False

    def __lt__(self, other):
        return (self.due, self.seq) < (other.due, other.seq)

    def cancel(self):
        self.cancelled = True


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

    def __init__(self, image: Image | None = None, *, core_hz: float = 20_971_520.0):
        self.image = image
        uc = Uc(UC_ARCH_ARM, UC_MODE_THUMB | UC_MODE_MCLASS)
        uc.ctl_set_cpu_model(A.UC_CPU_ARM_CORTEX_M4)        # before anything else
        uc.mem_map(FLASH_BASE, FLASH_SIZE, UC_PROT_READ | UC_PROT_EXEC)
        uc.mem_map(SRAM_BASE, SRAM_SIZE, UC_PROT_ALL)
        self.uc = uc
        self._raw = _RawHooks(uc, self._defer)
        for base, size in ((PERIPHERAL_BASE, PERIPHERAL_SIZE), (PPB_BASE, PPB_SIZE)):
            self._raw.mmio_map(base, size, self._mmio_read, self._mmio_write)
            # A memory hook on the peripheral spaces keeps the PC exact at every access
            # there (unicorn syncs it for memory hooks); the hook itself has nothing to do.
            self._raw.pc_sync_hook(base, base + size - 1)
        self._raw.block_hook(self._on_block)
        uc.hook_add(UC_HOOK_INTR, self._on_interrupt)
        uc.hook_add(UC_HOOK_MEM_UNMAPPED, self._on_unmapped)
        self._pc = _pc_reader(uc)
        self._decoder = BlockDecoder()
        self._blocks = {}
        self._pages = collections.defaultdict(list)     # 4 KiB page -> [(lo, hi, device)]
        self.devices = []
        self._breakpoints = {}                         # address -> [callback]
        self._bp_hooks = {}
        self._seq = itertools.count()
        self._reset_core_hz = core_hz
        self.reset_listeners = []           # called after the devices reset
        self.pre_reset_listeners = []       # called before
        self.clock_listeners = []

        # NVIC state (exception numbers 1..101)
        self.enabled = 0            # bit n: exception n enabled (IRQs; system ones always)
        self.pending = 0
        self.irq_lines = 0          # level of each peripheral's interrupt request, by exception number
        self.priority = [0] * N_EXCEPTIONS
        self.prigroup = 0
        self.vtor = 0
        self.active = []            # stack of active exception numbers, innermost last
        self._frames = []           # per active exception: (sp, fp frame, exc_return)
        self.cpacr = 0
        self.fpccr = 0xC000_0000
        self.ccr = 0x200            # STKALIGN: the Cortex-M4 (r0p1) resets it to 1
        self.exception_log = collections.deque(maxlen=4096)   # (cycle, 'enter'|'return', number)
        self.exception_counts = collections.Counter()
        self.reset()

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
        if len(self.first_accesses) < self.FIRST_ACCESSES or self.trace_enabled:
            a = Access(self.instructions_now(), self.now(), self.pc, address, size, value, write,
                       dev.name)
            if len(self.first_accesses) < self.FIRST_ACCESSES:
                self.first_accesses.append(a)
            if self.trace_enabled:
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
        try:
            self.uc.emu_stop()
        except UcError:
            pass

    def _on_unmapped(self, uc, access, address, size, value, _):
        kinds = {19: "read", 20: "write", 21: "fetch"}     # UC_MEM_*_UNMAPPED
        self._unmapped = (kinds.get(access, str(access)), address, size)
        return False

    # ------------------------------------------------------------------ breakpoints ---
    def break_at(self, where, callback=None):
        """Call ``callback(machine)`` when the instruction at ``where`` (address or symbol)
        is about to execute. A callback returning a truthy value (or no callback) stops the
        run there with reason ``breakpoint`` (or the value, if it is a string)."""
        address = self.image.symbol(where).address if isinstance(where, str) else where & ~1
        self._breakpoints.setdefault(address, []).append(callback)
        if address not in self._bp_hooks:
            self._bp_hooks[address] = self.uc.hook_add(UC_HOOK_CODE, self._on_breakpoint, None,
                                                       address, address)
            self.uc.ctl_remove_cache(address, address + 4)      # retranslate with the hook
        return address

    def _on_breakpoint(self, uc, address, size, _):
        if address == self._bp_resume:
            self._bp_resume = None
            return
        stop = None
        for cb in self._breakpoints.get(address, ()):
            result = True if cb is None else cb(self)
            if result and stop is None:
                stop = result
        if stop:
            self._stop = stop if isinstance(stop, Stop) else \
                Stop(stop if isinstance(stop, str) else "breakpoint", address)
            uc.emu_stop()

    # ------------------------------------------------------------------ reset ---------
    def load(self, image: Image):
        self.image = image
        self.uc.mem_write(FLASH_BASE, b"\xff" * FLASH_SIZE)
        for address, data in image.segments:
            self.uc.mem_write(address, data)
        self._blocks.clear()
        self.reset()

    def reset(self):
        """Power-on reset: core registers, NVIC, time, every attached device."""
        uc = self.uc
        self.cycles = 0                 # core cycles before the current block
        self.instructions = 0           # instructions retired before the current block
        self.sleep_cycles = 0
        self._epoch_cycles, self._epoch_seconds = 0, 0.0
        self.core_hz = self._reset_core_hz
        self._events = []
        self._cur = None
        self._deadline = 0
        self._instr_limit = 0
        self._stop = None
        self._error = None
        self._unmapped = None
        self._exc_return = None
        self._svc = False
        self._bp_resume = None
        self._sleeping = False
        self._watch_mask = False
        self._budget_hit = False
        self._last = None
        self.trace_enabled = False
        self.enabled = self.pending = self.irq_lines = 0
        self.priority = [0] * N_EXCEPTIONS
        self.priority[1], self.priority[2], self.priority[3] = -3, -2, -1
        self.prigroup = 0
        self.vtor = 0
        self.active, self._frames = [], []
        self.cpacr, self.fpccr, self.ccr = 0, 0xC000_0000, 0x200
        self.fpu_granted_at = None      # instruction count of the CPACR write granting CP10/CP11
        self.fpu_synced_at = None       # instruction count of the first ISB after that
        self.first_fpu = None           # (instruction count, pc) of the first FPU instruction
        self.fpu_violation = None       # (instruction count, pc) of an FPU instruction before the grant
        self._fpu_watch = True
        self.first_accesses = []
        self.trace = collections.deque(maxlen=self.TRACE_LENGTH)   # with trace_enabled
        self.access_listeners = []
        self.exception_log.clear()
        self.exception_counts.clear()
        self.handler_instructions = 0   # instructions retired in handler mode (all handlers)
        self.handler_cycles = 0         # core cycles spent in handlers, entry and return included
        self._handler_since = None
        for reg in (A.UC_ARM_REG_R0, A.UC_ARM_REG_R1, A.UC_ARM_REG_R2, A.UC_ARM_REG_R3,
                    A.UC_ARM_REG_R4, A.UC_ARM_REG_R5, A.UC_ARM_REG_R6, A.UC_ARM_REG_R7,
                    A.UC_ARM_REG_R8, A.UC_ARM_REG_R9, A.UC_ARM_REG_R10, A.UC_ARM_REG_R11,
                    A.UC_ARM_REG_R12):
            uc.reg_write(reg, 0)
        uc.reg_write(A.UC_ARM_REG_LR, 0xFFFF_FFFF)
        uc.reg_write(A.UC_ARM_REG_CONTROL, 0)
        uc.reg_write(A.UC_ARM_REG_PRIMASK, 0)
        uc.reg_write(A.UC_ARM_REG_BASEPRI, 0)
        uc.reg_write(A.UC_ARM_REG_FAULTMASK, 0)
        uc.reg_write(A.UC_ARM_REG_XPSR, 1 << 24)
        for listener in self.pre_reset_listeners:
            listener()
        for dev in self.devices:
            dev.reset()
        for listener in self.reset_listeners:
            listener()
        if self.image is not None:
            uc.reg_write(A.UC_ARM_REG_MSP, self._read32(0))
            uc.reg_write(A.UC_ARM_REG_SP, self._read32(0))
            uc.reg_write(A.UC_ARM_REG_PC, self._read32(4) & ~1)

    # ------------------------------------------------------------------ time ----------
    @property
    def pc(self) -> int:
        return self._pc()

    def now(self) -> int:
        """Core cycles since reset, exact at the instruction executing now."""
        cur = self._cur
        if cur is None:
            return self.cycles
        return self.cycles + cur.cycles_before(self._pc())

    def instructions_now(self) -> int:
        cur = self._cur
        if cur is None:
            return self.instructions
        return self.instructions + cur.executed_before(self._pc())

    def seconds(self, cycles: int | None = None) -> float:
        """Simulated time since reset at ``cycles`` (now by default)."""
        c = self.now() if cycles is None else cycles
        return self._epoch_seconds + (c - self._epoch_cycles) / self.core_hz

    def cycles_after(self, seconds: float, start: int | None = None) -> int:
        """The core cycle count ``seconds`` after ``start`` (now) at the current clock."""
        start = self.now() if start is None else start
        return start + max(1, int(-(-seconds * self.core_hz // 1)))

    def set_core_hz(self, hz: float):
        """The core clock changed now: time stays continuous, and events scheduled in
        seconds keep their time (their cycle counts are rescaled)."""
        if hz == self.core_hz:
            return
        now = self.now()
        self._epoch_seconds = self.seconds(now)
        self._epoch_cycles = now
        ratio = hz / self.core_hz
        self.core_hz = hz
        rescaled = []
        for ev in self._events:
            if ev.scaled and not ev.cancelled and ev.due > now:
                ev.due = now + max(1, int(round((ev.due - now) * ratio)))
            rescaled.append(ev)
        heapq.heapify(rescaled)
        self._events = rescaled
        self._update_deadline()
        for listener in self.clock_listeners:
            listener()

    def at(self, cycle: int, fn, *, scaled: bool = True) -> Event:
        """Run ``fn()`` at the first block boundary at or after core cycle ``cycle``.
        ``scaled``: the event is a time in seconds (moves with a core clock change);
        False for events counted in core cycles (SysTick)."""
        ev = Event(max(cycle, self.now()), next(self._seq), fn, scaled)
        heapq.heappush(self._events, ev)
        if ev.due < self._deadline:
            self._deadline = ev.due
        return ev

    def after(self, seconds: float, fn) -> Event:
        return self.at(self.cycles_after(seconds), fn)

    def attention(self):
        """Stop at the next block boundary to re-evaluate interrupts."""
        self._deadline = 0

    def _update_deadline(self):
        while self._events and self._events[0].cancelled:
            heapq.heappop(self._events)
        self._deadline = self._events[0].due if self._events else 1 << 62

    def _run_due_events(self):
        while self._events:
            ev = self._events[0]
            if ev.cancelled:
                heapq.heappop(self._events)
                continue
            if ev.due > self.cycles:
                break
            heapq.heappop(self._events)
            ev.fn()

    # ------------------------------------------------------------------ the block hook --
    def _on_block(self, address, size):
        """Unicorn is about to run the block at ``address``: the previous one retired.
        Stops before it (it does not run) when an event is due, the budget would be
        exceeded, or an interrupt waits on a mask the previous block may have lifted."""
        cur = self._cur
        if cur is not None:
            self.instructions += cur.n
            self.cycles += cur.cycles
            if cur.mask_op and self._watch_mask:
                self._cur = None
                self.uc.emu_stop()
                return
        block = self._blocks.get(address)
        if block is None or block.size != size:
            block = self._decoder.decode(bytes(self.uc.mem_read(address, size)), address)
            self._blocks[address] = block
        if self.cycles >= self._deadline or self.instructions + block.n > self._instr_limit:
            self._cur = None
            self._budget_hit = self.instructions + block.n > self._instr_limit
            self.uc.emu_stop()
            return
        if self._fpu_watch and not self._fpu_block(block):
            self._cur = None            # the chip would take a NOCP UsageFault here
            self.uc.emu_stop()
            return
        self._cur = block

    def _fpu_block(self, block) -> bool:
        """Until the first FPU instruction: note the ISB that synchronises a CPACR grant,
        and judge the first FPU instruction when it comes."""
        if block.vfp_at >= 0:
            self._fpu_watch = False
            return self._check_fpu(block)
        if block.isb and self.fpu_granted_at is not None and self.fpu_synced_at is None:
            self.fpu_synced_at = self.instructions + block.n
        return True

    def _check_fpu(self, block) -> bool:
        """The first FPU instruction is about to run. Not granted: a NOCP UsageFault on the
        chip (False: the run stops with that fault). Granted but no ISB since: recorded."""
        at = (self.instructions + block.vfp_at, block.addrs[block.vfp_at])
        self.first_fpu = at
        if (self.cpacr >> 20) & 0xF != 0xF:
            self.fpu_violation = at
            self._error = Fault("UsageFault", f"NOCP: FPU instruction at {self.describe(at[1])} "
                                f"(instruction {at[0]}) before CPACR granted CP10 and CP11 "
                                f"(CPACR = 0x{self.cpacr:08X}; a grant in the same block has "
                                "no ISB before it either)", at[1])
            return False
        if self.fpu_synced_at is None:
            self.fpu_violation = at
        return True

    def grant_fpu(self, cpacr: int):
        """SCB_CPACR written (from the SCS model)."""
        self.cpacr = cpacr
        if (cpacr >> 20) & 0xF == 0xF and self.fpu_granted_at is None:
            self.fpu_granted_at = self.instructions_now()
            if self._cur is not None and self._cur.isb:
                # ISB ends a block, so it follows this write in the same block
                self.fpu_synced_at = self.instructions + self._cur.n

    # ------------------------------------------------------------------ interrupts from unicorn
    def _on_interrupt(self, uc, intno, _):
        pc = uc.reg_read(A.UC_ARM_REG_PC)
        if intno == EXC_RETURN_TRAP:
            self._exc_return = pc | 1
        elif intno == _INTR_SVC:
            self._svc = True
        elif intno == _INTR_BKPT:
            imm = uc.mem_read(pc, 2)[0]
            self._stop = Stop("bkpt", pc, {"imm": imm})
        elif intno == _INTR_UNDEF:
            self._error = Fault("UsageFault", f"undefined instruction at {self.describe(pc)}", pc)
        else:
            self._error = Fault("UsageFault", f"exception {intno} from the core at "
                                f"{self.describe(pc)}", pc)
        uc.emu_stop()

    # ------------------------------------------------------------------ NVIC ----------
    def set_irq(self, irq: int, level: bool):
        """A peripheral's interrupt request line (level), by IRQ number."""
        bit = 1 << (irq + 16)
        if level:
            if not self.irq_lines & bit:
                self.irq_lines |= bit
                if (irq + 16) not in self.active:
                    self.pending |= bit
                    self.attention()
        else:
            self.irq_lines &= ~bit

    def pend(self, number: int):
        """Set an exception pending by exception number (SysTick 15, PendSV 14, IRQ n 16+n)."""
        self.pending |= 1 << number
        self.attention()

    def unpend(self, number: int):
        self.pending &= ~(1 << number)

    def _group(self, priority: int) -> int:
        if priority < 0:
            return priority
        return priority >> (self.prigroup + 1)

    def execution_priority(self, ignore_primask: bool = False) -> int:
        prio = THREAD_PRIORITY
        for n in self.active:
            prio = min(prio, self._group(self.priority[n]))
        uc = self.uc
        if not ignore_primask:
            if uc.reg_read(A.UC_ARM_REG_FAULTMASK) & 1:
                prio = min(prio, -1)
            if uc.reg_read(A.UC_ARM_REG_PRIMASK) & 1:
                prio = min(prio, 0)
        basepri = uc.reg_read(A.UC_ARM_REG_BASEPRI) & 0xF0
        if basepri:
            prio = min(prio, self._group(basepri))
        return prio

    def _enabled_mask(self) -> int:
        return self.enabled | 0xFFFF            # system exceptions need no NVIC enable

    def pending_exception(self):
        """The pending, enabled exception the NVIC would present, or None."""
        ready = self.pending & self._enabled_mask()
        if not ready:
            return None
        best, best_key = None, None
        n = 0
        while ready:
            if ready & 1:
                key = (self.priority[n], n)
                if best_key is None or key < best_key:
                    best, best_key = n, key
            ready >>= 1
            n += 1
        return best

    def _preempts(self, number: int, ignore_primask=False) -> bool:
        return self._group(self.priority[number]) < self.execution_priority(ignore_primask)

    def take_exception(self, number: int):
        """Exception entry: stack a frame on the main stack, set LR to EXC_RETURN and jump
        to the handler the vector table names."""
        uc = self.uc
        control = uc.reg_read(A.UC_ARM_REG_CONTROL)
        if control & _CONTROL_SPSEL and not self.active:
            raise Fault("UsageFault", "thread mode on the process stack (CONTROL.SPSEL) is not "
                        "modelled", self.pc)
        fp = bool(control & _CONTROL_FPCA) and bool(self.fpccr & (1 << 31))
        sp = uc.reg_read(A.UC_ARM_REG_SP)
        frame_size = 0x68 if fp else 0x20
        xpsr = uc.reg_read(A.UC_ARM_REG_XPSR)
        new_sp = sp - frame_size
        if (self.ccr & 0x200) or fp:
            if new_sp & 4:
                new_sp -= 4
                xpsr |= _XPSR_ALIGN
            else:
                xpsr &= ~_XPSR_ALIGN
        words = [uc.reg_read(r) for r in _FRAME_REGS] + [uc.reg_read(A.UC_ARM_REG_PC), xpsr]
        if fp:
            # Lazy stacking reserves this space and fills it when the handler first uses the
            # FPU; the harness fills it at once, which the program cannot tell apart.
            words += [uc.reg_read(r) for r in _S_REGS]
            words += [uc.reg_read(A.UC_ARM_REG_FPSCR), 0]
        try:
            uc.mem_write(new_sp, struct.pack(f"<{len(words)}I", *words))
        except UcError:
            raise Fault("BusFault", f"stacking a {exception_name(number)} frame at "
                        f"0x{new_sp:08X} failed (stack overflow?)", self.pc, new_sp) from None
        thread = not self.active
        if thread:
            self._handler_since = (self.instructions, self.cycles)
        exc_return = (0xFFFF_FFF9 if thread else 0xFFFF_FFF1) & ~(0 if not fp else 0x10)
        self.active.append(number)
        self._frames.append((new_sp, fp, exc_return))
        self.pending &= ~(1 << number)
        handler = self._read32(self.vtor + 4 * number)
        uc.reg_write(A.UC_ARM_REG_SP, new_sp)
        uc.reg_write(A.UC_ARM_REG_LR, exc_return)
        uc.reg_write(A.UC_ARM_REG_CONTROL, control & ~_CONTROL_FPCA)
        uc.reg_write(A.UC_ARM_REG_XPSR, (1 << 24) | number)
        uc.reg_write(A.UC_ARM_REG_PC, handler & ~1)
        self.cycles += EXCEPTION_ENTRY_CYCLES
        self.exception_log.append((self.cycles, "enter", number))
        self.exception_counts[number] += 1
        if not handler & 1:
            raise Fault("UsageFault", f"vector {number} ({exception_name(number)}) = "
                        f"0x{handler:08X} has no Thumb bit (INVSTATE)", self.pc)

    def return_from_exception(self, exc_return: int):
        uc = self.uc
        if not self.active:
            raise Fault("UsageFault", f"EXC_RETURN 0x{exc_return:08X} in thread mode (INVPC)",
                        exc_return)
        number = self.active[-1]
        sp_expected, fp, stacked_return = self._frames[-1]
        if exc_return not in (0xFFFF_FFF1, 0xFFFF_FFF9, 0xFFFF_FFE1, 0xFFFF_FFE9):
            raise Fault("UsageFault", f"EXC_RETURN 0x{exc_return:08X} from "
                        f"{exception_name(number)}: only main-stack returns are modelled",
                        exc_return)
        to_thread = bool(exc_return & 0x8)
        if to_thread != (len(self.active) == 1):
            raise Fault("UsageFault", f"EXC_RETURN 0x{exc_return:08X} from "
                        f"{exception_name(number)} names the wrong mode (INVPC)", exc_return)
        fp = not exc_return & 0x10
        sp = uc.reg_read(A.UC_ARM_REG_SP)
        n = 26 if fp else 8
        words = struct.unpack(f"<{n}I", bytes(uc.mem_read(sp, 4 * n)))
        for reg, value in zip(_FRAME_REGS, words[:6]):
            uc.reg_write(reg, value)
        xpsr = words[7]
        if fp:
            for reg, value in zip(_S_REGS, words[8:24]):
                uc.reg_write(reg, value)
            uc.reg_write(A.UC_ARM_REG_FPSCR, words[24])
        new_sp = sp + 4 * n + (4 if xpsr & _XPSR_ALIGN else 0)
        self.active.pop()
        self._frames.pop()
        uc.reg_write(A.UC_ARM_REG_SP, new_sp)
        control = uc.reg_read(A.UC_ARM_REG_CONTROL)
        uc.reg_write(A.UC_ARM_REG_CONTROL, (control | _CONTROL_FPCA) if fp else (control & ~_CONTROL_FPCA))
        uc.reg_write(A.UC_ARM_REG_XPSR, xpsr & ~_XPSR_ALIGN)
        uc.reg_write(A.UC_ARM_REG_PC, words[6] & ~1)
        self.cycles += EXCEPTION_RETURN_CYCLES
        self.exception_log.append((self.cycles, "return", number))
        if not self.active and self._handler_since is not None:
            self.handler_instructions += self.instructions - self._handler_since[0]
            self.handler_cycles += self.cycles - self._handler_since[1]
            self._handler_since = None
        if self.irq_lines & (1 << number):          # a level still asserted pends again
            self.pending |= 1 << number

    # ------------------------------------------------------------------ run ------------
    def run(self, instructions: int | None = None, seconds: float | None = None) -> Stop:
        """Run until a breakpoint or BKPT stops it, ``instructions`` more instructions have
        retired (at a block boundary, never more) or ``seconds`` more of simulated time have
        passed. Faults and resets raise. One of the two limits is required."""
        if instructions is None and seconds is None:
            raise ValueError("give an instruction budget or a simulated time")
        uc = self.uc
        instr_limit = self.instructions + instructions if instructions is not None else 1 << 62
        time_up = []
        # The time limit is an event in seconds: it keeps its time if the clock changes.
        limit = self.at(self.cycles_after(seconds, self.cycles), lambda: time_up.append(1)) \
            if seconds is not None else None
        self._stop = None
        try:
            while True:
                self._service()
                if self._stop is not None:
                    return self._stop
                if self.instructions >= instr_limit:
                    return Stop("budget", self.pc, {"instructions": self.instructions})
                if time_up:
                    return Stop("time", self.pc, {"seconds": self.seconds()})
                if self._sleeping:
                    if not self._sleep():
                        return Stop("sleep-forever", self.pc, {
                            "detail": "WFI with no enabled interrupt and no event to come"})
                    continue
                stop = self._execute(instr_limit)
                if stop is not None:
                    return stop
        finally:
            if limit is not None:
                limit.cancel()

    def _execute(self, instr_limit: int):
        """One emu_start: until a block boundary the harness must attend to."""
        uc = self.uc
        self._update_deadline()
        self._instr_limit = instr_limit
        self._budget_hit = False
        self._watch_mask = self._masked_pending()
        pc = self._pc()
        self._cur = None
        try:
            uc.emu_start(pc | 1, 0xFFFF_FFFF)
        except UcError as e:
            self._commit()
            if self._error is None:
                self._error = self._uc_error(e)
        else:
            self._commit()
        if self._error is not None:
            error, self._error = self._error, None
            raise error
        if self._budget_hit:
            self._budget_hit = False
            return Stop("budget", self.pc, {"instructions": self.instructions})
        if self._exc_return is not None:
            exc_return, self._exc_return = self._exc_return, None
            self.return_from_exception(exc_return)
        elif self._svc:
            self._svc = False
            self.pend(11)
        elif self._stop is not None:
            self._bp_resume = self._stop.pc if self._stop.reason != "bkpt" else None
            if self._stop.reason == "bkpt":
                uc.reg_write(A.UC_ARM_REG_PC, self._stop.pc + 2)
            return self._stop
        elif self._last is not None and self._last.wfi and \
                self._pc() == self._last.start + self._last.size:
            self._sleeping = True
        return None

    def _commit(self):
        """After unicorn returns: count what retired of the block it was in."""
        cur = self._cur
        self._last = cur
        if cur is not None:
            pc = self._pc()
            done = cur.executed_before(pc)
            self.instructions += done
            self.cycles += cur.cycles_before(pc) if done < cur.n else cur.cycles
            self._cur = None

    def _service(self):
        """At a boundary: due events, then the exception the NVIC presents, if it preempts."""
        self._run_due_events()
        number = self.pending_exception()
        if number is not None and self._preempts(number):
            self._sleeping = False
            self.take_exception(number)

    def _masked_pending(self) -> bool:
        number = self.pending_exception()
        return number is not None and not self._preempts(number) and \
            self._preempts(number, ignore_primask=True)

    def _sleep(self) -> bool:
        """WFI: wake on an exception that would preempt were PRIMASK clear; otherwise let
        time pass to the next event. False when nothing will ever wake the core."""
        number = self.pending_exception()
        if number is not None and self._preempts(number, ignore_primask=True):
            self._sleeping = False
            return True
        self._update_deadline()
        if not self._events:
            return False
        target = self._events[0].due
        if target > self.cycles:
            self.sleep_cycles += target - self.cycles
            self.cycles = target
        return True

    def _uc_error(self, e: UcError) -> EmulationError:
        pc = self.pc
        if self._unmapped:
            kind, address, size = self._unmapped
            self._unmapped = None
            return Fault("BusFault" if kind != "fetch" else "MemManage",
                         f"{size}-byte {kind} of unmapped 0x{address:08X} at {self.describe(pc)}",
                         pc, address)
        text = str(e)
        if "WRITE_PROT" in text:
            return Fault("BusFault", f"write to flash at {self.describe(pc)}", pc)
        if "INSN_INVALID" in text:
            return Fault("UsageFault", f"undefined instruction at {self.describe(pc)}", pc)
        return Fault("Fault", f"{text} at {self.describe(pc)}", pc)

    # ------------------------------------------------------------------ helpers -------
    def _read32(self, address: int) -> int:
        return struct.unpack("<I", bytes(self.uc.mem_read(address, 4)))[0]

    def read32(self, address: int) -> int:
        return self._read32(address)

    def read(self, address: int, n: int) -> bytes:
        return bytes(self.uc.mem_read(address, n))

    def write(self, address: int, data: bytes):
        self.uc.mem_write(address, bytes(data))

    def describe(self, pc: int) -> str:
        return self.image.describe(pc) if self.image is not None else f"0x{pc:08X}"

    def reg(self, name: str) -> int:
        return self.uc.reg_read(getattr(A, f"UC_ARM_REG_{name.upper()}"))

    def paint(self, lo: int, hi: int, word: int = 0xDEADBEEF):
        """Fill [lo, hi) with a 32-bit pattern (stack painting)."""
        lo, hi = (lo + 3) & ~3, hi & ~3
        self.uc.mem_write(lo, struct.pack("<I", word) * ((hi - lo) // 4))

    def painted_high_water(self, lo: int, hi: int, word: int = 0xDEADBEEF) -> int:
        """Lowest address in [lo, hi) whose painted word was overwritten (hi if none)."""
        lo, hi = (lo + 3) & ~3, hi & ~3
        data = self.read(lo, hi - lo)
        pattern = struct.pack("<I", word)
        for off in range(0, len(data), 4):
            if data[off:off + 4] != pattern:
                return lo + off
        return hi


class _RawHooks:
    """Hooks registered with the unicorn library directly, for the callbacks that run at
    every block and every peripheral access: the Python binding's generic wrappers cost
    about as much again as the callbacks themselves. Falls back to the binding when its
    internals are not there. Every callback is guarded: an exception stops the emulation
    and run() raises it."""

    def __init__(self, uc, on_error):
        self.uc, self.on_error = uc, on_error
        self._keep = []
        try:
            from unicorn.unicorn_py3 import unicorn as binding
            self.lib, self.handle = binding.uclib, uc._uch
            self.code_t, self.read_t = binding.HOOK_CODE_CFUNC, binding.MMIO_READ_CFUNC
            self.write_t, self.hook_h = binding.MMIO_WRITE_CFUNC, binding.uc_hook_h
        except (ImportError, AttributeError):
            self.lib = None

    def _add(self, htype, fptr, begin, end):
        h = self.hook_h()
        status = self.lib.uc_hook_add(self.handle, ctypes.byref(h), htype, fptr, None,
                                      ctypes.c_uint64(begin), ctypes.c_uint64(end))
        if status != 0:
            raise UcError(status)
        self._keep.append(fptr)

    def block_hook(self, fn):
        if self.lib is None:
            self.uc.hook_add(UC_HOOK_BLOCK, lambda uc, a, s, _: fn(a, s))
            return
        on_error = self.on_error

        def cb(handle, address, size, user):
            try:
                fn(address, size)
            except BaseException as e:       # noqa: BLE001 - re-raised by run()
                on_error(e)
        self._add(UC_HOOK_BLOCK, self.code_t(cb), 1, 0)

    def mmio_map(self, base, size, read, write):
        if self.lib is None:
            self.uc.mmio_map(base, size, lambda uc, off, n, _: read(base + off, n), None,
                             lambda uc, off, n, v, _: write(base + off, n, v), None)
            return
        on_error = self.on_error

        def rd(handle, offset, n, user):
            try:
                return read(base + offset, n)
            except BaseException as e:       # noqa: BLE001
                on_error(e)
                return 0

        def wr(handle, offset, n, value, user):
            try:
                write(base + offset, n, value)
            except BaseException as e:       # noqa: BLE001
                on_error(e)
        rp, wp = self.read_t(rd), self.write_t(wr)
        self._keep += [rp, wp]
        status = self.lib.uc_mmio_map(self.handle, base, size, rp, None, wp, None)
        if status != 0:
            raise UcError(status)

    def pc_sync_hook(self, begin, end):
        """A memory hook whose presence makes unicorn keep the PC exact at accesses in
        [begin, end]. Its callback does nothing; a side-effect-free function of the unicorn
        library (uc_arch_supported, which only reads its first argument) serves as one."""
        if self.lib is None:
            self.uc.hook_add(UC_HOOK_MEM_READ | UC_HOOK_MEM_WRITE, lambda *a: None, None,
                             begin, end)
            return
        noop = ctypes.cast(self.lib.uc_arch_supported, ctypes.c_void_p)
        self._add(UC_HOOK_MEM_READ | UC_HOOK_MEM_WRITE, noop, begin, end)


def _pc_reader(uc):
    """A fast read of the PC: the peripheral models ask for it at every access. Goes to the
    unicorn library directly when the binding exposes it, else through reg_read."""
    try:
        from unicorn.unicorn_py3.unicorn import uclib
        handle = uc._uch
    except (ImportError, AttributeError):
        return lambda: uc.reg_read(A.UC_ARM_REG_PC)
    buf = ctypes.c_uint64(0)
    ref = ctypes.byref(buf)
    read = uclib.uc_reg_read
    pc = A.UC_ARM_REG_PC

    def read_pc():
        read(handle, pc, ref)
        return buf.value & 0xFFFF_FFFF
    return read_pc
