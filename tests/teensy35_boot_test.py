"""The emulated MK64FX512 (sim/chip) and the Teensy 3.5 image booting on it.

Two parts:

* The harness itself, on tiny Cortex-M4 programs compiled here with arm-none-eabi-gcc:
  register tables against the SVD and the firmware's generated header, exception entry and
  return with basic and FP frames, nesting, tail-chaining and PRIMASK, the cycle counter
  against the stated cycle model, a clock-gated access, an FPU instruction before CPACR,
  the watchdog's reset window, and a small boot (clocks, I2C, UART, SysTick) with a good
  and a dead crystal; the FTM and watchdog models driven directly, and a watchdog reset by a
  program's store.
* The real image (build/teensy35/heliquad-fw-teensy35.elf, from ``cmake --preset teensy35
  && cmake --build --preset teensy35``; $HQ_TEENSY35_ELF overrides) from reset to its main
  loop: watchdog first, FPU granted first, the clock tree and the MCG sequence, a dead
  crystal, pin mux, I2C, UART, FTM0/FTM3, SysTick and the MPU6050 start-up against the
  project's emulated chip. Without the image the tests skip; in CI (CI set) the image is
  built with the preset (tests/teensy_image.py) and a missing one fails.

Every run is bounded by an instruction budget; nothing here depends on the machine's speed.
"""

from __future__ import annotations

import os
import pathlib
import re
import shutil
import struct
import subprocess
import sys

import pytest

from heliquad import _firmware
from heliquad.sim.chip import ChipReset, Fault, Mk64, Teensy35, registers, svd
from heliquad.sim.chip.i2c import SCL_DIVIDER
from heliquad.sim.chip.machine import Stop
from heliquad.sim.chip.teensy35 import I2C_PINS, PINS

ROOT = pathlib.Path(__file__).resolve().parents[1]
IMAGE = pathlib.Path(os.environ.get("HQ_TEENSY35_ELF",
                                    ROOT / "build" / "teensy35" / "heliquad-fw-teensy35.elf"))
HEADER = ROOT / "firmware" / "targets" / "teensy35" / "mk64f12.hpp"
ARM_FLAGS = ["-mcpu=cortex-m4", "-mthumb", "-mfpu=fpv4-sp-d16", "-mfloat-abi=hard"]
BOOT_BUDGET = 40_000_000        # instructions from reset to the first loop (the image needs ~9M)
FATAL_BUDGET = 5_000_000        # a dead crystal must reach hq_fatal well within this


# ---------------------------------------------------------------------------- helpers --------

def require_compiler():
    if shutil.which("arm-none-eabi-gcc"):
        return
    message = ("arm-none-eabi-gcc not found: apt-get install gcc-arm-none-eabi "
               "libnewlib-arm-none-eabi")
    if os.environ.get("CI"):
        pytest.fail(message)
    pytest.skip(message)


LINKER_SCRIPT = """
MEMORY { FLASH (rx) : ORIGIN = 0, LENGTH = 512K  RAM (rwx) : ORIGIN = 0x1FFF0000, LENGTH = 192K }
_estack = ORIGIN(RAM) + LENGTH(RAM);
SECTIONS {
  .text : { KEEP(*(.vectors)) *(.text*) *(.rodata*) } > FLASH
  _sidata = LOADADDR(.data);
  .data : { _sdata = .; *(.data*) _edata = .; } > RAM AT > FLASH
  .bss : { _sbss = .; *(.bss*) *(COMMON) _ebss = .; } > RAM
}
"""

# The start of every C test program: the watchdog off within its window, the FPU on, .data
# and .bss set up. Vector slots are filled by each program.
C_PRELUDE = r"""
#include <stdint.h>
#define REG32(a) (*(volatile uint32_t *)(a))
#define REG16(a) (*(volatile uint16_t *)(a))
#define REG8(a) (*(volatile uint8_t *)(a))
extern uint32_t _estack, _sidata, _sdata, _edata, _sbss, _ebss;
int main(void);
void reset(void) {
    REG16(0x4005200E) = 0xC520; REG16(0x4005200E) = 0xD928;
    __asm volatile("nop\n nop");
    REG16(0x40052000) = 0x01D2;
    REG32(0xE000ED88) |= 0xFu << 20;
    __asm volatile("dsb\n isb");
    for (uint32_t *s = &_sidata, *d = &_sdata; d < &_edata;) *d++ = *s++;
    for (uint32_t *d = &_sbss; d < &_ebss;) *d++ = 0;
    main();
    for (;;) __asm volatile("bkpt #0");
}
"""

ASM_WDOG_OFF = """
    ldr r0, =0x40052000
    movw r1, #0xC520
    strh r1, [r0, #14]
    movw r1, #0xD928
    strh r1, [r0, #14]
    nop
    nop
    movw r1, #0x01D2
    strh r1, [r0]
"""

# A vector table with the stack and the reset vector only, and a reset that first turns the
# watchdog off: the start of the tiny programs that need no interrupts.
ASM_RESET_ONLY = """
    .syntax unified
    .thumb
    .section .vectors,"a"
    .word _estack
    .word reset + 1
    .text
    .thumb_func
reset:
""" + ASM_WDOG_OFF


def build(tmp_path, name, source, *, asm=False, opt="-O2"):
    require_compiler()
    src = tmp_path / (name + (".S" if asm else ".c"))
    src.write_text(source)
    ld = tmp_path / "tiny.ld"
    ld.write_text(LINKER_SCRIPT)
    elf = tmp_path / (name + ".elf")
    res = subprocess.run(["arm-none-eabi-gcc", *ARM_FLAGS, opt, "-nostdlib", "-ffreestanding",
                          "-T", str(ld), str(src), "-o", str(elf)],
                         capture_output=True, text=True, timeout=120)
    assert res.returncode == 0, res.stderr
    return elf


def words(m, symbol, n):
    return struct.unpack(f"<{n}I", m.read(m.image.symbol(symbol).address, 4 * n))


# ------------------------------------------------------------ register tables ----------------

def test_register_tables_match_the_svd():
    try:
        data = svd.find_svd()
    except svd.SvdNotFound as e:
        if os.environ.get("CI"):
            pytest.fail(str(e))
        pytest.skip(str(e).splitlines()[0])
    from heliquad.sim.chip import regmap
    assert svd.parse(data) == regmap.PERIPHERALS, \
        "sim/chip/regmap.py is stale: python -m heliquad.sim.chip.svd --write"
    assert svd.interrupts(data) == regmap.INTERRUPTS


def _header_registers(text):
    """{(peripheral, register): (address, bits, reset)} from the firmware's generated header."""
    out, periph = {}, None
    for line in text.splitlines():
        m = re.match(r"namespace (\w+) \{", line)
        if m:
            periph = m.group(1)
            continue
        m = re.match(r"struct (\w+) : Reg<uint(\d+)_t, (0x[0-9A-Fa-f]+)u>", line)
        if m and periph:
            current = (periph, m.group(1))
            out[current] = [int(m.group(3), 16), int(m.group(2)), None]
            continue
        m = re.search(r"RESET_VALUE = (0x[0-9A-Fa-f]+)u", line)
        if m and periph and out:
            out[current][2] = int(m.group(1), 16)
    return out


def test_register_tables_match_the_firmware_header():
    """The emulator's register tables and the firmware's generated header agree on every
    register both describe: one SVD, two generators."""
    if not HEADER.exists():
        pytest.skip(f"{HEADER.relative_to(ROOT)} not generated yet")
    theirs = _header_registers(HEADER.read_text())
    compared = 0
    for (periph, name), (address, bits, reset) in theirs.items():
        try:
            reg = registers.peripheral(periph)[name]
        except KeyError:
            continue
        assert (reg.address, reg.bits) == (address, bits), f"{periph}_{name}"
        if reset is not None:
            assert reg.reset == reset, f"{periph}_{name} reset value"
        compared += 1
    assert compared > 200, f"only {compared} registers in common"


# ------------------------------------------------------------ reset cause ----------------------

