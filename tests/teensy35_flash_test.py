"""The emulated flash module (FTFE) and the Teensy image's parameter storage on it.

* The model (sim/chip/ftfe.py; native), driven register by register with no program or with
  tiny programs compiled here: Erase Flash Sector and Program Phrase change the flash when
  they complete, after their data sheet times counted on the emulator's cycle clock;
  misaligned, unknown and out-of-range commands are refused (ACCERR), protected ones too
  (FPVIOL); programming never turns a 0 into a 1 (MGSTAT0); a store to flash is a bus fault;
  an instruction fetched from flash while a command runs is a read collision, and the same
  wait run from RAM is not; the flash keeps its bytes across a reset, which abandons a
  running command.
* The image's FlashParamStorage (firmware/targets/teensy35/param_storage.*), called directly
  in the emulated board (the core does not call it yet): save then load, the slot format,
  alternating slots, blank and corrupted slots, saves cut short between and during commands
  followed by a reset, and a save with the data sheet's maximum times on the running loop
  (watchdog on).
* A parameter the image reads from that flash at start-up: UART0's baud rate
  (SER_TEL1_BAUD) and its link's budget.

Every run is bounded by an instruction budget and every time is the emulator's; nothing here
depends on the machine's speed.
"""

from __future__ import annotations

import pathlib
import struct
import sys
import zlib

import pytest

from heliquad.sim.chip import Fault, Mk64, Teensy35
from heliquad.sim.chip.ftfe import (ERASE_FLASH_SECTOR, ERASE_SECTOR_S, MAX_TIMES, PROGRAM_PHRASE,
                                    PROGRAM_PHRASE_S, SECTOR_BYTES)

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parent))
import teensy35_boot_test as boot  # noqa: E402

CCIF, RDCOLERR, ACCERR, FPVIOL, MGSTAT0 = 0x80, 0x40, 0x20, 0x10, 0x01
PARAMS = 0x7E000                      # the image's two parameter sectors (linker script)
PARAMS_MAGIC = 0x31505148             # a parameter record's magic, "HQP1" (params.cpp)


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


# ------------------------------------------------------------ the image's storage --------------

MAGIC = 0x31505148                    # FlashParamStorage::kMagic, "HQP1"
HEADER = 16
MAX_RECORD = 1024                     # hq::ParamStorage::kMaxBytes
OK, EMPTY, CORRUPT = 0, 1, 2          # hq::StoreStatus
STORAGE_OBJECT = "_ZZ14hq_teensy_mainE7storage"     # main.cpp's static FlashParamStorage
PROGRAM_STORAGE_OBJECT = "_ZZ14hq_teensy_mainE15program_storage"   # the on-board program's
PROGRAM_MAGIC = 0x31475148            # "HQG1": the program's slots
CALL_BUDGET = 20_000_000              # instructions; a 1 KiB save polls some 10^6


class Storage:
    """The image's FlashParamStorage, called directly on the emulated board (the core does
    not call it yet): each call enters the method with its arguments in r0-r3 and returns to
    a BKPT, as a call from the loop would. Scratch memory (the return BKPT, the record
    buffer) is at the bottom of the stack region, which the stack never reaches."""

    def __init__(self, board, obj: str = STORAGE_OBJECT):
        self.board, self.m = board, board.machine
        image = self.m.image
        self.this = image.symbol(obj).address
        self.methods = {name: image.symbol(f"hq::teensy::FlashParamStorage::{name}").address
                        for name in ("save", "load")}
        base = (image.ram_end() + 63) & ~31
        self.ret, self.n_word, self.buffer = base, base + 8, base + 16
        self.start, self.end = board.param_flash_range()
        self._cut = None
        self.m.break_at("hq_ftfe_run", self._on_command)

    def _on_command(self, m):
        """A breakpoint on the RAM function: stop as the (cut + 1)-th command would launch."""
        if self._cut is None:
            return None
        self._cut -= 1
        return "cut" if self._cut < 0 else None

    def _call(self, method: str, *args):
        m = self.m
        stop = boot.call_in_image(m, self.ret, self.methods[method], (self.this,) + args,
                                  CALL_BUDGET)
        if stop.reason == "cut":
            return None
        assert stop.reason == "bkpt" and stop.pc == self.ret, stop
        return m.reg("r0")

    def save(self, record: bytes, cut: int | None = None):
        """True/False as save() returns; None when stopped as command ``cut + 1`` launches."""
        self.m.write(self.buffer, record)
        self._cut = cut
        try:
            result = self._call("save", self.buffer, len(record))
        finally:
            self._cut = None
        return None if result is None else bool(result & 0xFF)

    def load(self, capacity: int = MAX_RECORD):
        """(status, record)."""
        self.m.write(self.n_word, b"\xaa" * 4)
        status = self._call("load", self.buffer, capacity, self.n_word) & 0xFF
        n = struct.unpack("<I", self.m.read(self.n_word, 4))[0]
        return status, (self.m.read(self.buffer, n) if status == OK else None)

    def slot(self, i: int) -> bytes:
        return self.m.read(self.start + i * SECTOR_BYTES, SECTOR_BYTES)


