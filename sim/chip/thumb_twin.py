"""The engine's CPU (heliquad._simcore.ThumbEngine, sim/chip/thumb.hpp) and unicorn side by
side, loaded with the same image and set to the same state: what the engine's differential
tests (tests/thumb_engine_test.py) and its benchmark (benchmarks/thumb_speed.py) drive.

Unicorn is set up as sim/chip/machine.py sets it up (Cortex-M4 model first, flash read and
execute, SRAM read/write); its FPU runs without a CPACR grant. A state is a dict: ``r`` (16
registers), ``apsr`` (N Z C V Q in bits 31..27), ``it`` (ITSTATE), ``s`` (32 S registers),
``fpscr``, ``control``, ``primask``, ``basepri``, ``faultmask``.

The FPSCR's cumulative exception flags are not kept by the engine, so :data:`FPSCR_COMPARED`
leaves them out; CONTROL is compared in its three M4 bits (unicorn also sets bit 3, SFPA,
which the M4 does not have)."""

from __future__ import annotations

import random

from unicorn import (UC_ARCH_ARM, UC_HOOK_BLOCK, UC_HOOK_CODE, UC_MODE_MCLASS, UC_MODE_THUMB,
                     UC_PROT_ALL, UC_PROT_EXEC, UC_PROT_READ, Uc, UcError)
from unicorn import arm_const as A

from heliquad._simcore import ThumbEngine

from .image import FLASH_BASE, FLASH_SIZE, SRAM_BASE, SRAM_SIZE
from .timing import BlockDecoder

FPSCR_COMPARED = 0xF7C0_0000        # N Z C V, AHP, DN, FZ, RMode
CONTROL_COMPARED = 0x7
RETURN_ADDRESS = 0x2001_FF00        # a called function returns here (LR): the run stops
CALL_STACK = 0x2001_F000

_R = [getattr(A, f"UC_ARM_REG_R{i}") for i in range(13)] + [A.UC_ARM_REG_SP, A.UC_ARM_REG_LR,
                                                             A.UC_ARM_REG_PC]
_S = [getattr(A, f"UC_ARM_REG_S{i}") for i in range(32)]
_SYS = {"control": A.UC_ARM_REG_CONTROL, "primask": A.UC_ARM_REG_PRIMASK,
        "basepri": A.UC_ARM_REG_BASEPRI, "faultmask": A.UC_ARM_REG_FAULTMASK}

#: Interesting single-precision values: zeros, denormals, the normal range's ends,
#: infinities, quiet and signalling NaNs of both signs, integers' edges.
SPECIAL_FLOATS = (0x0000_0000, 0x8000_0000, 0x0000_0001, 0x8000_0001, 0x007F_FFFF, 0x8040_0000,
                  0x0080_0000, 0x8080_0000, 0x0080_0001, 0x7F7F_FFFF, 0xFF7F_FFFF, 0x7F80_0000,
                  0xFF80_0000, 0x7FC0_0000, 0xFFC0_0001, 0x7F80_0001, 0xFFA0_0000, 0x7FBF_FFFF,
                  0x3F80_0000, 0xBF80_0000, 0x3F00_0000, 0x3FC0_0000, 0x4F00_0000, 0xCF00_0000,
                  0x4F80_0000, 0x4EFF_FFFF, 0x4F7F_FFFF, 0xBF00_0001, 0x3EFF_FFFF, 0x0100_0000,
                  0x4B7F_FFFF, 0x3F80_0001)


def new_unicorn() -> Uc:
    uc = Uc(UC_ARCH_ARM, UC_MODE_THUMB | UC_MODE_MCLASS)
    uc.ctl_set_cpu_model(A.UC_CPU_ARM_CORTEX_M4)        # before anything else
    uc.mem_map(FLASH_BASE, FLASH_SIZE, UC_PROT_READ | UC_PROT_EXEC)
    uc.mem_map(SRAM_BASE, SRAM_SIZE, UC_PROT_ALL)
    return uc