_SRS0, _SRS1 = registers.peripheral("RCM")["SRS0"], registers.peripheral("RCM")["SRS1"]
_CAUSE = _firmware.ResetCause
#: (SRS0 flags, SRS1 flags, what the firmware calls the reset): each flag alone, then the
#: orders that matter when several are set.
RESET_CAUSES = [
    (("POR",), (), _CAUSE.POWER_ON),
    (("POR", "LVD"), (), _CAUSE.POWER_ON),            # a power-on also sets LVD: the SVD's reset
    (("LVD",), (), _CAUSE.LOW_VOLTAGE),
    (("WDOG",), (), _CAUSE.WATCHDOG),
    ((), ("LOCKUP",), _CAUSE.LOCKUP),
    ((), ("SW",), _CAUSE.SOFTWARE),
    (("PIN",), (), _CAUSE.PIN),
    (("LOC",), (), _CAUSE.CLOCK_LOSS),
    (("LOL",), (), _CAUSE.CLOCK_LOSS),
    ((), ("JTAG",), _CAUSE.DEBUGGER),
    ((), ("MDM_AP",), _CAUSE.DEBUGGER),
    ((), ("EZPT",), _CAUSE.DEBUGGER),
    ((), (), _CAUSE.OTHER),
    (("WAKEUP",), (), _CAUSE.OTHER),
    ((), ("SACKERR",), _CAUSE.OTHER),
    (("POR", "WDOG", "PIN"), ("LOCKUP", "SW"), _CAUSE.POWER_ON),
    (("WDOG", "PIN", "LVD"), ("LOCKUP",), _CAUSE.WATCHDOG),
    (("LVD", "PIN"), ("LOCKUP", "SW"), _CAUSE.LOCKUP),
    (("LVD", "LOC", "PIN"), ("SW",), _CAUSE.LOW_VOLTAGE),
    (("LOL", "PIN"), ("SW", "JTAG"), _CAUSE.CLOCK_LOSS),
    (("PIN",), ("SW", "JTAG"), _CAUSE.SOFTWARE),
    (("PIN",), ("MDM_AP",), _CAUSE.DEBUGGER),
]


@pytest.mark.parametrize("srs0, srs1, cause", RESET_CAUSES)
def test_reset_cause_from_the_rcm_flags(srs0, srs1, cause):
    flags0 = sum(_SRS0.bit(name) for name in srs0)
    flags1 = sum(_SRS1.bit(name) for name in srs1)
    assert _firmware.reset_cause_from(flags0, flags1) == cause


def test_the_emulated_chips_reset_flags_read_as_a_power_on():
    assert _firmware.reset_cause_from(_SRS0.reset, _SRS1.reset) == _CAUSE.POWER_ON


# ------------------------------------------------------------ exceptions -----------------------

FRAMES_ASM = """
    .syntax unified
    .thumb
    .section .vectors,"a"
    .word _estack
    .word reset + 1
    .fill 13, 4, 0
    .word systick + 1
    .text
    .thumb_func
reset:
""" + ASM_WDOG_OFF + """
    ldr r0, =0xE000ED88          @ CPACR: CP10, CP11 full access
    ldr r1, [r0]
    orr r1, r1, #0xF00000
    str r1, [r0]
    dsb
    isb
    ldr r0, =0xE000E010          @ SysTick: RVR 300, CVR 0, CSR = CLKSOURCE | TICKINT | ENABLE
    movw r1, #300
    str r1, [r0, #4]
    movs r1, #0
    str r1, [r0, #8]
    movs r1, #7
    str r1, [r0]
    sub sp, sp, #4               @ phase 1: SP = 4 mod 8, no FP context -> basic frame, padded
    ldr r0, =0x11111111
    ldr r1, =0x22222222
    ldr r2, =0x33333333
    ldr r3, =0x44444444
    ldr r12, =0x55555555
    ldr r4, =count
1:  ldr r5, [r4]
    cmp r5, #1
    blt 1b
    ldr r6, =after_basic
    stmia r6, {r0-r3, r12}
    add sp, sp, #4               @ phase 2: SP = 0 mod 8, FP context active -> extended frame
    ldr r6, =fp_values
    vldmia r6, {s0-s15}
    ldr r7, =0x03000000          @ FPSCR: DN and FZ, to see it restored
    vmsr fpscr, r7
1:  ldr r5, [r4]
    cmp r5, #2
    blt 1b
    ldr r6, =after_fp
    vstmia r6, {s0-s15}
    vmrs r7, fpscr
    str r7, [r6, #64]
    bkpt #0
    .thumb_func
systick:
    ldr r0, =count
    ldr r1, [r0]
    adds r1, r1, #1
    str r1, [r0]
    ldr r2, =seen                @ seen[count] = (LR = EXC_RETURN, SP, stacked xPSR)
    add r2, r2, r1, lsl #4
    str lr, [r2]
    str sp, [r2, #4]
    ldr r3, [sp, #28]
    str r3, [r2, #8]
    cmp r1, #2
    bne 2f
    ldr r3, =0xE000E010
    movs r0, #0
    str r0, [r3]                 @ SysTick off after the second one
2:  movs r0, #0                  @ clobber what a handler may clobber
    movs r1, #0
    movs r2, #0
    movs r3, #0
    mov r12, r0
    tst lr, #0x10
    bne 3f
    vmov.f32 s0, #1.0
    vmov s1, s0
    vmov s15, s0
    vmsr fpscr, r0
3:  bx lr
    .ltorg
    .section .rodata
fp_values:
    .word 0x3f800000, 0x40000000, 0x40400000, 0x40800000, 0x40a00000, 0x40c00000, 0x40e00000
    .word 0x41000000, 0x41100000, 0x41200000, 0x41300000, 0x41400000, 0x41500000, 0x41600000
    .word 0x41700000, 0x41800000
    .bss
    .align 3
count: .space 4
seen: .space 48
after_basic: .space 20
after_fp: .space 68
"""


def test_exception_entry_and_return_with_basic_and_fp_frames(tmp_path):
    elf = build(tmp_path, "frames", FRAMES_ASM, asm=True)
    chip = Mk64(elf)
    m = chip.machine
    stop = m.run(instructions=200_000)
    assert stop.reason == "bkpt", stop
    assert words(m, "count", 1) == (2,)
    seen = words(m, "seen", 12)
    top = 0x2002_0000
    # 1st: thread on MSP, no FPU context: EXC_RETURN 0xFFFFFFF9, an 8-word frame below an SP
    # of top - 4, aligned down to 8 with xPSR bit 9 set to say so.
    assert seen[4] == 0xFFFF_FFF9
    assert seen[5] == (top - 4 - 0x20) & ~7
    assert seen[6] & (1 << 9) and seen[6] & (1 << 24)
    # 2nd: the thread has used the FPU: EXC_RETURN 0xFFFFFFE9 and a 26-word frame.
    assert seen[8] == 0xFFFF_FFE9
    assert seen[9] == top - 0x68
    assert not seen[10] & (1 << 9)
    # Everything the handler clobbered came back.
    assert words(m, "after_basic", 5) == (0x11111111, 0x22222222, 0x33333333, 0x44444444,
                                          0x55555555)
    fp = words(m, "after_fp", 17)
    assert fp[:16] == words(m, "fp_values", 16)
    assert fp[16] == 0x0300_0000
    assert [e[1:] for e in m.exception_log] == [("enter", 15), ("return", 15)] * 2
    assert m.active == [] and m.reg("sp") == top


NESTING_C = C_PRELUDE + r"""
void irq0(void); void irq1(void); void irq2(void);
__attribute__((section(".vectors"), used)) void (*const vectors[16 + 86])(void) = {
    (void (*)(void))&_estack, reset, [16] = irq0, [17] = irq1, [18] = irq2 };
volatile uint32_t order[16]; volatile uint32_t n;
void irq0(void) { order[n++] = 0x10; REG32(0xE000E200) = 1u << 1; __asm volatile("dsb\n isb");
                  order[n++] = 0x11; }
void irq1(void) { order[n++] = 0x20; }
void irq2(void) { order[n++] = 0x30; }
int main(void) {
    REG8(0xE000E400) = 0x80; REG8(0xE000E401) = 0x40; REG8(0xE000E402) = 0x80;
    REG32(0xE000E100) = 7;
    __asm volatile("cpsid i");
    REG32(0xE000E200) = 5;          /* IRQ 0 and 2 pending, masked */
    order[n++] = 1;
    __asm volatile("cpsie i");
    order[n++] = 2;
    return 0;
}
"""


def test_preemption_tail_chaining_and_primask(tmp_path):
    """IRQ0 and IRQ2 (priority 8) pend under PRIMASK; unmasking takes IRQ0 (lower number),
    whose pend of IRQ1 (priority 4) preempts it; IRQ2 follows by tail-chaining."""
    chip = Mk64(build(tmp_path, "nesting", NESTING_C))
    m = chip.machine
    assert m.run(instructions=100_000).reason == "bkpt"
    n = words(m, "n", 1)[0]
    assert words(m, "order", n) == (1, 0x10, 0x20, 0x11, 0x30, 2)
    assert [e[1:] for e in m.exception_log] == [("enter", 16), ("enter", 17), ("return", 17),
                                                ("return", 16), ("enter", 18), ("return", 18)]


# ------------------------------------------------------------ IT blocks ----------------------

