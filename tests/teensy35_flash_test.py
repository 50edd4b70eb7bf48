"""The emulated flash module (FTFE).

* The model (sim/mk64/ftfe.py; native), driven register by register with no program or with
  tiny programs compiled here: Erase Flash Sector and Program Phrase change the flash when
  they complete, after their data sheet times counted on the emulator's cycle clock;
  misaligned, unknown and out-of-range commands are refused (ACCERR), protected ones too
  (FPVIOL); programming never turns a 0 into a 1 (MGSTAT0); a store to flash is a bus fault;
  an instruction fetched from flash while a command runs is a read collision, and the same
  wait run from RAM is not; the flash keeps its bytes across a reset, which abandons a
  running command.

Every run is bounded by an instruction budget and every time is the emulator's; nothing here
depends on the machine's speed.
"""

from __future__ import annotations

import pathlib
import sys

import pytest

from heliquad.sim.mk64 import Fault, Mk64
from heliquad.sim.mk64.ftfe import (ERASE_FLASH_SECTOR, ERASE_SECTOR_S, MAX_TIMES,
                                    PROGRAM_PHRASE, PROGRAM_PHRASE_S, SECTOR_BYTES)

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parent))
import teensy35_boot_test as boot  # noqa: E402

CCIF, RDCOLERR, ACCERR, FPVIOL, MGSTAT0 = 0x80, 0x40, 0x20, 0x10, 0x01
PARAMS = 0x7E000                      # the image's two parameter sectors (linker script)


# ------------------------------------------------------------------ the model ------------------

def _chip():
    chip = Mk64()
    boot._wdog_off(chip)
    return chip


def _fstat(chip) -> int:
    return chip.ftfe.read_register("FSTAT")


def _launch(chip, code: int, address: int, data: bytes = b""):
    """FCCOB loaded (byte k of the phrase in FCCOB 7, 6, 5, 4, B, A, 9, 8), then CCIF written."""
    ftfe = chip.ftfe
    for name, value in (("FCCOB0", code), ("FCCOB1", address >> 16 & 0xFF),
                        ("FCCOB2", address >> 8 & 0xFF), ("FCCOB3", address & 0xFF)):
        boot._write(ftfe, name, value)
    for k, byte in enumerate(data):
        boot._write(ftfe, "FCCOB" + "7654BA98"[k], byte)
    boot._write(ftfe, "FSTAT", CCIF)


def _finish(chip):
    """Let a running command complete (time passes with no program)."""
    m = chip.machine
    m.advance(m.cycles_after(max(ERASE_SECTOR_S, PROGRAM_PHRASE_S)) - m.now())
    assert _fstat(chip) & CCIF


def test_erase_and_program_take_their_data_sheet_times_and_change_the_flash_when_done():
    chip = _chip()
    m, ftfe = chip.machine, chip.ftfe
    assert _fstat(chip) == CCIF, "idle after reset"
    m.write(PARAMS, bytes(range(64)))
    start = m.now()
    _launch(chip, ERASE_FLASH_SECTOR, PARAMS + 0x40)          # anywhere in the sector
    assert _fstat(chip) == 0 and ftfe.busy
    done = m.cycles_after(ERASE_SECTOR_S, start)
    m.advance(done - 1 - m.now())
    assert _fstat(chip) == 0 and m.read(PARAMS, 4) == bytes(range(4)), "not yet"
    m.advance(1)
    assert _fstat(chip) == CCIF
    assert m.read(PARAMS, SECTOR_BYTES) == b"\xff" * SECTOR_BYTES
    assert m.read(PARAMS - 1, 1) == b"\xff" and m.read(PARAMS + SECTOR_BYTES, 4) == b"\xff" * 4

    start = m.now()
    _launch(chip, PROGRAM_PHRASE, PARAMS + 8, b"\x01\x02\x03\x04\x05\x06\x07\x08")
    m.advance(m.cycles_after(PROGRAM_PHRASE_S, start) - 1 - m.now())
    assert _fstat(chip) == 0 and m.read(PARAMS + 8, 8) == b"\xff" * 8
    m.advance(1)
    assert _fstat(chip) == CCIF
    assert m.read(PARAMS, 24) == b"\xff" * 8 + bytes(range(1, 9)) + b"\xff" * 8
    assert [(c.code, c.address, c.end - c.start, c.fstat) for c in ftfe.log] == [
        (ERASE_FLASH_SECTOR, PARAMS + 0x40, m.cycles_after(ERASE_SECTOR_S, 0), CCIF),
        (PROGRAM_PHRASE, PARAMS + 8, m.cycles_after(PROGRAM_PHRASE_S, 0), CCIF)]
    assert ftfe.take_notes() == []