def _to_main(storage: Storage) -> Storage:
    """The board from reset to the entry of hq_teensy_main: .data (the RAM function, the
    storage object) in place, clocks at their reset values, watchdog off."""
    stop = storage.board.run(instructions=1_000_000)
    assert stop.reason == "breakpoint" and stop.pc == storage.m.image.symbol(
        "hq_teensy_main").address, stop
    return storage


@pytest.fixture
def storage():
    boot.require_image()
    board = Teensy35(boot.IMAGE, with_mpu6050=False)
    board.machine.break_at("hq_teensy_main")
    return _to_main(Storage(board))


def _power_cycle(storage: Storage) -> Storage:
    """A reset of the chip (power off and on): RAM starts afresh, the flash keeps its bytes."""
    storage.board.reset()
    return _to_main(storage)


def _slot(sequence: int, record: bytes) -> bytes:
    """A slot as the documented format has it (docs/teensy35.md)."""
    head = struct.pack("<II", sequence, len(record))
    crc = zlib.crc32(head + record)
    body = struct.pack("<IIII", MAGIC, sequence, len(record), crc) + record
    return body + b"\xff" * (SECTOR_BYTES - len(body))


def test_the_parameter_sectors_are_the_top_8_kib_and_start_blank(storage):
    assert (storage.start, storage.end) == (PARAMS, 0x80000)
    assert storage.board.read_param_flash() == b"\xff" * 2 * SECTOR_BYTES
    assert storage.load() == (EMPTY, None)
    image = storage.m.image
    ram_function = image.symbol("hq_ftfe_run")
    data = image.symbol("_sdata").address, image.symbol("_edata").address
    assert data[0] <= ram_function.address < data[1], "the command's wait runs from RAM"


def test_save_then_load_returns_the_record_in_the_documented_format(storage):
    record = bytes(range(256)) * 4
    m = storage.m
    start = m.now()
    assert storage.save(record) is True
    seconds = (m.now() - start) / m.core_hz
    phrases = MAX_RECORD // 8 + 2
    expected = ERASE_SECTOR_S + phrases * PROGRAM_PHRASE_S
    log = storage.board.chip.ftfe.log
    busy = sum(c.end - c.start for c in log) / m.core_hz
    print(f"save of {len(record)} B at {m.core_hz / 1e6:.2f} MHz: {seconds * 1e3:.2f} ms "
          f"emulated, {busy * 1e3:.2f} ms of it flash commands ({phrases} phrases)")
    assert busy == pytest.approx(expected, rel=2e-3)       # events land at block boundaries
    assert expected < seconds < 2 * expected, "the rest is the CPU's reads and CRCs"
    assert storage.load() == (OK, record)
    assert storage.slot(0) == _slot(1, record) and storage.slot(1) == b"\xff" * SECTOR_BYTES
    assert [c.code for c in log] == [ERASE_FLASH_SECTOR] + [PROGRAM_PHRASE] * phrases
    assert [c.address for c in log[-2:]] == [PARAMS + 8, PARAMS], "the magic's phrase last"
    assert all(c.fstat == CCIF for c in log)
    assert storage.board.chip.ftfe.take_notes() == []
    assert len(storage.board.chip.fmc.invalidations) >= 2, "cache invalidated after writing"