# A Thumb IT block whose load is the first touch of a page (a TLB fill) or a peripheral
# access (the protection hook): unicorn rolls the CPU state back to that instruction to call
# the hook, IT bits included, and the block then goes on; what runs after the block must not
# inherit those bits (unicorn 2.1.4 leaves them, and the next block ran as if still inside
# the IT block: an instruction skipped). The lookup is the shape GCC gives a switch of
# string literals (hq::reason_text in the image): the image's STATUSTEXTs came out empty.
IT_BLOCK_ASM = ASM_RESET_ONLY + """
    movs r0, #3
    movs r2, #0
    movs r4, #0
    bl lookup                    @ r0 = table[3]: a TLB fill inside an ITTE LS block
    mov r2, r0                   @ after the return: both must run
    movs r4, #7
    ldr r1, =0xE0001004          @ DWT_CYCCNT: a peripheral read inside an ITT EQ block
    movs r5, #0
    movs r6, #0
    movs r7, #0
    cmp r5, r5
    itt eq
    ldreq r3, [r1]
    moveq r6, #1
    cmp r5, #1                   @ NE from here: a leftover EQ would skip what follows
    b 1f
1:  movs r5, #9
    movs r7, #11
    ldr r1, =result
    stmia r1, {r2, r4, r5, r6, r7}
    bkpt #0
    .ltorg
lookup:
    cmp r0, #35
    itte ls
    ldrls r3, =table
    ldrls.w r0, [r3, r0, lsl #2]
    ldrhi r0, =0
    bx lr
    .ltorg
    .section .rodata
    .balign 4096                 @ a page of its own, never touched before the lookup
table: .word 0x100, 0x101, 0x102, 0x103, 0x104
    .bss
result: .space 20
"""


def test_what_follows_an_it_block_whose_access_called_a_hook_runs_unconditionally(tmp_path):
    chip = Mk64(build(tmp_path, "it_block", IT_BLOCK_ASM, asm=True))
    m = chip.machine
    assert m.run(instructions=100_000).reason == "bkpt"
    looked_up, after_return, after_branch, in_block, after_branch_2 = words(m, "result", 5)
    assert looked_up == 0x103                   # the lookup's value reached its caller
    assert after_return == 7
    assert in_block == 1
    assert (after_branch, after_branch_2) == (9, 11)


# ------------------------------------------------------------ time base -----------------------

CYCCNT_ASM = ASM_RESET_ONLY + """
    ldr r0, =0xE0001004          @ DWT_CYCCNT
    ldr r2, =0xE0001000          @ DWT_CTRL
    ldr r3, [r2]
    orr r3, r3, #1
    str r3, [r2]                 @ CYCCNTENA without TRCENA: must not count
    ldr r1, [r0]
    ldr r2, =0xE000EDFC          @ DEMCR.TRCENA
    ldr r3, [r2]
    orr r3, r3, #0x1000000
    str r3, [r2]
    ldr r4, [r0]                 @ c0
    movw r5, #1000
1:  subs r5, r5, #1
    bne 1b
    ldr r6, [r0]                 @ c1
    ldr r7, =result
    stmia r7, {r1, r4, r6}
    bkpt #0
    .ltorg
    .bss
result: .space 12
"""


def test_cyccnt_counts_the_stated_cycle_model(tmp_path):
    """Between the two reads: LDR (2) + MOVW (1) + 1000 x (SUBS 1 + BNE 2) = 3003 cycles, as
    timing.py states; the counter stays at 0 until DEMCR.TRCENA."""
    chip = Mk64(build(tmp_path, "cyccnt", CYCCNT_ASM, asm=True))
    m = chip.machine
    assert m.run(instructions=100_000).reason == "bkpt"
    before_trcena, c0, c1 = words(m, "result", 3)
    assert before_trcena == 0
    assert c1 - c0 == 2 + 1 + 1000 * (1 + 2)
    assert m.cycles >= c1


# ------------------------------------------------------------ what the chip refuses -----------

GATED_C = C_PRELUDE + r"""
__attribute__((section(".vectors"), used)) void (*const vectors[16])(void) = {
    (void (*)(void))&_estack, reset };
volatile uint8_t s;
int main(void) {
    REG32(0x40048038) |= 1u << 10;      /* PORTB clock on: fine */
    REG32(0x4004A008) = 0x200;          /* PORTB_PCR2 */
    s = REG8(0x40066003);               /* I2C0_S with SIM_SCGC4.I2C0 still 0 */
    return 0;
}
"""


def test_access_to_a_gated_peripheral_is_a_bus_fault(tmp_path):
    chip = Mk64(build(tmp_path, "gated", GATED_C))
    with pytest.raises(Fault) as info:
        chip.run(instructions=100_000)
    assert info.value.kind == "BusFault"
    assert info.value.address == 0x40066003
    assert "SIM_SCGC4.I2C0" in str(info.value)
    assert chip.ports.mux("B", 2) == 2          # the gated-on PORTB write went through
    fn = chip.image.function_at(info.value.pc)
    assert fn is not None and fn.name == "main"


NOCP_ASM = ASM_RESET_ONLY + """
    b 1f
1:  vmov s0, r0                  @ CPACR still 0
    bkpt #0
"""


def test_fpu_instruction_before_cpacr_is_a_nocp_fault(tmp_path):
    chip = Mk64(build(tmp_path, "nocp", NOCP_ASM, asm=True))
    with pytest.raises(Fault) as info:
        chip.run(instructions=10_000)
    assert info.value.kind == "UsageFault" and "NOCP" in str(info.value)
    assert chip.machine.fpu_violation is not None
    assert chip.machine.fpu_granted_at is None


def test_watchdog_resets_a_chip_that_does_not_unlock_it_in_time(tmp_path):
    late = C_PRELUDE.replace("void reset(void) {", "void reset(void) {\n"
                             "    for (volatile int i = 0; i < 100; ++i) {}")
    source = late + r"""
__attribute__((section(".vectors"), used)) void (*const vectors[16])(void) = {
    (void (*)(void))&_estack, reset };
int main(void) { return 0; }
"""
    chip = Mk64(build(tmp_path, "late_wdog", source))
    with pytest.raises(ChipReset) as info:
        chip.run(instructions=100_000)
    assert info.value.source == "WDOG" and "WCT" in str(info.value)


# ------------------------------------------------------------ a small boot ---------------------

MINI_BOOT_C = C_PRELUDE + r"""
void systick(void); void uart0(void);
__attribute__((noreturn, noipa)) void hq_fatal(uint32_t code) {
    (void)code; for (;;) __asm volatile("nop"); }
static void unexpected(void) { hq_fatal(99); }
__attribute__((section(".vectors"), used)) void (*const vectors[16 + 86])(void) = {
    (void (*)(void))&_estack, reset, unexpected, unexpected, [15] = systick, [16 + 31] = uart0 };
volatile uint32_t ticks, tx_left;
volatile uint8_t who, nack, rx_echo;
static const char msg[] = "0123456789abcdef";
void systick(void) { ticks++; }
void uart0(void) {
    while ((REG8(0x4006A004) & 0x80) && tx_left) REG8(0x4006A007) = (uint8_t)msg[16 - tx_left--];
    if (!tx_left) REG8(0x4006A003) &= (uint8_t)~0x80;          /* TIE off */
}
static int mcg_wait(uint8_t mask, uint8_t want) {
    for (uint32_t i = 0; i < 200000; ++i) if ((REG8(0x40064006) & mask) == want) return 1;
    return 0;
}
static int i2c_byte(void) {
    for (uint32_t i = 0; i < 100000; ++i)
        if (REG8(0x40066003) & 0x02) { REG8(0x40066003) = 0x02; return 1; }
    return 0;
}
static uint8_t i2c_read(uint8_t addr, uint8_t reg, uint8_t *nacked) {
    REG8(0x40066002) = 0xB0;                     /* IICEN MST TX: START */
    REG8(0x40066004) = (uint8_t)(addr << 1); i2c_byte();
    if (REG8(0x40066003) & 1) { *nacked = 1; REG8(0x40066002) = 0x80; return 0; }
    REG8(0x40066004) = reg; i2c_byte();
    REG8(0x40066002) = 0xB4;                     /* RSTA */
    REG8(0x40066004) = (uint8_t)(addr << 1 | 1); i2c_byte();
    REG8(0x40066002) = 0xA8;                     /* receive, NACK the only byte */
    (void)*(volatile uint8_t *)0x40066004;       /* dummy read starts it */
    i2c_byte();
    REG8(0x40066002) = 0x80;                     /* STOP */
    return REG8(0x40066004);
}
int main(void) {
    REG8(0x40065000) = 0x8A;                     /* OSC0: ERCLKEN SC8P SC2P */
    REG8(0x40064001) = 0x24;                     /* MCG_C2: RANGE 2, EREFS */
    REG8(0x40064000) = 0xA0;                     /* MCG_C1: CLKS 2, FRDIV 4 */
    if (!mcg_wait(0x02, 0x02)) hq_fatal(1);
    if (!mcg_wait(0x10, 0x00)) hq_fatal(2);
    if (!mcg_wait(0x0C, 0x08)) hq_fatal(3);
    REG8(0x40064004) = 0x03;                     /* PRDIV0 3: 4 MHz */
    REG8(0x40064005) = 0x46;                     /* PLLS, VDIV0 6: x30 */
    if (!mcg_wait(0x20, 0x20) || !mcg_wait(0x40, 0x40)) hq_fatal(4);
    REG32(0x40048044) = 0x01240000;              /* core /1, bus /2, FlexBus /3, flash /5 */
    REG32(0x40048048) = (4 << 1) | 1;            /* USB 120 x 2 / 5 */
    REG8(0x40064000) = 0x20;                     /* CLKS 0: PEE */
    if (!mcg_wait(0x0C, 0x0C)) hq_fatal(5);
    REG32(0x40048004) |= (1u << 18) | (1u << 16);
    /* I2C0 on PTB2/PTB3 at 60 MHz / 144 */
    REG32(0x40048034) |= (1u << 6) | (1u << 10); REG32(0x40048038) |= 1u << 10;
    REG32(0x4004A008) = 0x264; REG32(0x4004A00C) = 0x264;
    REG8(0x40066001) = 0x1C; REG8(0x40066002) = 0x80;
    who = i2c_read(0x68, 0x75, (uint8_t *)&nack);
    uint8_t n2 = 0; i2c_read(0x69, 0x75, &n2); nack = n2;
    for (uint32_t i = 0; i < 10000 && (REG8(0x40066003) & 0x20); ++i) {}
    /* UART0 at 921600 with the TX FIFO, interrupt-driven */
    REG32(0x4004A040) = 0x300; REG32(0x4004A044) = 0x300;
    REG8(0x4006A000) = 0; REG8(0x4006A001) = 8; REG8(0x4006A00A) = 4;
    REG8(0x4006A010) = 0x88; REG8(0x4006A013) = 2;
    REG8(0x4006A003) = 0x0C;
    REG32(0xE000E100) = 1u << 31;
    tx_left = 16;
    REG8(0x4006A003) |= 0x80;
    /* 200 Hz SysTick, WFI until three ticks */
    REG32(0xE000E014) = 599999; REG32(0xE000E018) = 0; REG32(0xE000E010) = 7;
    while (ticks < 3) __asm volatile("wfi");
    return 0;
}
"""


