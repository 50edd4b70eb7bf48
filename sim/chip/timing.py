"""The time base: a stated cycles-per-instruction model of the Cortex-M4, applied per
translated block.

Time in the emulator is counted in core clock cycles, never read from the host's clock:
every retired instruction costs the cycles below, sleeping (WFI) costs the cycles until the
next event, and exception entry and return cost :data:`EXCEPTION_ENTRY_CYCLES` /
:data:`EXCEPTION_RETURN_CYCLES`. The figures are the Cortex-M4 Technical Reference Manual's
instruction timings (r0p1, "Processor instruction timings" and the FPU's "Instruction
timing"), with each range resolved to one number:

* P, the pipeline refill after a taken branch (1 to 3 in the manual), is :data:`REFILL` = 2.
* A conditional branch costs 1 not taken and 1 + P taken; the model does not know which
  happened, so it charges the middle, 2.
* SDIV/UDIV take 2 to 12 cycles (early termination): 7.
* Loads and stores are not pipelined with their neighbours (the manual lets a load or
  store followed by another save a cycle): LDR/STR 2, LDRD/STRD 3, LDM/STM/PUSH/POP 1 + N.
* No flash wait states: at 120 MHz core and 24 MHz flash the flash memory controller's
  prefetch buffer and cache hide most of them on straight-line code; the model charges none.

Consequently cycles are an estimate (the instruction counts are exact); use instruction
counts to compare builds and cycles to relate them to the 5 ms loop.
"""

from __future__ import annotations

import capstone
from capstone import arm as cs_arm

REFILL = 2
EXCEPTION_ENTRY_CYCLES = 12
EXCEPTION_RETURN_CYCLES = 12

_ONE = 1
_COSTS = {
    # loads and stores
    "ldr": 2, "ldrb": 2, "ldrh": 2, "ldrsb": 2, "ldrsh": 2, "ldrt": 2, "ldrbt": 2, "ldrht": 2,
    "ldrsbt": 2, "ldrsht": 2, "ldrex": 2, "ldrexb": 2, "ldrexh": 2,
    "str": 2, "strb": 2, "strh": 2, "strt": 2, "strbt": 2, "strht": 2, "strex": 2,
    "strexb": 2, "strexh": 2, "ldrd": 3, "strd": 3, "pld": 1,
    # multiply and divide
    "mla": 2, "mls": 2, "sdiv": 7, "udiv": 7,
    # barriers and system
    "dmb": 1, "dsb": 1, "isb": 1 + REFILL, "mrs": 2, "msr": 2,
    "tbb": 2 + REFILL, "tbh": 2 + REFILL,
    # FPU
    "vmla": 3, "vmls": 3, "vnmla": 3, "vnmls": 3, "vfma": 3, "vfms": 3, "vfnma": 3,
    "vfnms": 3, "vdiv": 14, "vsqrt": 14, "vldr": 2, "vstr": 2,
}
_LIST_OPS = {"ldm", "ldmia", "ldmdb", "ldmfd", "ldmea", "stm", "stmia", "stmdb", "stmfd",
             "stmea", "push", "pop", "vldmia", "vldmdb", "vstmia", "vstmdb", "vpush", "vpop",
             "vldm", "vstm"}
_BRANCHES = {"b", "bl", "blx", "bx"}
_COND_BRANCHES = {"cbz", "cbnz"}


_FPU_GROUPS = {g for g in (getattr(cs_arm, n, None) for n in
               ("ARM_GRP_VFP2", "ARM_GRP_VFP3", "ARM_GRP_VFP4", "ARM_GRP_FPARMV8")) if g}


def _name(insn) -> str:
    name = insn.insn_name()
    if name == "hint":                  # capstone files WFI, WFE, SEV, NOP, YIELD as hints
        name = insn.mnemonic.split(".")[0]
    return name


def _is_fpu(insn, name) -> bool:
    """An instruction of the FPU (coprocessors 10 and 11): needs CPACR to grant them."""
    return name.startswith("v") or name == "fmstat" or bool(_FPU_GROUPS & set(insn.groups))


def _pc_written(insn) -> bool:
    ops = insn.operands
    return bool(ops) and ops[0].type == cs_arm.ARM_OP_REG and ops[0].reg == cs_arm.ARM_REG_PC


def instruction_cycles(insn) -> int:
    """Cycles the model charges for one decoded instruction (capstone, detail on)."""
    name = _name(insn)
    if name in _LIST_OPS:
        regs = [op for op in insn.operands if op.type == cs_arm.ARM_OP_REG]
        if name in ("ldm", "ldmia", "ldmdb", "ldmfd", "ldmea", "stm", "stmia", "stmdb",
                    "stmfd", "stmea", "vldmia", "vldmdb", "vstmia", "vstmdb", "vldm", "vstm"):
            regs = regs[1:]                         # the first register is the base
        n = len(regs)
        pops_pc = any(op.reg == cs_arm.ARM_REG_PC for op in regs)
        return 1 + n + (REFILL if pops_pc else 0)
    if name in _BRANCHES:
        conditional = insn.cc not in (cs_arm.ARM_CC_AL, cs_arm.ARM_CC_INVALID)
        return 2 if conditional else 1 + REFILL
    if name in _COND_BRANCHES:
        return 2
    cost = _COSTS.get(name, _ONE)
    if name.startswith("ldr") and _pc_written(insn):
        return 2 + REFILL
    if cost == _ONE and name not in ("cmp", "cmn", "tst", "teq", "it") and _pc_written(insn):
        return 1 + REFILL                           # data processing into PC
    return cost


class Block:
    """One translated block of straight-line Thumb code, decoded once."""
    __slots__ = ("start", "size", "n", "cycles", "cum", "addrs", "vfp_at", "isb",
                 "wfi", "mask_op", "svc", "mnemonics")

    def __init__(self, start, size, insns, undecoded_halfwords=0):
        self.start = start
        self.size = size
        cum = []
        total = 0
        self.vfp_at = -1            # index of the first FPU instruction, -1 if none
        self.isb = self.wfi = self.mask_op = self.svc = False
        names = []
        for i, insn in enumerate(insns):
            cum.append(total)
            total += instruction_cycles(insn)
            name = _name(insn)
            names.append(name)
            if _is_fpu(insn, name) and self.vfp_at < 0:
                self.vfp_at = i
            if name == "isb":
                self.isb = True
            if name in ("cps", "cpsie", "cpsid", "msr"):
                self.mask_op = True
            if name == "svc":
                self.svc = True
        for _ in range(undecoded_halfwords):        # not decodable by capstone: 1 cycle each
            cum.append(total)
            total += 1
        self.wfi = bool(names) and names[-1] == "wfi"
        self.n = len(insns) + undecoded_halfwords
        self.cycles = total
        self.cum = cum                 # cycles before each instruction (the native core's table)
        self.addrs = [insn.address for insn in insns]
        self.mnemonics = names


class BlockDecoder:
    def __init__(self):
        self._cs = capstone.Cs(capstone.CS_ARCH_ARM, capstone.CS_MODE_THUMB | capstone.CS_MODE_MCLASS)
        self._cs.detail = True

    def decode(self, code: bytes, start: int) -> Block:
        insns = list(self._cs.disasm(code, start))
        used = sum(i.size for i in insns)
        return Block(start, len(code), insns, (len(code) - used + 1) // 2)
