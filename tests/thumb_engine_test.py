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
import pathlib
import random
import shutil
import struct
import subprocess

import pytest
from unicorn.arm_const import UC_ARM_REG_XPSR

import thumb_cases
from heliquad.sim.base.firmware_image import teensy35_image
from heliquad.sim.chip.image import Image
from heliquad.sim.chip.thumb_twin import RETURN_ADDRESS, SRAM_BASE, SRAM_SIZE, Twin
from heliquad.sim.chip.timing import instruction_cycles

STATES = 3
EXTRA_STATES = 12
ENCODINGS = pathlib.Path(__file__).parent / "data" / "thumb_encodings.s"
SEED = 20261129
DATA = 0x2001_E000          # a called function's pointer arguments point here
CALLS = 24                  # inputs per function
#: Functions of the image called in both: name -> (pointer arguments, float arguments,
#: an integer argument after the pointers or None).
FUNCTIONS = {
    "sinf": (0, 1, None), "cosf": (0, 1, None), "atan2f": (0, 2, None), "expf": (0, 1, None),
    "logf": (0, 1, None), "acosf": (0, 1, None), "asinf": (0, 1, None), "atanf": (0, 1, None),
    "__ieee754_sqrtf": (0, 1, None),
    "_ZN2hq3Pid6updateEfff": (1, 3, None),
    "_ZN2hq19ComplementaryFilter6updateERKNS_4Vec3ES3_fb": (3, 1, 1),
    "_ZN2hq8multiplyERKNS_4QuatES2_": (2, 0, None),
    "_ZN2hq9normaliseERKNS_4QuatE": (1, 0, None),
    "_ZN2hq8to_eulerERKNS_4QuatE": (1, 0, None),
}


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


def _compare(twin, case_list, states, code=None):
    """Runs every case from `states` random states: ({outcome: runs}, [mismatch lines]).
    code: (address, bytes) written again before each run (code in SRAM)."""
    rng = random.Random(SEED)
    counts = {"compared": 0, "faulted": 0, "skipped": 0}
    bad = []
    for case in case_list:
        for _ in range(states):
            if code:
                twin.write(*code)
            got = _run_case(twin, case, rng)
            if got in counts:
                counts[got] += 1
            else:
                insn = case.insns[-1]
                bad.append(f"0x{insn.address:x} {insn.mnemonic} {insn.op_str}: {got}")
            if got != "compared":
                twin = _resync(twin)
    return counts, bad


def test_every_instruction_of_the_image_runs_as_in_unicorn():
    all_insns = instructions()
    case_list, _ = thumb_cases.cases(all_insns)
    counts, bad = _compare(_twin(), case_list, STATES)
    names = {i.insn_name() for i, _, _ in all_insns}
    print(f"\n{len(all_insns)} instructions in .text, {len(case_list)} distinct encodings "
          f"(IT blocks as run), {len(names)} capstone names; runs: {counts}")
    assert not bad, f"{len(bad)} mismatches:\n" + "\n".join(bad[:40])
    assert counts["compared"] >= STATES * len(case_list) * 0.95


def test_encodings_the_image_lacks_run_as_in_unicorn(tmp_path):
    """tests/data/thumb_encodings.s, assembled and linked into SRAM: the FP conversions with
    FPSCR rounding and fixed point, the negated multiply-adds, long multiplies, extends with
    rotation, shifts by register, the addressing modes and system registers the image does
    not use, IT blocks of four."""
    if not (shutil.which("arm-none-eabi-as") and shutil.which("arm-none-eabi-ld")):
        pytest.skip("no ARM toolchain")
    obj, elf = tmp_path / "x.o", tmp_path / "x.elf"
    subprocess.run(["arm-none-eabi-as", "-mcpu=cortex-m4", "-mfpu=fpv4-sp-d16", "-mthumb",
                    str(ENCODINGS), "-o", str(obj)], check=True)
    subprocess.run(["arm-none-eabi-ld", "-Ttext=0x20000000", str(obj), "-o", str(elf)],
                   check=True)
    base, data, _ = thumb_cases.code_ranges(elf)
    all_insns = thumb_cases.text_instructions(elf)
    case_list, _ = thumb_cases.cases(all_insns)
    twin = _twin()
    twin.write(base, data)
    counts, bad = _compare(twin, case_list, EXTRA_STATES, (base, data))
    print(f"\n{len(all_insns)} instructions, {len(case_list)} cases; runs: {counts}")
    assert not bad, f"{len(bad)} mismatches:\n" + "\n".join(bad[:40])
    assert len(all_insns) > 100 and counts["compared"] >= EXTRA_STATES * len(case_list) * 0.9


def _resync(twin):
    """A fresh unicorn with the engine's SRAM (unicorn took an exception: its stack frame,
    its handler mode)."""
    fresh = Twin(image().segments, twin.engine.read(SRAM_BASE, SRAM_SIZE))
    return fresh


def _float_input(rng):
    pick = rng.random()
    if pick < 0.15:
        return rng.choice((0x0000_0000, 0x8000_0000, 0x7F80_0000, 0xFF80_0000, 0x7FC0_0000,
                           0x7F80_0001, 0x0000_0001, 0x3F80_0000, 0x4F00_0000))
    scale = rng.choice((1.0, 10.0, 1e-3, 1e4, 1e30))
    return struct.unpack("<I", struct.pack("<f", rng.uniform(-scale, scale)))[0]


def _call_args(rng, pointers, floats, integer):
    ints = [DATA + 64 * i for i in range(pointers)]
    if integer is not None:
        ints.append(rng.getrandbits(1))
    return ints, [_float_input(rng) for _ in range(floats)]


def test_whole_functions_give_unicorns_results_state_and_instruction_count():
    rng = random.Random(SEED)
    twin = Twin(image().segments, bytes(SRAM_SIZE), step_hook=False)
    twin.count_blocks()
    calls = 0
    for name, (pointers, floats, integer) in FUNCTIONS.items():
        address = image().symbol(name).address
        for _ in range(CALLS):
            data = b"".join(struct.pack("<I", _float_input(rng)) for _ in range(64))
            twin.write(DATA, data)
            ints, fargs = _call_args(rng, pointers, floats, integer)
            twin.set_call(address, ints, fargs)
            twin.engine.instructions = twin.engine.cycles = 0
            twin.block_instructions = twin.block_cycles = 0
            stop = twin.call_engine()
            err = twin.call_unicorn(address)
            what = f"{name}{tuple(hex(a) for a in ints + fargs)}"
            assert stop == "stop_address" and twin.engine.pc == RETURN_ADDRESS, (what, stop)
            assert err is None, (what, err)
            assert twin.differences() == {}, what
            assert twin.engine.instructions == twin.block_instructions, what
            assert twin.engine.cycles == twin.block_cycles, what
            calls += 1
    print(f"\n{calls} calls of {len(FUNCTIONS)} functions compared")


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