@pytest.fixture(scope="module")
def mini_boot_elf(tmp_path_factory):
    return build(tmp_path_factory.mktemp("mini"), "mini_boot", MINI_BOOT_C)


def _fatal_stop(m):
    return Stop("fatal", m.pc, {"code": m.reg("r0")})


def test_small_boot_clocks_i2c_uart_and_systick(mini_boot_elf):
    chip = Mk64(mini_boot_elf)
    m = chip.machine
    m.break_at("hq_fatal", _fatal_stop)
    stop = m.run(instructions=3_000_000)
    assert stop.reason == "bkpt", stop
    tree = chip.tree()
    assert (tree.mode, tree.core, tree.bus, tree.flexbus, tree.flash, tree.usb) == \
        ("PEE", 120e6, 60e6, 40e6, 24e6, 48e6)
    assert [mode for _, _, mode in chip.mcg.modes] == ["FEI", "FBE", "PBE", "PEE"]
    assert chip.clock_violations == [] and chip.mcg.violations == []
    # I2C with nothing on the bus: no acknowledge, and the program sees it
    assert m.read(m.image.symbol("nack").address, 1)[0] == 1
    assert [t.acked for t in chip.i2c0.transfers] == [False, False]
    assert chip.i2c0.scl_hz() == pytest.approx(60e6 / 144)
    # UART: the 16 bytes left at line rate, one 10-bit frame apart once the FIFO was primed
    sent = chip.uart0.sent
    assert bytes(b for _, b in sent) == b"0123456789abcdef"
    frame = chip.uart0.frame_cycles()
    assert frame == round(10 * 120e6 / chip.uart0.baud())
    gaps = {b[0] - a[0] for a, b in zip(sent, sent[1:])}
    assert gaps == {frame}
    assert abs(chip.uart0.baud() / 921600 - 1) < 0.02
    # SysTick: 5 ms apart, slept through in WFI
    wraps = chip.scs.systick.wraps
    assert [b - a for a, b in zip(wraps, wraps[1:])] == [600_000] * (len(wraps) - 1)
    assert m.sleep_cycles > 1_000_000
    assert m.exception_counts[15] == 3
    # Deterministic: a second chip runs the same program to the same instruction and cycle
    again = Mk64(mini_boot_elf)
    again.machine.break_at("hq_fatal", _fatal_stop)
    assert again.run(instructions=3_000_000).reason == "bkpt"
    assert (again.machine.instructions, again.machine.cycles, again.uart0.sent) == \
        (m.instructions, m.cycles, sent)


def test_small_boot_with_an_mpu6050_on_the_bus(mini_boot_elf):
    Mpu6050Emulator = pytest.importorskip("heliquad._firmware").Mpu6050Emulator
    from heliquad.sim.chip.i2c import Mpu6050Slave
    chip = Mk64(mini_boot_elf)
    m = chip.machine
    chip.i2c0.slaves.append(Mpu6050Slave(Mpu6050Emulator(), m))
    assert m.run(instructions=3_000_000).reason == "bkpt"
    assert m.read(m.image.symbol("who").address, 1)[0] == 0x68
    t = chip.i2c0.transfers
    assert [(x.address, x.read, x.acked) for x in t] == [(0x68, False, True), (0x68, True, True),
                                                          (0x69, False, False)]
    assert bytes(t[0].data) == b"\x75" and bytes(t[1].data) == b"\x68"


def test_small_boot_with_a_dead_crystal_ends_in_the_fault_path(mini_boot_elf):
    chip = Mk64(mini_boot_elf, crystal_ok=False)
    m = chip.machine
    m.break_at("hq_fatal", _fatal_stop)
    stop = m.run(instructions=10_000_000)
    assert stop.reason == "fatal" and stop.detail["code"] == 1
    assert chip.mcg.modes[-1][2] == "FEI"
    assert not chip.mcg.v["S"] & 0x02           # OSCINIT0 never set


def test_i2c_scl_divider_table():
    assert len(SCL_DIVIDER) == 64
    assert 60e6 / SCL_DIVIDER[0x1C] == pytest.approx(416_667, rel=1e-5)
    assert 60e6 / SCL_DIVIDER[0x1D] == 375_000


# ============================================================ the real image ===================

def require_image():
    """In CI the image is (re)built with the preset by tests/teensy_image.py, once per
    session, and a missing or unbuildable image fails; elsewhere a missing one skips."""
    global IMAGE
    if os.environ.get("CI") and "HQ_TEENSY35_ELF" not in os.environ:
        try:
            sys.path.insert(0, str(pathlib.Path(__file__).resolve().parent))
            from teensy_image import image
        except ImportError:
            image = None
        if image is not None:
            IMAGE = image().elf
    if IMAGE.exists():
        return
    message = (f"{IMAGE} is not built (cmake --preset teensy35 && cmake --build --preset "
               "teensy35)")
    if os.environ.get("CI"):
        pytest.fail(message)
    pytest.skip(message)


@pytest.fixture(scope="module")
def booted():
    """The image from reset to the entry of its first FlightController::step."""
    require_image()
    pytest.importorskip("heliquad._firmware")
    board = Teensy35(IMAGE)
    stop = board.run_to_loop(1, instructions=BOOT_BUDGET)
    assert stop.reason == "loop", f"did not reach the main loop: {stop} (fatal code " \
                                  f"{board.fatal_code})"
    return board


@pytest.fixture(scope="module")
def running():
    """The image through its first four loops (telemetry has started)."""
    require_image()
    pytest.importorskip("heliquad._firmware")
    board = Teensy35(IMAGE)
    stop = board.run_to_loop(4, instructions=BOOT_BUDGET)
    assert stop.reason == "loop", stop
    return board


def test_image_has_the_symbols_the_contract_names():
    require_image()
    board = Teensy35(IMAGE, with_mpu6050=False)
    image = board.machine.image
    for name in ("Reset_Handler", "NMI_Handler", "HardFault_Handler", "SysTick_Handler",
                 "UART0_RX_TX_IRQHandler", "FTM3_IRQHandler", "I2C0_IRQHandler",
                 "USB0_IRQHandler", "Default_Handler", "hq_fatal",
                 "hq::FlightController::step"):
        assert image.has(name), name
    slots = {1: "Reset_Handler", 2: "NMI_Handler", 3: "HardFault_Handler",
             15: "SysTick_Handler", 16 + registers.irq("UART0_RX_TX"): "UART0_RX_TX_IRQHandler",
             16 + registers.irq("FTM3"): "FTM3_IRQHandler",
             16 + registers.irq("I2C0"): "I2C0_IRQHandler",
             16 + registers.irq("USB0"): "USB0_IRQHandler"}
    for number, name in slots.items():
        assert image.vector_symbol(number) == name, number
    for irq in range(86):
        if 16 + irq not in slots:
            assert image.vector_symbol(16 + irq) == "Default_Handler", irq
    assert image.objects_straddling_sram_boundary() == []