def test_saves_alternate_slots_and_load_takes_the_newest(storage):
    records = [b"first", b"second record", b"", b"x" * 9]
    for record in records:
        assert storage.save(record) is True
        assert storage.load() == (OK, record)
    assert storage.slot(0) == _slot(3, records[2]) and storage.slot(1) == _slot(4, records[3])
    storage = _power_cycle(storage)
    assert storage.load() == (OK, records[3])


def test_refused_arguments_touch_no_flash(storage):
    assert storage.save(b"\x00" * (MAX_RECORD + 1)) is False
    assert storage.board.chip.ftfe.log == []
    assert storage.save(b"abc") is True
    assert storage.load(capacity=2) == (CORRUPT, None), "a record the caller cannot hold"


@pytest.mark.parametrize("damage", ["magic", "record", "length"])
def test_a_damaged_slot_falls_back_to_the_other_and_both_damaged_is_corrupt(storage, damage):
    assert storage.save(b"older") is True
    assert storage.save(b"newer") is True
    offset = {"magic": 0, "record": HEADER + 2, "length": 8}[damage]
    m = storage.m
    address = storage.start + SECTOR_BYTES + offset          # the newer record's slot
    m.write(address, bytes([m.read(address, 1)[0] ^ 0x10]))
    assert storage.load() == (OK, b"older")
    m.write(storage.start + offset, bytes([m.read(storage.start + offset, 1)[0] ^ 0x10]))
    assert storage.load() == (CORRUPT, None)
    assert storage.save(b"again") is True, "a save over damaged slots"
    assert storage.load() == (OK, b"again")


def test_one_written_slot_damaged_and_the_other_blank_is_corrupt(storage):
    flash = bytearray(b"\xff" * 2 * SECTOR_BYTES)
    flash[SECTOR_BYTES + 100] = 0x00                          # a stray zero, no header
    storage.board.write_param_flash(bytes(flash))
    assert storage.load() == (CORRUPT, None)
    storage.board.write_param_flash(_slot(7, b"from a file") + b"\xff" * SECTOR_BYTES)
    assert storage.load() == (OK, b"from a file")
    assert storage.save(b"next") is True
    assert storage.slot(1)[:16] == struct.pack("<IIII", MAGIC, 8, 4, zlib.crc32(
        struct.pack("<II", 8, 4) + b"next")), "the next sequence, in the other slot"


@pytest.mark.parametrize("commands", [0, 1, 2, 64, 126, 127])
def test_a_save_cut_short_between_commands_leaves_the_previous_record(storage, commands):
    """Stopped as command ``commands + 1`` would launch (of 128: the erase, 125 record
    phrases, the header's second phrase, its first; so 0: before the erase, 1: after it, 127:
    everything but the magic's phrase), then a reset: the previous record loads, and the next
    save works."""
    old, new = b"o" * 1000, b"n" * 1000                      # 125 + 2 phrases
    assert storage.save(old) is True
    assert storage.save(new, cut=commands) is None
    storage = _power_cycle(storage)
    assert storage.load() == (OK, old)
    assert storage.save(new) is True
    assert storage.load() == (OK, new)


@pytest.mark.parametrize("commands, into_s", [(0, ERASE_SECTOR_S / 2),
                                              (50, PROGRAM_PHRASE_S / 2),
                                              (127, PROGRAM_PHRASE_S / 2)])
def test_a_reset_while_a_command_runs_leaves_the_previous_record(storage, commands, into_s):
    """Stopped as command ``commands + 1`` launches, run into it, reset: the command is
    abandoned and the previous record loads."""
    old = b"previous"
    assert storage.save(b"oldest") is True
    assert storage.save(old) is True
    assert storage.save(b"n" * 1000, cut=commands) is None
    m = storage.m
    m.run(seconds=into_s)                                     # the command is under way
    assert storage.board.chip.ftfe.busy
    storage = _power_cycle(storage)
    assert storage.load() == (OK, old)