@pytest.mark.parametrize("code, address", [
    (PROGRAM_PHRASE, PARAMS + 4),          # a phrase is 8-byte aligned
    (ERASE_FLASH_SECTOR, PARAMS + 8),      # an erase address 16-byte aligned
    (PROGRAM_PHRASE, 0x80000),             # past the 512 KiB of program flash
    (0x01, PARAMS),                        # Read 1s Section: not modelled
    (0x49, PARAMS),                        # Erase All Blocks: not modelled
])
def test_misaligned_unknown_and_out_of_range_commands_are_refused_at_launch(code, address):
    chip = _chip()
    m = chip.machine
    m.write(PARAMS, b"\x00" * 16)
    _launch(chip, code, address, b"\x00" * 8)
    assert _fstat(chip) == CCIF | ACCERR and not chip.ftfe.busy
    m.advance(m.cycles_after(ERASE_SECTOR_S) - m.now())
    assert m.read(PARAMS, 16) == b"\x00" * 16
    # ACCERR still set: the next launch is not launched, until it is cleared (write 1)
    _launch(chip, ERASE_FLASH_SECTOR, PARAMS)
    assert _fstat(chip) == CCIF | ACCERR and not chip.ftfe.busy
    assert "ACCERR or FPVIOL set" in chip.ftfe.take_notes()[0][1]
    boot._write(chip.ftfe, "FSTAT", ACCERR)
    _launch(chip, ERASE_FLASH_SECTOR, PARAMS)
    assert chip.ftfe.busy
    _finish(chip)
    assert m.read(PARAMS, 16) == b"\xff" * 16


def test_programming_clears_bits_only_and_a_second_program_fails_its_verify():
    chip = _chip()
    m = chip.machine
    _launch(chip, PROGRAM_PHRASE, PARAMS, b"\x0f" * 8)
    _finish(chip)
    assert m.read(PARAMS, 8) == b"\x0f" * 8 and _fstat(chip) == CCIF
    _launch(chip, PROGRAM_PHRASE, PARAMS, b"\xf3" * 8)        # 0 -> 1 asked in bits 4..7
    _finish(chip)
    assert m.read(PARAMS, 8) == b"\x03" * 8, "the cells keep old AND new"
    assert _fstat(chip) == CCIF | MGSTAT0
    assert "not erased" in chip.ftfe.take_notes()[0][1]
    _launch(chip, ERASE_FLASH_SECTOR, PARAMS)
    assert not _fstat(chip) & MGSTAT0, "a launch clears MGSTAT0"
    _finish(chip)


def test_protection_comes_from_the_flash_configuration_field_and_refuses_with_fpviol():
    chip = _chip()
    m = chip.machine
    m.write(0x40B, b"\x7f")          # FPROT0 bit 7: region 31, the top 16 KiB, protected
    m.reset()
    boot._wdog_off(chip)
    assert chip.ftfe.read_register("FPROT0") == 0x7F
    _launch(chip, ERASE_FLASH_SECTOR, PARAMS)
    assert _fstat(chip) == CCIF | FPVIOL and not chip.ftfe.busy
    boot._write(chip.ftfe, "FSTAT", FPVIOL)
    _launch(chip, PROGRAM_PHRASE, 0x7BFF8, b"\x00" * 8)      # region 30: not protected
    _finish(chip)
    assert m.read(0x7BFF8, 8) == b"\x00" * 8
    boot._write(chip.ftfe, "FPROT0", 0xFF)
    assert chip.ftfe.read_register("FPROT0") == 0x7F, "protection can only be added"