def test_image_boots_to_the_main_loop(booted):
    m = booted.machine
    assert booted.loops == 1 and booted.fatal_code is None
    assert m.instructions < BOOT_BUDGET
    assert booted.chip.notes == []


def test_watchdog_is_disabled_before_anything_else(booted):
    chip, m = booted.chip, booted.machine
    assert chip.wdog.disabled_at is not None, "the watchdog was never disabled"
    disabled_at = chip.wdog.disabled_at[0]
    before = [a for a in m.first_accesses if a.instruction <= disabled_at]
    assert before and all(a.device == "WDOG" for a in before), before
    assert [(a.address, a.value) for a in before] == [(0x4005200E, 0xC520), (0x4005200E, 0xD928),
                                                      (0x40052000, 0x01D2)]
    assert chip.wdog.ignored == []


def test_fpu_is_granted_before_the_first_fpu_instruction(booted):
    m = booted.machine
    assert m.fpu_violation is None
    assert m.fpu_granted_at is not None and m.fpu_synced_at is not None
    assert m.fpu_granted_at < m.fpu_synced_at <= m.first_fpu[0]
    mcg_first = booted.chip.mcg.log[0][0]
    assert m.fpu_granted_at < mcg_first, "CP10/CP11 are granted before the clock set-up"


def test_clock_tree_after_the_mcg_sequence(booted):
    chip = booted.chip
    tree = chip.tree()
    assert tree.mode == "PEE"
    assert tree.core == 120e6 and tree.bus == 60e6 and tree.flash <= 25e6
    assert tree.usb == 48e6
    assert [mode for _, _, mode in chip.mcg.modes] == ["FEI", "FBE", "PBE", "PEE"]
    assert chip.clock_violations == [] and chip.mcg.violations == []


def test_mcg_waits_come_in_the_documented_order(booted):
    """Each step's status is seen by a read of MCG_S before the next step's write."""
    chip = booted.chip
    events = [(i, "W", reg, v) for i, _, kind, reg, v in chip.mcg.log if kind == "W"]
    events += [(i, "R", reg, v) for i, _, kind, reg, v in chip.mcg.log if kind == "R"]
    events += [(i, "W", "SIM_" + reg, v) for i, reg, v in chip.sim.writes
               if reg in ("CLKDIV1", "CLKDIV2", "SOPT2")]
    events += [(i, "W", "OSC_" + reg, v) for i, reg, v in chip.osc.writes]
    events.sort(key=lambda e: e[0])

    def first(pred, after):
        for e in events:
            if e[0] >= after and pred(e):
                return e[0]
        raise AssertionError(f"not found after instruction {after}")

    w = lambda reg, test=lambda v: True: (lambda e: e[1] == "W" and e[2] == reg and test(e[3]))
    s = lambda test: (lambda e: e[1] == "R" and test(e[3]))
    osc = first(w("OSC_CR", lambda v: v & 0x80), 0)
    c2 = first(w("C2", lambda v: v & 0x04 and (v >> 4) & 3 == 2), osc)
    fbe = first(w("C1", lambda v: v >> 6 == 2 and not v & 0x04 and (v >> 3) & 7 == 4), c2)
    oscinit = first(s(lambda v: v & 0x02), fbe)
    irefst = first(s(lambda v: not v & 0x10), oscinit)
    clkst2 = first(s(lambda v: (v >> 2) & 3 == 2), irefst)
    c5 = first(w("C5", lambda v: v & 0x1F == 3), clkst2)
    c6 = first(w("C6", lambda v: v & 0x40 and v & 0x1F == 6), c5)
    pllst = first(s(lambda v: v & 0x20), c6)
    lock = first(s(lambda v: v & 0x40), pllst)
    div = first(w("SIM_CLKDIV1", lambda v: v == 0x0124_0000), lock)
    pee = first(w("C1", lambda v: v >> 6 == 0), div)
    clkst3 = first(s(lambda v: (v >> 2) & 3 == 3), pee)
    first(w("SIM_SOPT2", lambda v: v & (1 << 18) and (v >> 16) & 3 == 1), clkst3)


def test_dead_crystal_ends_in_hq_fatal_with_the_crystal_code():
    require_image()
    board = Teensy35(IMAGE, crystal_ok=False, with_mpu6050=False)
    stop = board.run(instructions=FATAL_BUDGET)
    assert stop.reason == "fatal", stop
    assert board.fatal_code == 1
    assert board.machine.instructions < FATAL_BUDGET
    for pin in (22, 23, 9, 10, 6):
        assert board.pin(pin).signal is None, "an ESC pin was driven"


EXPECTED_PINS = {
    18: ("I2C0_SDA", True), 19: ("I2C0_SCL", True),
    22: ("FTM0_CH0", False), 23: ("FTM0_CH1", False), 9: ("FTM0_CH2", False),
    10: ("FTM0_CH3", False), 6: ("FTM0_CH4", False),
    2: ("FTM3_CH0", False), 14: ("FTM3_CH1", False), 7: ("FTM3_CH2", False),
    8: ("FTM3_CH3", False), 35: ("FTM3_CH4", False), 36: ("FTM3_CH5", False),
    0: ("UART0_RX", False), 1: ("UART0_TX", False), 13: ("PTC5", False),
}


def test_pin_mux_of_every_used_pin(booted):
    for pin, (sig, open_drain) in EXPECTED_PINS.items():
        state = booted.pin(pin)
        assert state.signal == sig, (pin, state)
        if open_drain:
            assert state.open_drain, pin
    gpio_c = booted.chip.ports.gpio["C"]
    assert gpio_c.v["PDDR"] & (1 << 5), "LED pin is an output"


def test_i2c_rate_and_mpu6050_start_up(booted):
    chip, mpu = booted.chip, booted.mpu
    assert 375e3 <= chip.i2c0.scl_hz() <= 417e3
    assert chip.i2c0.errors == []
    assert all(t.acked for t in chip.i2c0.transfers)
    log = [(kind, reg, data) for _, kind, reg, data in mpu.log]
    assert log[:3] == [("W", 0x6B, b"\x80"), ("W", 0x6B, b"\x01"), ("R", 0x75, b"\x68")]
    assert mpu.log[1][0] - mpu.log[0][0] >= 0.1, "100 ms after the device reset"
    assert log[3:7] == [("W", 0x19, b"\x04"), ("W", 0x1A, b"\x03"), ("W", 0x1B, b"\x18"),
                        ("W", 0x1C, b"\x00")]
    if mpu.emu.dmp_enabled:
        assert ("W", 0x6A, bytes([0xC0])) in log
    else:
        assert log[7:11] == [("W", 0x23, b"\x78"), ("W", 0x38, b"\x11"), ("W", 0x6A, b"\x04"),
                             ("W", 0x6A, b"\x40")]
        assert mpu.emu.raw_fifo_enabled


def test_uart0_baud_and_line_rate(running):
    uart = running.chip.uart0
    assert abs(uart.baud() / 921600 - 1) < 0.02
    assert uart.frame_bits() == 10
    sent = uart.sent
    assert sent, "no telemetry left the pin"
    assert sent[0][1] == 0xFD, "MAVLink 2 frames"
    gaps = [b[0] - a[0] for a, b in zip(sent, sent[1:])]
    assert min(gaps) == uart.frame_cycles(), "bytes leave one frame apart, never faster"
    assert running.machine.exception_counts[16 + registers.irq("UART0_RX_TX")] > 0


def test_uart0_telemetry_leaves_back_to_back_within_a_loops_burst(running):
    """The shifter takes the FIFO's next byte the cycle the last one left, and the interrupt
    refills the FIFO at its watermark before it runs dry: within a loop's telemetry every
    byte leaves exactly one frame after the one before (what the transmitter is worked out
    to when looked at, not stepped byte by byte); the only longer gaps are between loops."""
    uart = running.chip.uart0
    sent, frame = uart.sent, uart.frame_cycles()
    gaps = [b[0] - a[0] for a, b in zip(sent, sent[1:])]
    assert len(gaps) > 100
    assert {g for g in gaps if g < 100 * frame} == {frame}
    assert sum(g == frame for g in gaps) / len(gaps) > 0.95


def test_ftm0_esc_outputs_at_the_stop_pulse_from_their_first_edge(booted):
    for pin, sig, period, pulse in booted.esc_outputs():
        assert period == pytest.approx(2.5e-3, abs=1e-9), pin
        assert pulse == pytest.approx(1.0e-3, abs=1e-9), pin
    assert set(booted.esc_first_edges) == {22, 23, 9, 10, 6, 20, 21, 5}
    for pin, (t, period, pulse) in booted.esc_first_edges.items():
        assert period == pytest.approx(2.5e-3, abs=1e-9) and pulse == pytest.approx(1e-3, abs=1e-9), \
            f"pin {pin} was switched to FTM0 before its stop pulse was set"