def test_a_save_on_the_running_loop_with_the_slowest_flash_keeps_the_watchdog_fed():
    """At 120 MHz with the watchdog on (500 ms): a 1 KiB save with the data sheet's maximum
    times (an erase of 115 ms, phrases of 150 us) completes and the chip does not reset."""
    boot.require_image()
    board = Teensy35(boot.IMAGE)
    assert board.run_to_loop(1, instructions=boot.BOOT_BUDGET).reason == "loop"
    assert board.chip.wdog.enabled and board.machine.core_hz == 120e6
    storage = Storage(board)
    board.chip.ftfe.times = MAX_TIMES
    record = bytes(range(256)) * 4
    m = board.machine
    start = m.now()
    assert storage.save(record) is True
    seconds = (m.now() - start) / m.core_hz
    print(f"save with the maximum times: {seconds * 1e3:.1f} ms emulated")
    assert MAX_TIMES[0] + 130 * MAX_TIMES[1] < seconds < board.chip.wdog.timeout_s()
    assert storage.load() == (OK, record)


# ------------------------------------------------ the processor-in-the-loop's parameter file ---

def test_the_pil_board_keeps_its_parameter_flash_in_a_file(tmp_path):
    """--params FILE: the file's two sectors are in the flash before the boot; after the image
    changes them (a save, here called directly) they are written back."""
    boot.require_image()
    pytest.importorskip("heliquad._firmware")
    from heliquad.sim.chip.pil.board import PilBoard

    path = tmp_path / "params.bin"
    path.write_bytes(_slot(3, b"kept") + b"\xff" * SECTOR_BYTES)
    pil = PilBoard(str(boot.IMAGE), params_file=str(path), link="uart")
    pil.boot()
    storage = Storage(pil.board)
    assert storage.load() == (OK, b"kept")
    pil.params.keep()
    assert path.read_bytes() == _slot(3, b"kept") + b"\xff" * SECTOR_BYTES, "nothing changed"
    assert storage.save(b"changed") is True
    pil.params.keep()                                 # what each frame does after its loop
    assert path.read_bytes() == _slot(3, b"kept") + _slot(4, b"changed")
    assert not (tmp_path / "params.bin.tmp").exists()

    new_board = PilBoard(str(boot.IMAGE), params_file=str(tmp_path / "none.bin"), link="uart")
    new_board.boot()
    assert new_board.board.read_param_flash() == b"\xff" * 2 * SECTOR_BYTES
    assert not (tmp_path / "none.bin").exists(), "created only when the image writes"


def test_the_program_has_its_own_two_sectors_and_its_own_file(tmp_path):
    """The on-board program's storage: the two sectors below the parameters', slots with
    their own magic (so neither pair loads as the other's record), kept in --program's file
    as --params keeps the parameters'; a program save leaves the parameter file alone."""
    boot.require_image()
    pytest.importorskip("heliquad._firmware")
    from heliquad.sim.chip.pil.board import PilBoard

    params, program = tmp_path / "p.bin", tmp_path / "p.bin.program"
    params.write_bytes(_slot(2, b"parameters") + b"\xff" * SECTOR_BYTES)
    pil = PilBoard(str(boot.IMAGE), params_file=str(params), program_file=str(program),
                   link="uart")
    pil.boot()
    board_params, board_program = Storage(pil.board), Storage(pil.board, PROGRAM_STORAGE_OBJECT)
    assert pil.board.stored_range("program") == (0x7C000, 0x7E000)
    assert board_program.load() == (EMPTY, None)
    assert board_params.load() == (OK, b"parameters")
    assert board_program.save(b"steps") is True
    for kept in pil.stored:
        kept.keep()
    assert params.read_bytes() == _slot(2, b"parameters") + b"\xff" * SECTOR_BYTES
    flash = program.read_bytes()
    assert len(flash) == 2 * SECTOR_BYTES and flash == pil.board.read_stored("program")
    assert int.from_bytes(flash[:4], "little") == PROGRAM_MAGIC
    assert board_params.load() == (OK, b"parameters")
    # a parameter slot copied into the program's sectors is no program
    pil.board.write_stored(_slot(9, b"parameters") + b"\xff" * SECTOR_BYTES, "program")
    assert board_program.load() == (CORRUPT, None)

    again = PilBoard(str(boot.IMAGE), params_file=str(params), program_file=str(program),
                     link="uart")
    again.boot()
    assert Storage(again.board, PROGRAM_STORAGE_OBJECT).load() == (OK, b"steps")


