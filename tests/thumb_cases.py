"""The firmware image's instructions as the engine's differential test takes them
(tests/thumb_engine_test.py): every instruction of .text between the ARM mapping symbols
($t code, $d data: literal pools are never decoded), each with the IT instruction and the
block's earlier instructions before it when it sits in an IT block, deduplicated by bytes;
and the random states they run from, with memory operands pointed into SRAM."""

from __future__ import annotations

import random
from dataclasses import dataclass

import capstone
from capstone import arm as cs_arm
from elftools.elf.elffile import ELFFile
from elftools.elf.sections import SymbolTableSection

from heliquad.sim.chip.thumb_twin import random_state, sram_pointer

#: Run by their own tests (stop reasons), not by the differential one.
NOT_COMPARED = {"wfi", "bkpt", "svc", "udf"}
_REGS = {**{f"r{i}": i for i in range(13)}, "sb": 9, "sl": 10, "fp": 11, "ip": 12, "sp": 13,
         "lr": 14, "pc": 15}
_LISTS = {"ldm", "stm", "stmdb", "ldmdb", "vldmia", "vstmia", "vldmdb", "vstmdb"}
_UNALIGNED_OK = {"ldr", "str", "ldrh", "strh", "ldrsh"}


@dataclass
class Case:
    start: int          # the first instruction's address (the IT instruction in a block)
    end: int            # after the instruction under test
    count: int          # instructions the engine runs (the IT instruction included)
    insns: list         # capstone instructions from start to end


def code_ranges(elf_path) -> tuple:
    """(.text address, bytes, [(lo, hi)] of code by the mapping symbols)."""
    with open(elf_path, "rb") as f:
        elf = ELFFile(f)
        text = elf.get_section_by_name(".text")
        lo, data = text["sh_addr"], text.data()
        hi = lo + len(data)
        marks = []
        for sec in elf.iter_sections():
            if isinstance(sec, SymbolTableSection):
                for s in sec.iter_symbols():
                    if s.name[:2] in ("$t", "$d") and lo <= s["st_value"] < hi:
                        marks.append((s["st_value"] & ~1, s.name[1]))
    marks.sort()
    ranges = []
    for i, (address, kind) in enumerate(marks):
        if kind == "t":
            end = marks[i + 1][0] if i + 1 < len(marks) else hi
            if end > address:
                ranges.append((address, end))
    return lo, data, ranges


def text_instructions(elf_path) -> list:
    """[(capstone instruction, IT instruction or None, index in its block)] of .text's code."""
    cs = capstone.Cs(capstone.CS_ARCH_ARM, capstone.CS_MODE_THUMB | capstone.CS_MODE_MCLASS)
    cs.detail = True
    base, data, ranges = code_ranges(elf_path)
    out = []
    for lo, hi in ranges:
        address = lo
        while address < hi:
            it, left, index = None, 0, 0
            for got in cs.disasm(data[address - base:hi - base], address):
                if left:
                    index += 1
                    out.append((got, it, index))
                    left -= 1
                else:
                    out.append((got, None, 0))
                if got.insn_name() == "it":
                    it, left, index = got, len(got.mnemonic) - 1, 0
                address = got.address + got.size
            if address < hi:                        # not decodable: skip a halfword
                address += 2
    return out


def cases(instructions) -> tuple:
    """([Case], {address: Case key}) deduplicated by the bytes run."""
    by_address = {i.address: i for i, _, _ in instructions}
    seen, out = {}, []
    for insn, it, index in instructions:
        name = insn.mnemonic.split(".")[0]
        if name in NOT_COMPARED or name == "it":
            continue
        if it is None:
            case = Case(insn.address, insn.address + insn.size, 1, [insn])
        else:
            group, a = [], it.address
            while a <= insn.address:
                group.append(by_address[a])
                a += by_address[a].size
            if group[-1].address != insn.address:
                continue
            case = Case(it.address, insn.address + insn.size, index + 1, group)
        key = b"".join(bytes(i.bytes) for i in case.insns)
        if key not in seen:
            seen[key] = case
            out.append(case)
    return out, seen


def _reg(insn, reg) -> int:
    return _REGS[insn.reg_name(reg)]


def loads_pc(insn) -> bool:
    regs = [op.reg for op in insn.operands if op.type == cs_arm.ARM_OP_REG]
    name = insn.insn_name()
    return (name in ("pop", "ldm", "ldmdb") or name.startswith("ldr")) and \
        cs_arm.ARM_REG_PC in regs


def state_for(case: Case, rng: random.Random) -> tuple:
    """(state, [(address, bytes)] memory patches) for one run of the case: memory operands'
    bases in SRAM and their index registers small; branch registers odd flash addresses;
    words an instruction loads into the PC odd flash addresses too."""
    st = random_state(rng)
    patches = []
    for insn in case.insns:
        name = insn.insn_name()
        ops = insn.operands
        aligned = name not in _UNALIGNED_OK or rng.random() < 0.75
        for op in ops:
            if op.type == cs_arm.ARM_OP_MEM:
                if op.mem.base and _reg(insn, op.mem.base) != 15:
                    base = _reg(insn, op.mem.base)
                    st["r"][base] = sram_pointer(rng, aligned or base == 13)
                if op.mem.index:
                    st["r"][_reg(insn, op.mem.index)] = rng.randrange(0, 16 if
                                                                      loads_pc(insn) else 64)
        if name in _LISTS and ops and ops[0].type == cs_arm.ARM_OP_REG:
            st["r"][_reg(insn, ops[0].reg)] = sram_pointer(rng)
        if name in ("bx", "blx") and ops and ops[0].type == cs_arm.ARM_OP_REG:
            st["r"][_reg(insn, ops[0].reg)] = rng.randrange(0x400, 0x40000) | 1
        if loads_pc(insn):
            if name == "pop":
                base = st["r"][13]
            elif name in _LISTS:
                base = st["r"][_reg(insn, ops[0].reg)]
            else:
                mem = next(op.mem for op in ops if op.type == cs_arm.ARM_OP_MEM)
                base = st["r"][_reg(insn, mem.base)] + mem.disp
            words = [rng.randrange(0x400, 0x40000) | 1 for _ in range(40)]
            patches.append(((base & ~3) - 80, b"".join(w.to_bytes(4, "little") for w in words)))
    if any(is_fp(i) for i in case.insns[1:-1]):
        # unicorn checks for a new FP context (CONTROL.FPCA clear) once per translated block,
        # at its first FP instruction even when that one fails its IT condition; the engine,
        # as the architecture, at every FP instruction that passes its condition
        st["control"] = 4
    if any("control" in i.op_str for i in case.insns):
        st["control"] = 0       # with an FP context unicorn's CONTROL has bit 3 (not an M4's)
    st["r"][15] = case.start
    return st, patches


def is_fp(insn) -> bool:
    return insn.mnemonic.startswith("v")