def test_ftm3_rc_capture_configuration(booted):
    ftm3, m = booted.chip.ftm3, booted.machine
    assert ftm3.clock_hz() == pytest.approx(60e6 / 32)
    assert ftm3.v["MOD"] == 0xFFFF
    for ch in range(6):
        assert ftm3.channel_mode(ch) == "capture both", ch
        assert ftm3.v[f"C{ch}SC"] & 0x40, f"CHIE on channel {ch}"
    assert m.enabled & (1 << (16 + registers.irq("FTM3")))


def test_systick_runs_the_loop_at_200_hz(booted):
    systick = booted.chip.scs.systick
    assert systick.rvr == 599_999 and systick.enabled and systick.csr & 2
    assert systick.period_s() == pytest.approx(5e-3)
    assert booted.machine.priority[15] == 12 << 4


def test_main_loop_sleeps_between_ticks_and_keeps_200_hz(running):
    board = running
    starts = [c for _, c in board.loop_starts]
    assert [b - a for a, b in zip(starts, starts[1:])] == [600_000] * 3
    m = board.machine
    assert m.sleep_cycles > 0
    assert m.exception_counts[15] >= 3
    for pin, sig, period, pulse in board.esc_outputs():
        assert pulse == pytest.approx(1.0e-3, abs=1e-9), "disarmed: the ESCs stay at stop"


def test_a_stuck_i2c_bus_times_out_recovers_and_the_loop_goes_on():
    # The byte waits sleep until the I2C0 interrupt; with SCL held low no byte ends, and
    # only SysTick wakes the wait: the timeout shows at the first tick after 1 ms (the
    # step's first byte starts right after the tick, so at the next one, 5 ms on), the
    # transfer ends in the bus recovery (the pins as GPIO, then back to I2C) and the loop
    # carries on. Released, the bus works again.
    require_image()
    pytest.importorskip("heliquad._firmware")
    board = Teensy35(IMAGE)
    assert board.run_to_loop(4, instructions=BOOT_BUDGET).reason == "loop"
    m, ports, i2c = board.machine, board.chip.ports, board.chip.i2c0
    scl = PINS[I2C_PINS["SCL"]]
    held_at, loops = m.now(), board.loops
    i2c.hold_scl(True)
    board.run(seconds=0.03)
    to_gpio = [c for _, c, letter, n, pcr in ports.log
               if (letter, n) == scl and c > held_at and (pcr >> 8) & 7 == 1]
    assert to_gpio, "no bus recovery"
    assert 120_000 < to_gpio[0] - held_at <= 600_000, "noticed at the next tick"
    assert ports.mux(*scl) == 2, "the pins are back on I2C0"
    assert board.loops >= loops + 4, "the loop goes on"
    i2c.hold_scl(False)
    released, loops = m.now(), board.loops
    board.run(seconds=0.02)
    assert board.loops >= loops + 3
    assert any(t.acked and t.start_cycle > released for t in i2c.transfers)


def _flight(board, loops):
    """Run ``loops`` main loops as a lockstep driver does (one raw IMU sample a loop), and
    what a run must reproduce exactly: counts, times, the UART line with its stamps, the
    interrupts, the I2C traffic, the ESC commands, the watchdog's writes."""
    from heliquad.sim.sensor.mpu6050_packets import raw_packet
    sample = raw_packet([0.01, -0.02, 0.005], [0.0, 0.0, -9.80665])
    m = board.machine
    assert board.run_to_loop(1, instructions=BOOT_BUDGET).reason == "loop"
    for _ in range(loops):
        board.mpu.emu.push_fifo(sample, False)
        assert board.run_to_loop(board.loops + 1, instructions=1_000_000).reason == "loop"
    transfers = [(t.address, t.read, t.acked, t.start_cycle, bytes(t.data), t.end_cycle)
                 for t in board.chip.i2c0.transfers]
    chip = board.chip
    return (m.instructions, m.cycles, m.sleep_cycles, list(chip.uart0.sent),
            list(m.exception_log), sorted(m.exception_counts.items()), transfers,
            board.loop_starts, [chip.ftm0.commanded_value(ch) for ch in range(5)],
            list(chip.wdog.log))


def test_image_runs_are_deterministic_and_the_native_paths_agree_with_the_reference():
    # Two runs give the same counts, times and UART stamps; so does a run that stops at
    # every boundary needing attention (instead of attending to it inside unicorn) and
    # takes every peripheral access through Python (the logged path): the fast paths
    # change nothing the image can see.
    require_image()
    pytest.importorskip("heliquad._firmware")
    first = _flight(Teensy35(IMAGE), 12)
    assert _flight(Teensy35(IMAGE), 12) == first
    reference = Teensy35(IMAGE)
    reference.machine.core.inline_boundaries = False
    reference.machine.trace_enabled = True
    assert _flight(reference, 12) == first
    assert len(first[3]) > 12 * 100, "telemetry streamed at line rate meanwhile"
    counts = reference.machine.counts()
    assert counts["inline_boundaries"] == 0 and counts["native_accesses"] == 0


def _stopping_at_the_wait(native: bool):
    """``(board, machine)``: the image reset, its runs stopping at the loop's wait, by a
    native stop (``native``) or a breakpoint with no callback."""
    require_image()
    pytest.importorskip("heliquad._firmware")
    board = Teensy35(IMAGE, track_loops=False)
    m = board.machine
    (m.stop_at if native else m.break_at)("hq::teensy::LoopTimer::wait")
    return board, m


def test_a_native_stop_stops_where_a_breakpoint_does_and_the_run_goes_on_alike():
    # Machine.stop_at (the lockstep's loop end, no call into Python) against a breakpoint
    # with no callback at the same instruction: each stop at the same PC, instruction count
    # and cycle, and each run after it goes on through the stop alike.
    runs = []
    for native in (False, True):
        board, m = _stopping_at_the_wait(native)
        stops = []
        for _ in range(6):
            stop = m.run(instructions=BOOT_BUDGET)
            assert stop.reason == ("stop-at" if native else "breakpoint")
            stops.append((stop.pc, m.pc, m.instructions, m.cycles, m.sleep_cycles))
        runs.append((stops, list(board.chip.uart0.sent), list(m.exception_log)))
    assert runs[0] == runs[1]
    assert len({pc for pc, *_ in runs[0][0]}) == 1


def test_an_interrupt_taken_at_a_stop_with_a_watch_on_its_handler_stops_there_once():
    # The loop's run stops at the wait (a native stop). An interrupt pending when the next run
    # starts is taken before the wait's first instruction; a breakpoint that does not stop
    # (a watch) at its handler's first instruction stops the CPU there too. After the handler
    # the run must go through the wait it already stopped at, on to the next loop's, as it
    # does with no watch (on the engine it once stopped at the same wait again: a loop
    # counted twice, 329 cycles long).
    ends = []
    for with_watch in (False, True):
        _, m = _stopping_at_the_wait(True)
        for _ in range(4):
            assert m.run(instructions=BOOT_BUDGET).reason == "stop-at"
        stopped_at = m.cycles
        seen = []
        if with_watch:
            m.break_at("FTM3_IRQHandler", lambda machine: seen.append(machine.cycles))
        m.pend(16 + registers.irq("FTM3"))
        stop = m.run(instructions=BOOT_BUDGET)
        assert stop.reason == "stop-at" and len(seen) == int(with_watch)
        assert m.cycles - stopped_at > 500_000, "the next loop's wait, not the same one again"
        ends.append((stop.pc, m.instructions, m.cycles, list(m.exception_log)))
    assert ends[0] == ends[1]


def test_take_telemetry_hands_over_each_byte_once():
    require_image()
    pytest.importorskip("heliquad._firmware")
    whole = Teensy35(IMAGE)
    whole.run_to_loop(6, instructions=BOOT_BUDGET)
    taken = Teensy35(IMAGE)
    parts = []
    for n in range(1, 7):
        taken.run_to_loop(n, instructions=BOOT_BUDGET)
        parts.append(taken.take_telemetry())
    assert b"".join(parts) == whole.telemetry() and len(whole.telemetry()) > 100
    assert taken.telemetry() == b"" and taken.chip.uart0.sent == []
    taken.run_to_loop(7, instructions=BOOT_BUDGET)
    assert taken.telemetry() == taken.take_telemetry() != b""