def random_float(rng: random.Random) -> int:
    """Bits of a single: a special value 40 % of the time, else any sign, exponent, mantissa
    (exponents near the ends and the middle alike)."""
    if rng.random() < 0.4:
        return rng.choice(SPECIAL_FLOATS)
    return rng.getrandbits(32)


def random_word(rng: random.Random) -> int:
    pick = rng.random()
    if pick < 0.25:
        return rng.choice((0, 1, 2, 0xFFFF_FFFF, 0x8000_0000, 0x7FFF_FFFF, 0xFF, 0xFFFF, 31, 32,
                           33, 0x1_0000, 0x8000))
    if pick < 0.5:
        return rng.randrange(0, 256)
    if pick < 0.6:
        return (-rng.randrange(1, 256)) & 0xFFFF_FFFF
    return rng.getrandbits(32)


def sram_pointer(rng: random.Random, aligned: bool = True) -> int:
    """An address in the middle of SRAM: any immediate offset (up to 4 KiB) stays inside."""
    p = rng.randrange(SRAM_BASE + 0x2000, SRAM_BASE + SRAM_SIZE - 0x2000)
    return p & ~3 if aligned else p


def random_state(rng: random.Random) -> dict:
    r = [random_word(rng) for _ in range(13)] + [sram_pointer(rng), rng.getrandbits(32) | 1, 0]
    fpscr = (rng.getrandbits(4) << 28) | (rng.randrange(4) << 22)
    fpscr |= (rng.random() < 0.3) << 24 | (rng.random() < 0.3) << 25 | (rng.random() < 0.2) << 26
    return {"r": r, "apsr": rng.getrandbits(5) << 27, "it": 0,
            "s": [random_float(rng) for _ in range(32)], "fpscr": fpscr,
            "control": 4 if rng.random() < 0.8 else 0,
            "primask": rng.getrandbits(1), "basepri": rng.choice((0, 0x40, 0x80)),
            "faultmask": 0}


