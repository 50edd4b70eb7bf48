"""The engine's CPU (sim/chip/thumb.hpp, heliquad._simcore.ThumbEngine) against unicorn.

* Every instruction of the image's .text (tests/thumb_cases.py: code by the mapping symbols,
  each IT block's instructions run with their IT instruction), deduplicated by bytes, from
  STATES random states each: registers, flags, ITSTATE, S0-S31, FPSCR (without its
  cumulative flags: the engine does not keep them), CONTROL's M4 bits, the masks and all of
  SRAM compared after the step.
* Whole functions of the image (libm and the firmware's own) from the same inputs: results,
  state and the instruction count.
* The cycle model: every .text instruction costs what sim/chip/timing.py charges it.
* The stop reasons, decode-cache invalidation, an undefined encoding.
Deterministic (a fixed seed); no timing asserts (benchmarks/thumb_speed.py measures speed).
"""

import functools
import random

import pytest
from unicorn.arm_const import UC_ARM_REG_XPSR

import thumb_cases
from heliquad.sim.base.firmware_image import teensy35_image
from heliquad.sim.chip.image import Image
from heliquad.sim.chip.thumb_twin import SRAM_BASE, SRAM_SIZE, Twin
from heliquad.sim.chip.timing import instruction_cycles

STATES = 3
SEED = 20261129
CODE = 0x2000_0000          # where hand-written code goes (SRAM)


@functools.lru_cache(maxsize=1)
def image():
    return Image(teensy35_image("elf"))


@functools.lru_cache(maxsize=1)
def instructions():
    return thumb_cases.text_instructions(image().path)


def _twin(seed=SEED):
    rng = random.Random(seed)
    return Twin(image().segments, bytes(rng.getrandbits(8) for _ in range(SRAM_SIZE)))


def _run_case(twin, case, rng):
    """'compared', 'faulted' (both), 'skipped' (the PC got no Thumb address), or a mismatch
    description."""
    st, patches = thumb_cases.state_for(case, rng)
    for address, data in patches:
        twin.write(address, data)
    twin.set_state(st)
    stop = twin.step_engine(case.count)
    err = twin.step_unicorn(case.start, case.end)
    if stop in ("bus_fault", "unaligned", "div_by_zero"):
        took = err is not None or twin.uc.reg_read(UC_ARM_REG_XPSR) & 0x1FF
        return "faulted" if took else f"engine {stop}, unicorn ran on"
    if stop in ("exc_return", "inv_state"):
        return "skipped"
    if err is not None:
        return f"unicorn {err}, engine {stop}"
    if stop not in ("limit", "mask_changed"):
        return f"engine stopped: {stop} {twin.engine.stop_detail}"
    diff = twin.differences()
    return "compared" if not diff else repr(diff)


def test_every_instruction_of_the_image_runs_as_in_unicorn():
    all_insns = instructions()
    case_list, _ = thumb_cases.cases(all_insns)
    rng = random.Random(SEED)
    twin = _twin()
    counts = {"compared": 0, "faulted": 0, "skipped": 0}
    bad = []
    for case in case_list:
        for _ in range(STATES):
            got = _run_case(twin, case, rng)
            if got in counts:
                counts[got] += 1
            else:
                insn = case.insns[-1]
                bad.append(f"0x{insn.address:x} {insn.mnemonic} {insn.op_str}: {got}")
                twin.uc.mem_write(SRAM_BASE, twin.engine.read(SRAM_BASE, SRAM_SIZE))
            if got == "faulted" or got not in counts:
                twin = _resync(twin)
    names = {i.insn_name() for i, _, _ in all_insns}
    print(f"\n{len(all_insns)} instructions in .text, {len(case_list)} distinct encodings "
          f"(IT blocks as run), {len(names)} capstone names; runs: {counts}")
    assert not bad, f"{len(bad)} mismatches:\n" + "\n".join(bad[:40])
    assert counts["compared"] >= STATES * len(case_list) * 0.95


def _resync(twin):
    """A fresh unicorn with the engine's SRAM (unicorn took an exception: its stack frame,
    its handler mode)."""
    fresh = Twin(image().segments, twin.engine.read(SRAM_BASE, SRAM_SIZE))
    return fresh


def test_every_instruction_costs_what_the_timing_model_charges():
    twin = Twin(image().segments)
    wrong = []
    for insn, it, _ in instructions():
        size, cycles, cycles_in_it, _ = twin.engine.cost(insn.address)
        engine = cycles_in_it if it is not None else cycles
        model = instruction_cycles(insn)
        if size != insn.size or engine != model:
            wrong.append(f"0x{insn.address:x} {insn.mnemonic} {insn.op_str}: engine "
                         f"{engine} cycles {size} bytes, model {model} cycles {insn.size} bytes")
    assert not wrong, "\n".join(wrong[:40])
    assert len(instructions()) > 20_000