def test_rc_pulses_reach_the_capture_interrupt():
    require_image()
    pytest.importorskip("heliquad._firmware")
    board = Teensy35(IMAGE)
    assert board.run_to_loop(1, instructions=BOOT_BUDGET).reason == "loop"
    board.rc_pulse(0, 1500e-6)
    board.run(seconds=2e-3)
    caps = [c for c in board.chip.ftm3.captures if c[1] == 0]
    assert len(caps) == 2
    width = (caps[1][2] - caps[0][2]) & 0xFFFF
    assert width == pytest.approx(1500e-6 * 60e6 / 32, abs=1)
    assert board.machine.exception_counts[16 + registers.irq("FTM3")] == 2


def test_image_telemetry_reports_its_loop_cycles_over_uart0():
    """A second of the image: its UART0 bytes parse as the dialect (CRCs computed on the
    Cortex-M4 agree with pymavlink), and HQ_FW_STATUS carries the loop's cycle figures
    measured with the board's own cycle counter."""
    require_image()
    pytest.importorskip("heliquad._firmware")
    from heliquad.sim.base.dialect import dialect

    from heliquad.sim.sensor.mpu6050_packets import raw_packet
    board = Teensy35(IMAGE)
    assert board.run_to_loop(1, instructions=BOOT_BUDGET).reason == "loop"
    # 1.2 s of loops (the first HQ_FW_STATUS, at the first loop, and a second one), each with
    # an IMU sample as the rig gives it: without one the IMU goes stale and its blocking
    # re-initialisation (disarmed only) would be the loop measured.
    sample = raw_packet([0.01, -0.02, 0.005], [0.0, 0.0, -9.80665])
    for _ in range(240):
        board.mpu.emu.push_fifo(sample, False)
        assert board.run_to_loop(board.loops + 1, instructions=1_000_000).reason == "loop"
    mav = dialect().MAVLink(None)
    mav.robust_parsing = False
    messages = []
    for b in board.telemetry():
        m = mav.parse_char(bytes([b]))
        if m is not None:
            messages.append(m)
    kinds = {m.get_type() for m in messages}
    assert {"ATTITUDE", "HQ_SYSID_SAMPLE", "HEARTBEAT", "HQ_FW_STATUS"} <= kinds, kinds
    assert "BAD_DATA" not in kinds
    statuses = [m for m in messages if m.get_type() == "HQ_FW_STATUS"]
    assert len(statuses) >= 2, "one HQ_FW_STATUS a second"
    status = statuses[-1]
    # The step's own work is a few thousand instructions plus the polled I2C reads
    # (tens of thousands of cycles); the 5 ms budget is 600 000.
    assert 10_000 < status.loop_cycles_median <= status.loop_cycles_max < 300_000, status
    assert status.loop_overruns == 0
    assert status.telemetry_dropped == 0, "the UART ring carries the telemetry"


@pytest.fixture(scope="module")
def dmp_image_elf(tmp_path_factory):
    """The Teensy image built with a DMP firmware file compiled in (made-up tables of the
    real shape: InvenSense's are never in the repository), in a build folder of its own."""
    require_image()
    sys.path.insert(0, str(pathlib.Path(__file__).resolve().parent))
    from fake_dmp import write_fake_dmp
    from teensy_image import build_preset

    work = tmp_path_factory.mktemp("t35dmp")
    dmp = write_fake_dmp(work / "dmp.bin")
    build = work / "build"
    rc, log = build_preset(build, defines=(f"HQ_DMP_IMAGE={dmp}",))
    assert rc == 0, log[-4000:]
    return build / "heliquad-fw-teensy35.elf", dmp


def test_image_runs_the_motionapps_sequence_on_the_emulated_chip(dmp_image_elf):
    """With a DMP firmware built in, the ARM image's start-up (image upload and read-back,
    the configuration table, the register writes and the updates in MotionApps' order) is
    what the register emulator requires before it produces DMP packets."""
    pytest.importorskip("heliquad._firmware")
    from heliquad.host.commands.dmp_image import read_dmp_file, table_entries

    elf, dmp = dmp_image_elf
    firmware = read_dmp_file(str(dmp))
    board = Teensy35(elf)
    assert board.mpu.emu.set_dmp_reference(firmware.image, firmware.config, firmware.updates)
    stop = board.run_to_loop(2, instructions=4 * BOOT_BUDGET)
    assert stop.reason == "loop", (stop, board.fatal_code)
    emu = board.mpu.emu
    assert emu.dmp_status == "configured", emu.dmp_status
    assert emu.dmp_configured and emu.dmp_enabled
    entries = len(table_entries(firmware.config, specials=True))
    updates = len(table_entries(firmware.updates, specials=False))
    assert emu.dmp_progress == (len(firmware.image), entries, updates)


def test_watchdog_resets_the_chip_when_the_loop_stops_running():
    """The loop feeds the watchdog every tick. If the loop stops (here: its tick stops, as a
    hang would stop it), the chip resets about 500 ms after the last refresh, so the ESC
    pins fall back to inputs instead of holding the last command."""
    require_image()
    pytest.importorskip("heliquad._firmware")
    board = Teensy35(IMAGE)
    assert board.run_to_loop(3, instructions=BOOT_BUDGET).reason == "loop"
    board.run(seconds=0.1)                      # 20 more loops: no reset while it runs
    m, wdog = board.machine, board.chip.wdog
    refreshes = [entry for entry in wdog.log if entry[2] == "REFRESH"]
    assert refreshes, "the loop refreshes the watchdog"
    # The tick stops, as if the CPU wrote SYST_CSR = 0: the loop sleeps in WFI for good.
    m._mmio_write(registers.peripheral("SysTick").address("CSR"), 4, 0)
    with pytest.raises(ChipReset) as info:
        board.run(seconds=1.0)
    assert info.value.source == "WDOG"
    last_refresh_cycle = [entry for entry in wdog.log if entry[2] == "REFRESH"][-1][1]
    waited = m.seconds(m.now() - last_refresh_cycle)
    assert 0.495 <= waited <= 0.51, waited


def test_commands_on_uart0_rx_reach_the_firmware_and_are_answered():
    """The receive side of the telemetry UART: an arm command sent into UART0's RX pin at
    921600 baud reaches the FlightController through the RX interrupt and ring, and is
    refused over TX with the reason (no ground station heartbeat: the sender never sent
    one), as on the host build."""
    require_image()
    pytest.importorskip("heliquad._firmware")
    from heliquad.sim.base.dialect import dialect

    mav_mod = dialect()
    board = Teensy35(IMAGE)
    assert board.run_to_loop(2, instructions=BOOT_BUDGET).reason == "loop"
    host = mav_mod.MAVLink(None, srcSystem=255, srcComponent=190)
    arm = host.command_long_encode(1, 1, mav_mod.MAV_CMD_COMPONENT_ARM_DISARM, 0,
                                   1, 0, 0, 0, 0, 0, 0)
    board.receive(arm.pack(host) * 3)       # three back to back: the ring drains
    board.run(seconds=0.05)
    parser = mav_mod.MAVLink(None)
    acks = []
    for b in board.telemetry():
        m = parser.parse_char(bytes([b]))
        if m is not None and m.get_type() == "COMMAND_ACK":
            acks.append(m)
    assert len(acks) == 3, acks
    for ack in acks:
        assert ack.command == mav_mod.MAV_CMD_COMPONENT_ARM_DISARM
        assert ack.result == mav_mod.MAV_RESULT_DENIED
        assert ack.result_param2 == mav_mod.HQ_REASON_NO_HOST
    assert board.chip.uart0.overruns == 0


def test_uart_rdrf_is_latched_as_on_the_chip():
    """S1[RDRF] clears only on an S1 read that saw it followed by a D read that leaves the
    FIFO below its watermark: draining two bytes after one S1 read (what the firmware's
    first UART handler did) leaves it set over an empty FIFO, so the interrupt would fire
    for ever; the firmware's handler reads S1 before the last byte."""
    chip = Mk64()
    m, uart, wdog = chip.machine, chip.uart0, chip.wdog
    for name, value in (("UNLOCK", 0xC520), ("UNLOCK", 0xD928), ("STCTRLH", 0x01D2)):
        wdog.write(wdog.base + wdog.map[name].offset, 2, value)      # the watchdog off

    def wr(name, value):
        uart.write(uart.base + uart.map[name].offset, 1, value)

    rd = uart.read_register
    wr("PFIFO", 0x88)                        # both FIFOs on
    wr("RWFIFO", 1)
    wr("C2", rd("C2") | 0x04)                # RE

    def arrive(*data):                       # on the RX pin, time passing with no program
        uart.receive(bytes(data))
        m.advance(len(data) * uart.frame_cycles())

    arrive(1, 2)
    assert uart.rx == [1, 2] and uart.rdrf()
    rd("S1")
    assert (rd("D"), rd("D")) == (1, 2)
    assert uart.rdrf() and not uart.rx, "one S1 read, two D reads: RDRF stays set"
    rd("S1")
    rd("D")                                  # the dummy read clears it, and underflows
    assert not uart.rdrf() and rd("SFIFO") & 0x01
    arrive(3, 4)
    first = rd("D")
    rd("S1")
    assert (first, rd("D")) == (3, 4) and not uart.rdrf()
    assert chip.notes == []