class Twin:
    """The engine and unicorn with the same flash, SRAM and state."""

    def __init__(self, segments=(), sram: bytes | None = None, step_hook: bool = True):
        self.engine = ThumbEngine()
        self.engine.set_bus(lambda address, size: None, lambda address, size, value: False)
        self.uc = new_unicorn()
        self.uc.mem_write(FLASH_BASE, b"\xff" * FLASH_SIZE)
        for address, data in segments:
            self.write(address, data)
        if sram is not None:
            self.write(SRAM_BASE, sram)
        self._stop_range = (0, 0)
        self._seen = []
        self._stepping = False
        if step_hook:
            self.uc.hook_add(UC_HOOK_CODE, self._on_code)
        self.engine.add_stop_address(RETURN_ADDRESS)
        self._blocks = {}
        self._decoder = BlockDecoder()
        self.block_instructions = self.block_cycles = 0

    def write(self, address: int, data: bytes):
        self.engine.write(address, bytes(data))
        self.uc.mem_write(address, bytes(data))

    # --- state ---------------------------------------------------------------------------
    def set_state(self, st: dict):
        e, uc = self.engine, self.uc
        e.ipsr = 0
        for i in range(15):
            e.set_reg(i, st["r"][i])
            uc.reg_write(_R[i], st["r"][i])
        e.set_reg(15, st["r"][15])
        e.apsr = st["apsr"]
        e.itstate = st["it"]
        uc.reg_write(A.UC_ARM_REG_XPSR, st["apsr"] | (1 << 24) | ((st["it"] & 3) << 25)
                     | ((st["it"] >> 2) << 10))
        for i in range(32):
            e.set_sreg(i, st["s"][i])
            uc.reg_write(_S[i], st["s"][i])
        e.fpscr = st["fpscr"]
        uc.reg_write(A.UC_ARM_REG_FPSCR, st["fpscr"])
        for name, reg in _SYS.items():
            setattr(e, name, st[name])
            uc.reg_write(reg, st[name])
        if st["control"] & 4:               # unicorn keeps an FP context only with SFPA too
            uc.reg_write(A.UC_ARM_REG_CONTROL, st["control"] | 8)

    def engine_state(self) -> dict:
        e = self.engine
        return {"r": [e.reg(i) for i in range(16)], "apsr": e.apsr, "it": e.itstate,
                "s": [e.sreg(i) for i in range(32)], "fpscr": e.fpscr & FPSCR_COMPARED,
                "control": e.control & CONTROL_COMPARED, "primask": e.primask,
                "basepri": e.basepri, "faultmask": e.faultmask}

    def unicorn_state(self) -> dict:
        uc = self.uc
        xpsr = uc.reg_read(A.UC_ARM_REG_XPSR)
        st = {"r": [uc.reg_read(r) for r in _R], "apsr": xpsr & 0xF800_0000,
              "it": ((xpsr >> 25) & 3) | (((xpsr >> 10) & 0x3F) << 2),
              "s": [uc.reg_read(s) for s in _S],
              "fpscr": uc.reg_read(A.UC_ARM_REG_FPSCR) & FPSCR_COMPARED}
        for name, reg in _SYS.items():
            st[name] = uc.reg_read(reg)
        st["control"] &= CONTROL_COMPARED
        return st

    def sram_equal(self) -> bool:
        return bytes(self.uc.mem_read(SRAM_BASE, SRAM_SIZE)) == self.engine.read(SRAM_BASE,
                                                                                 SRAM_SIZE)

    # --- running -------------------------------------------------------------------------
    def _on_code(self, uc, address, size, _):
        if not self._stepping:
            return
        lo, hi = self._stop_range
        if not lo <= address < hi or (self._seen and address <= self._seen[-1]):
            uc.emu_stop()
            return
        self._seen.append(address)

    def step_unicorn(self, start: int, end: int):
        """Run unicorn from start until the PC leaves [start, end) or goes back: one
        instruction, or an IT instruction and its block up to end. None, or the UcError."""
        self._stop_range = (start, end)
        self._seen = []
        self._stepping = True
        try:
            self.uc.emu_start(start | 1, end, count=64)
        except UcError as err:
            return err
        return None

    def step_engine(self, n: int) -> str:
        return self.engine.run(1 << 62, n)

    def differences(self) -> dict:
        """{field: (engine, unicorn)} of what differs now, SRAM included."""
        a, b = self.engine_state(), self.unicorn_state()
        out = {k: (a[k], b[k]) for k in a if a[k] != b[k]}
        if not self.sram_equal():
            out["sram"] = ("differs", "")
        return out

    # --- calling functions ---------------------------------------------------------------
    def set_call(self, function: int, args=(), fargs=()):
        """Both at the entry of ``function`` with integer arguments in R0-R3 and float ones
        (bits) in S0-S15 (AAPCS-VFP), LR the return address, an FP context open, FPSCR 0."""
        r = [0] * 16
        r[:len(args)] = list(args)
        r[13], r[14], r[15] = CALL_STACK, RETURN_ADDRESS | 1, function & ~1
        s = [0] * 32
        s[:len(fargs)] = list(fargs)
        self.set_state({"r": r, "apsr": 0, "it": 0, "s": s, "fpscr": 0, "control": 4,
                        "primask": 0, "basepri": 0, "faultmask": 0})

    def call_engine(self, limit: int = 1_000_000) -> str:
        return self.engine.run(1 << 62, limit)

    def call_unicorn(self, start: int):
        """Unicorn from ``start`` to the return address; None or the UcError."""
        self._stepping = False
        try:
            self.uc.emu_start(start | 1, RETURN_ADDRESS)
        except UcError as err:
            return err
        return None

    def count_blocks(self):
        """Count unicorn's instructions and cycles as heliquad's machine does: a block hook
        and timing.py's model of each translated block (block_instructions, block_cycles)."""
        self.uc.hook_add(UC_HOOK_BLOCK, self._on_block)

    def _on_block(self, uc, address, size, _):
        block = self._blocks.get((address, size))
        if block is None:
            block = self._decoder.decode(bytes(uc.mem_read(address, size)), address)
            self._blocks[(address, size)] = block
        self.block_instructions += block.n
        self.block_cycles += block.cycles