def test_the_drop_in_takes_a_params_file_and_refuses_one_of_the_wrong_size(tmp_path):
    boot.require_image()
    from heliquad.sim.base.errors import FirmwareError
    from heliquad.sim.rig.lockstep import PilFirmware

    good = tmp_path / "good.bin"
    good.write_bytes(_slot(1, b"abc") + b"\xff" * SECTOR_BYTES)
    with PilFirmware(image=str(boot.IMAGE), params_file=str(good)) as fw:
        assert fw.alive()
    assert good.read_bytes() == _slot(1, b"abc") + b"\xff" * SECTOR_BYTES
    bad = tmp_path / "bad.bin"
    bad.write_bytes(b"\x00" * 100)
    with pytest.raises(FirmwareError, match="100 bytes.*8192 bytes"):
        PilFirmware(image=str(boot.IMAGE), params_file=str(bad))


# ------------------------------------------------------- UART0's baud rate from the flash ---

def _params_record(**values) -> bytes:
    """A parameter record (docs/parameters.md) holding only ``values``: the others keep their
    defaults."""
    body = struct.pack("<II", PARAMS_MAGIC, len(values)) + b"".join(
        struct.pack("<If", zlib.crc32(name.encode()), value) for name, value in values.items())
    return body + struct.pack("<I", zlib.crc32(body))


def _acks(board, mav_mod) -> list:
    """The COMMAND_ACKs in the telemetry UART0 has sent since the last take."""
    parser = mav_mod.MAVLink(None)
    parser.robust_parsing = True                      # the take began inside a frame
    acks = []
    for b in board.take_telemetry():
        m = parser.parse_char(bytes([b]))
        if m is not None and m.get_type() == "COMMAND_ACK":
            acks.append(m)
    return acks


def test_uart0_starts_at_the_stored_baud_rate_and_its_link_budget_follows():
    """SER_TEL1_BAUD = 115200 in the parameter flash: the image begins UART0 at 115200 (SBR
    and BRFA within 2 %, bytes one frame of that rate apart), and its link's budget is 11.5
    kB/s: turning ATTITUDE off is taken (it adds nothing), a faster SCALED_IMU (taken at
    921600) is refused."""
    boot.require_image()
    pytest.importorskip("heliquad._firmware")
    from heliquad.sim.base.dialect import dialect

    board = Teensy35(boot.IMAGE)
    board.write_param_flash(_slot(1, _params_record(SER_TEL1_BAUD=115200.0)) +
                            b"\xff" * SECTOR_BYTES)
    assert board.run_to_loop(4, instructions=boot.BOOT_BUDGET).reason == "loop"
    uart = board.chip.uart0
    assert abs(uart.baud() / 115200 - 1) < 0.02
    assert uart.frame_cycles() == round(10 * 120e6 / uart.baud())
    gaps = [b[0] - a[0] for a, b in zip(uart.sent, uart.sent[1:])]
    assert gaps and min(gaps) == uart.frame_cycles()
    mav_mod = dialect()
    host = mav_mod.MAVLink(None, srcSystem=255, srcComponent=190)
    board.take_telemetry()
    for msgid, interval_us in ((mav_mod.MAVLINK_MSG_ID_ATTITUDE, -1),
                               (mav_mod.MAVLINK_MSG_ID_SCALED_IMU, 20000)):
        board.receive(host.command_long_encode(1, 1, mav_mod.MAV_CMD_SET_MESSAGE_INTERVAL, 0,
                                               msgid, interval_us, 0, 0, 0, 0, 0).pack(host))
        board.run(seconds=0.1)
    acks = _acks(board, mav_mod)
    assert [a.result for a in acks] == [mav_mod.MAV_RESULT_ACCEPTED, mav_mod.MAV_RESULT_DENIED]