# ------------------------------------------------- FTM and WDOG models, no program ------------

def _write(dev, name, value, size=None):
    reg = dev.map[name]
    dev.write(dev.base + reg.offset, size or reg.bits // 8, value)


def call_in_image(machine, ret: int, address: int, args, budget: int):
    """Calls the image's function at ``address`` with ``args`` in r0-r3 as a debug probe
    would, returning to a BKPT written at ``ret`` (scratch RAM): the run's Stop, reason
    "bkpt" at ``ret`` once it returned (r0 holds the result)."""
    machine.write(ret, b"\x00\xbe\x00\xbe")                      # bkpt #0
    for i, value in enumerate(args):
        machine.set_reg(f"r{i}", value)
    machine.set_reg("lr", ret | 1)
    machine.set_reg("pc", address)
    return machine.run(instructions=budget)


def _wdog_off(chip):
    for name, value in (("UNLOCK", 0xC520), ("UNLOCK", 0xD928), ("STCTRLH", 0x01D2)):
        _write(chip.wdog, name, value)


def test_ftm_pwm_writes_wait_for_the_wrap_and_captures_copy_the_count():
    """The FTM model (native; ``Ftm`` is its view) at the reset clocks (bus = core clock, so
    one count a cycle): MOD and CnV load at once while stopped and at the next wrap while
    counting; an edge on a capture channel copies CNT into CnV and raises the interrupt
    until CHF is written 0; accesses of any width reach the 32-bit registers."""
    chip = Mk64()
    m, ftm0, ftm3 = chip.machine, chip.ftm0, chip.ftm3
    _wdog_off(chip)
    sc, cnsc = ftm0.map["SC"], ftm0.map["C0SC"]
    bus_clock = 1 << sc.field("CLKS").mask.bit_length() - 2          # CLKS = 1
    _write(ftm0, "MOD", 99)
    _write(ftm0, "C0SC", cnsc.bit("MSB") | cnsc.bit("ELSB"))
    _write(ftm0, "C0V", 25)
    assert ftm0.channel_mode(0) == "edge-aligned PWM" and ftm0.high_true(0)
    assert ftm0.period_s() is None and ftm0.commanded_value(0) == 25    # no clock yet
    _write(ftm0, "SC", bus_clock)
    hz = chip.bus_hz()
    assert ftm0.clock_hz() == hz and ftm0.cycles_per_tick() == 1.0
    assert ftm0.period_s() == 100 / hz and ftm0.pulse_s(0) == 25 / hz
    m.advance(10)
    _write(ftm0, "C0V", 50)
    assert ftm0.commanded_value(0) == 50 and ftm0.pulse_s(0) == 25 / hz, "waits for the wrap"
    assert ftm0.read_register("CNT") == 10
    m.advance(90)
    assert ftm0.read_register("CNT") == 0 and ftm0.pulse_s(0) == 50 / hz and not ftm0.pending
    assert ftm0.read_register("SC") & sc.bit("TOF"), "TOF computed when read (no TOIE)"
    c0v = ftm0.base + ftm0.map["C0V"].offset
    assert ftm0.read(c0v, 1) == 50 and ftm0.read(c0v, 2) == 50
    assert ftm0.next_tick(m.now()) == m.now()

    _write(ftm3, "MOD", 0xFFFF)
    _write(ftm3, "C0SC", cnsc.bit("ELSA") | cnsc.bit("ELSB") | cnsc.bit("CHIE"))
    _write(ftm3, "SC", bus_clock)
    assert ftm3.channel_mode(0) == "capture both"
    irq = 1 << (16 + ftm3.irq)
    m.advance(37)
    ftm3.edge(0, True)
    assert ftm3.captures == [(m.now(), 0, 37)] and ftm3.v["C0V"] == 37
    assert ftm3.read_register("STATUS") == 1 and m.irq_lines & irq
    ftm3.captures.clear()
    assert ftm3.captures == [], "taken once"
    _write(ftm3, "C0SC", ftm3.v["C0SC"] & ~cnsc.bit("CHF"))
    assert not m.irq_lines & irq and ftm3.read_register("STATUS") == 0
    assert ftm0.unmodelled == [] and ftm3.unmodelled == []
    _write(ftm3, "COMBINE", 1)
    assert ftm3.unmodelled == ["combined / dual-edge channel modes"]


def test_the_reset_control_module_says_power_on_after_every_reset():
    """RCM_SRS0/SRS1 hold a power-on reset's flags (POR and LVD), read only, and again after
    a reset: the emulated chip's every reset is a power-on reset."""
    chip = Mk64()
    rcm = chip.rcm
    srs0, srs1 = rcm.map["SRS0"], rcm.map["SRS1"]
    assert rcm.read(rcm.base + srs0.offset, 1) == srs0.bit("POR") | srs0.bit("LVD") == 0x82
    assert rcm.read(rcm.base + srs1.offset, 1) == 0
    _write(rcm, "SRS0", 0)                       # read only: the flags stay
    _write(rcm, "RPFW", 0x1F)                    # the pin filter stores what is written
    assert rcm.read_register("SRS0") == 0x82 and rcm.read_register("RPFW") == 0x1F
    chip.reset()
    assert rcm.read_register("SRS0") == 0x82 and rcm.read_register("RPFW") == 0


def test_watchdog_resets_with_its_cause():
    """The watchdog model (native; ``Wdog`` is its view): each way it resets the chip
    raises ChipReset("WDOG", why), whether the cause is a write or time passing."""
    chip = Mk64()
    with pytest.raises(ChipReset) as info:
        chip.machine.advance(1000)
    assert info.value.source == "WDOG"
    assert str(info.value) == ("reset by WDOG: no unlock sequence within the WCT (256 bus "
                               "clocks) after reset")

    chip = Mk64()
    wdog = chip.wdog
    with pytest.raises(ChipReset, match="8-bit write to WDOG_UNLOCK: the sequence is two "
                                        "16-bit writes"):
        _write(wdog, "UNLOCK", 0x20, size=1)
    assert [e[2:] for e in wdog.log] == [("UNLOCK", 0x20)]

    chip = Mk64()
    wdog = chip.wdog
    _write(wdog, "UNLOCK", 0xC520)
    _write(wdog, "UNLOCK", 0xD928)
    _write(wdog, "TOVALL", 1000)         # 1000 bus clocks, the watchdog left on
    _write(wdog, "TOVALH", 0)
    _write(wdog, "PRESC", 0)
    _write(wdog, "PRESC", 0x100)         # ignored: once only
    assert wdog.enabled and wdog.written == {"TOVALL", "TOVALH", "PRESC"}
    assert wdog.ignored == [(0, "PRESC", 0x100, "already written once since the unlock")]
    assert wdog.timeout_s() == 1000 / chip.bus_hz()
    _write(wdog, "REFRESH", 0xA602)
    _write(wdog, "REFRESH", 0xB480)
    with pytest.raises(ChipReset, match=r"invalid refresh sequence \(0x1234\)"):
        _write(wdog, "REFRESH", 0x1234)
    chip.machine.advance(999)
    with pytest.raises(ChipReset, match=r"watchdog timeout \(0.000 s\) while enabled"):
        chip.machine.advance(1)


WDOG_WRONG_REFRESH_C = C_PRELUDE + r"""
__attribute__((section(".vectors"), used)) void (*const vectors[16])(void) = {
    (void (*)(void))&_estack, reset };
volatile uint32_t sum;
int main(void) {
    for (int i = 0; i < 100; ++i) sum += REG16(0x40052004);     /* TOVALH: past the logged ones */
    REG16(0x4005200C) = 0x1234;
    for (;;) {}
}
"""


def test_a_wrong_refresh_from_the_program_stops_the_run_at_its_store(tmp_path):
    chip = Mk64(build(tmp_path, "wrong_refresh", WDOG_WRONG_REFRESH_C))
    m = chip.machine
    with pytest.raises(ChipReset, match=r"invalid refresh sequence \(0x1234\)") as info:
        chip.run(instructions=100_000)
    assert info.value.source == "WDOG"
    assert m.counts()["native_accesses"] >= 100 - m.FIRST_ACCESSES, "the native path took it"
    import capstone
    cs = capstone.Cs(capstone.CS_ARCH_ARM, capstone.CS_MODE_THUMB | capstone.CS_MODE_MCLASS)
    insn = next(cs.disasm(m.read(m.pc, 4), m.pc))
    assert m.image.function_at(m.pc).name == "main" and insn.mnemonic.startswith("strh"), \
        f"stopped at the store, which does not retire ({insn.mnemonic} {insn.op_str})"