def test_the_flash_keeps_its_bytes_across_a_reset_which_abandons_a_running_command():
    chip = _chip()
    m = chip.machine
    _launch(chip, PROGRAM_PHRASE, PARAMS, b"\x55" * 8)
    _finish(chip)
    m.reset()
    boot._wdog_off(chip)
    assert m.read(PARAMS, 8) == b"\x55" * 8 and _fstat(chip) == CCIF
    _launch(chip, ERASE_FLASH_SECTOR, PARAMS)
    m.advance(m.cycles_after(ERASE_SECTOR_S / 2) - m.now())
    changes = chip.ftfe.changes
    m.reset()
    boot._wdog_off(chip)
    assert _fstat(chip) == CCIF and not chip.ftfe.busy
    m.advance(m.cycles_after(ERASE_SECTOR_S) - m.now())
    assert m.read(PARAMS, 8) == b"\x55" * 8 and chip.ftfe.changes == changes


def test_the_command_times_are_settable_for_worst_cases():
    chip = _chip()
    chip.ftfe.times = MAX_TIMES
    assert chip.ftfe.times == MAX_TIMES
    m = chip.machine
    start = m.now()
    _launch(chip, ERASE_FLASH_SECTOR, PARAMS)
    m.advance(m.cycles_after(MAX_TIMES[0], start) - 1 - m.now())
    assert chip.ftfe.busy
    m.advance(1)
    assert not chip.ftfe.busy


def test_a_store_to_flash_is_a_bus_fault(tmp_path):
    elf = boot.build(tmp_path, "store", boot.ASM_RESET_ONLY + """
    ldr r0, =0x7E000
    movs r1, #0
    str r1, [r0]
    bkpt #0
""", asm=True)
    chip = Mk64(elf)
    with pytest.raises(Fault) as err:
        chip.run(instructions=100)
    assert err.value.kind == "BusFault" and "write to flash" in str(err.value)
    assert chip.machine.read(PARAMS, 4) == b"\xff" * 4


# Launch an erase of the parameter sector and wait for CCIF, the wait either in flash or in
# RAM (a .data section, copied there by the prelude), interrupts masked.
WAIT_PROGRAM = boot.C_PRELUDE + r"""
#define FSTAT REG8(0x40020000)
#define WAIT_SECTION %s
__attribute__((noinline, long_call, section(WAIT_SECTION)))
uint8_t launch_and_wait(void) {
    FSTAT = 0x80;
    while (!(FSTAT & 0x80)) {}
    return FSTAT;
}
volatile uint8_t result;
int main(void) {
    REG8(0x40020007) = 0x09;                     /* FCCOB0: Erase Flash Sector */
    REG8(0x40020006) = 0x07;                     /* FCCOB1..3: 0x07E000 */
    REG8(0x40020005) = 0xE0;
    REG8(0x40020004) = 0x00;
    __asm volatile("cpsid i");
    result = launch_and_wait();
    __asm volatile("cpsie i");
    return 0;
}
__attribute__((section(".vectors"), used)) void (*const vectors[16])(void) = {
    (void (*)(void))&_estack, reset };
"""


@pytest.mark.parametrize("where", ["flash", "RAM"])
def test_a_fetch_from_flash_while_a_command_runs_is_a_read_collision(tmp_path, where):
    section = '".text.wait"' if where == "flash" else '".data.wait"'
    elf = boot.build(tmp_path, "wait_" + where, WAIT_PROGRAM % section)
    chip = Mk64(elf)
    m = chip.machine
    m.write(PARAMS, b"\x00" * 4)
    if where == "flash":
        with pytest.raises(Fault) as err:
            chip.run(instructions=1_000_000)
        assert err.value.kind == "ReadCollision", err.value
        assert "launch_and_wait" in m.image.describe(err.value.pc)
        assert _fstat(chip) & RDCOLERR
        return
    start = m.now()
    stop = chip.run(instructions=5_000_000)
    assert stop.reason == "bkpt", stop
    assert m.read(m.image.symbol("result").address, 1)[0] == CCIF
    assert m.now() - start >= m.cycles_after(ERASE_SECTOR_S, 0)
    assert m.read(PARAMS, 4) == b"\xff" * 4

