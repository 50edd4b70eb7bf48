"""The emulated SDHC controller (sim/chip/sdhc.py) with its card (sd_card.py), and the image's
SD card driver (firmware/targets/teensy35/block_device.cpp) identifying it.

* Register level, with no program: the test plays the driver's part (the same sequence and
  register values as SdhcCard): identification at 375 kHz, the card's states and responses,
  CSD size and write protection, ADMA2 writes and reads with auto-CMD12, the busy on DAT0
  after a write and TC after it, the MPU's rule for bus master 5, and the faults: no card,
  a corrupt response CRC, a negative CRC status (and the stop that recovers), a response with
  an error bit, a full card, a card that holds busy, and a power cut (the image keeps exactly
  the blocks acknowledged).
* The image: a card image present -> hq_sd_probe says Ready with the card's size; absent ->
  NoCard; a write-protected card -> its flag.
"""

from __future__ import annotations

import pathlib
import sys

import pytest

from heliquad.sim.chip import Fault, Mk64
from heliquad.sim.chip.sd_card import ERROR, OUT_OF_RANGE, WP_VIOLATION, SdCard
from heliquad.sim.chip.teensy35 import Teensy35

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parent))
import teensy35_boot_test as boot  # noqa: E402

BLOCK = 512
TABLE = 0x2000_0000                 # ADMA2 descriptors, in SRAM_U
BUFFER = 0x2000_0100
# XFERTYP flags, as the driver builds them
R1 = 2 << 16 | 1 << 19 | 1 << 20
R1B = 3 << 16 | 1 << 19 | 1 << 20
R2 = 1 << 16 | 1 << 19
R3 = 2 << 16
DATA = 1 << 21 | 1 << 0                              # DPSEL, DMAEN
MULTI = 1 << 5 | 1 << 1 | 1 << 2                      # MSBSEL, BCEN, AC12EN
READ = 1 << 4                                         # DTDSEL
CC, TC, CTOE, CCE, DTOE, DCE, DMAE = 1, 2, 1 << 16, 1 << 17, 1 << 20, 1 << 21, 1 << 28
DAT0 = 1 << 24
IDENT_SYSCTL = 0x10 << 8 | 9 << 4 | 0xE << 16 | 0xF       # 120 MHz / 32 / 10, SDCLKEN
FAST_SYSCTL = 0x00 << 8 | 4 << 4 | 0xE << 16 | 0xF        # 120 MHz / 5
CORE_HZ = 120e6


def _w(dev, name, value):
    boot._write(dev, name, value)


def _r(dev, name):
    return dev.read_register(name)


def _card_image(tmp_path, blocks=2048, name="card.img"):
    path = tmp_path / name
    path.write_bytes(bytes(blocks * BLOCK))
    return path


def _chip(card=None, grant=True):
    """The chip at its 120 MHz core (the SDHC's clock), the SDHC gated on, PTE0-5 on ALT4,
    master 5 granted by the MPU (unless ``grant`` is False) and ``card`` in the socket."""
    chip = Mk64()
    boot._wdog_off(chip)
    chip.machine.set_clocks(CORE_HZ, CORE_HZ / 2)
    chip.clocks_changed = lambda cause: None            # keep the stated core clock
    chip.core_hz = lambda: CORE_HZ
    sim = chip.sim
    _w(sim, "SCGC3", sim.v["SCGC3"] | sim.map["SCGC3"].bit("SDHC"))
    _w(sim, "SCGC5", sim.v["SCGC5"] | sim.map["SCGC5"].bit("PORTE"))
    for n in range(6):
        _w(chip.ports.port["E"], f"PCR{n}", 4 << 8 | 0x43)
    if grant:
        rgd = chip.mpu.map["RGDAAC0"]
        _w(chip.mpu, "RGDAAC0", chip.mpu.v["RGDAAC0"] | rgd.bit("M5RE") | rgd.bit("M5WE"))
    chip.sdhc.insert(card)
    _w(chip.sdhc, "PROCTL", 2 << 4 | 2 << 8)                # little endian, ADMA2
    _w(chip.sdhc, "SYSCTL", IDENT_SYSCTL)
    return chip


def _settle(chip, seconds=2e-3):
    chip.machine.advance(int(seconds * CORE_HZ))


def _command(chip, index, arg, flags, seconds=2e-3):
    """Sends a command and lets it finish: IRQSTAT afterwards."""
    sd = chip.sdhc
    _w(sd, "IRQSTAT", 0xFFFF_FFFF)
    _w(sd, "CMDARG", arg)
    _w(sd, "XFERTYP", index << 24 | flags)
    assert _r(sd, "PRSSTAT") & 1, "CIHB while the command is out"
    _settle(chip, seconds)
    return _r(sd, "IRQSTAT")


def _identify(chip):
    """The driver's identification: the card's block count from its CSD."""
    sd = chip.sdhc
    _command(chip, 0, 0, 0)
    assert _command(chip, 8, 0x1AA, R1) == CC and _r(sd, "CMDRSP0") & 0xFFF == 0x1AA
    for _ in range(10):
        assert _command(chip, 55, 0, R1) == CC
        assert _command(chip, 41, 0x4030_0000, R3) == CC
        if _r(sd, "CMDRSP0") >> 31:
            break
    assert _r(sd, "CMDRSP0") >> 30 == 3, "ready and block-addressed"
    assert _command(chip, 2, 0, R2) == CC
    assert _command(chip, 3, 0, R1) == CC
    rca = _r(sd, "CMDRSP0") & 0xFFFF_0000
    assert _command(chip, 9, rca, R2) == CC
    assert _r(sd, "CMDRSP3") >> 22 & 3 == 1, "a version 2 CSD"
    blocks = ((_r(sd, "CMDRSP1") >> 8 & 0x3FFFFF) + 1) * 1024
    wp = bool(_r(sd, "CMDRSP0") & 0x30)
    assert _command(chip, 7, rca, R1B) & CC
    assert _command(chip, 55, rca, R1) == CC and _command(chip, 6, 2, R1) == CC
    _w(sd, "PROCTL", _r(sd, "PROCTL") | 1 << 1)           # 4-bit
    assert _command(chip, 16, BLOCK, R1) == CC
    _w(sd, "SYSCTL", FAST_SYSCTL)
    return blocks, wp


def _table(chip, address, blocks):
    desc = (blocks * BLOCK) << 16 | 0x20 | 0x2 | 0x1        # tran, end, valid
    chip.machine.write(TABLE, desc.to_bytes(4, "little") + address.to_bytes(4, "little"))
    _w(chip.sdhc, "ADSADDR", TABLE)


def _transfer(chip, index, lba, blocks, flags):
    sd = chip.sdhc
    _table(chip, BUFFER, blocks)
    _w(sd, "BLKATTR", blocks << 16 | BLOCK)
    _w(sd, "IRQSTAT", 0xFFFF_FFFF)
    _w(sd, "CMDARG", lba)
    _w(sd, "XFERTYP", index << 24 | R1 | DATA | flags)


def _wait_tc(chip, limit_s=1.0):
    sd, step = chip.sdhc, 1e-4
    for _ in range(int(limit_s / step)):
        stat = _r(sd, "IRQSTAT")
        if stat & (TC | 0xFFFF_0000):
            return stat
        _settle(chip, step)
    return _r(sd, "IRQSTAT")


def test_identification_reads_the_size_and_the_card_goes_through_its_states(tmp_path):
    card = SdCard(_card_image(tmp_path, blocks=4096))
    chip = _chip(card)
    assert _identify(chip) == (4096, False)
    assert card.state == "tran"
    states = [s for _, _, s in card.log]
    assert states[:3] == ["idle", "idle", "idle"] and "ready" in states and "stby" in states
    assert not chip.notes, chip.notes
    assert chip.sdhc.sd_hz() == 24e6
    big = tmp_path / "32g.img"                               # sparse: C_SIZE's 22 bits
    with open(big, "wb") as f:
        f.truncate(32 << 30)
    assert _identify(_chip(SdCard(big))) == (32 << 30 >> 9, False)


def test_no_card_times_out_a_fast_identification_clock_is_noted_and_busy_stays_busy(tmp_path):
    chip = _chip(None)
    _command(chip, 0, 0, 0)
    assert _command(chip, 8, 0x1AA, R1) == CTOE | 0
    assert _command(chip, 55, 0, R1) == CTOE
    card = SdCard(_card_image(tmp_path))
    chip.sdhc.insert(card)
    _w(chip.sdhc, "SYSCTL", FAST_SYSCTL)
    _command(chip, 0, 0, 0)
    assert _command(chip, 8, 0x1AA, R1) == CC
    assert any("during identification" in text for _, text in chip.notes)
    card.busy_tries = None                                  # a card that never gets ready
    _w(chip.sdhc, "SYSCTL", IDENT_SYSCTL)
    _command(chip, 0, 0, 0)
    assert _command(chip, 8, 0x1AA, R1) == CC
    for _ in range(20):
        assert _command(chip, 55, 0, R1) == CC and _command(chip, 41, 0x4030_0000, R3) == CC
        assert not _r(chip.sdhc, "CMDRSP0") >> 31 and card.state == "idle"


def test_pins_not_on_the_sdhc_mean_no_answer(tmp_path):
    chip = _chip(SdCard(_card_image(tmp_path)))
    _w(chip.ports.port["E"], "PCR3", 1 << 8)              # CMD as a GPIO
    assert _command(chip, 8, 0x1AA, R1) == CTOE


def test_adma2_write_holds_dat0_busy_then_tc_and_reads_back(tmp_path):
    path = _card_image(tmp_path)
    card = SdCard(path)
    chip = _chip(card)
    _identify(chip)
    data = bytes(range(256)) * 6                            # three blocks
    chip.machine.write(BUFFER, data)
    _transfer(chip, 25, 100, 3, MULTI)
    _settle(chip, 1.5e-3)                                   # first block in, programming
    assert not _r(chip.sdhc, "PRSSTAT") & DAT0, "DAT0 low while the card programs"
    assert not _r(chip.sdhc, "IRQSTAT") & TC
    assert _wait_tc(chip) == CC | TC
    assert _r(chip.sdhc, "PRSSTAT") & DAT0 and not _r(chip.sdhc, "PRSSTAT") & 0x7
    assert path.read_bytes()[100 * BLOCK:103 * BLOCK] == data
    assert card.state == "tran" and [c for _, c, _, _ in chip.sdhc.log][-2:] == [25, 12]
    chip.machine.write(BUFFER, bytes(3 * BLOCK))
    _transfer(chip, 18, 100, 3, MULTI | READ)
    assert _wait_tc(chip) == CC | TC
    assert chip.machine.read(BUFFER, 3 * BLOCK) == data
    _transfer(chip, 17, 101, 1, READ)
    assert _wait_tc(chip) == CC | TC
    assert chip.machine.read(BUFFER, BLOCK) == data[BLOCK:2 * BLOCK]
    assert card.state == "tran"


def test_the_mpu_must_grant_master_5(tmp_path):
    chip = _chip(SdCard(_card_image(tmp_path)), grant=False)
    _identify(chip)
    _transfer(chip, 25, 0, 1, MULTI)
    with pytest.raises(Fault, match="bus master 5"):
        _settle(chip, 1e-3)


def test_a_corrupt_response_crc_and_a_negative_crc_status_fail_and_cmd12_recovers(tmp_path):
    path = _card_image(tmp_path)
    card = SdCard(path)
    chip = _chip(card)
    _identify(chip)
    chip.sdhc.corrupt_command_crc = 1
    assert _command(chip, 13, card.rca << 16, R1) == CC | CCE
    card.fail_writes = "crc"
    chip.machine.write(BUFFER, b"\xAA" * BLOCK)
    _transfer(chip, 25, 5, 1, MULTI)
    assert _wait_tc(chip) == CC | DCE
    assert card.state == "rcv" and path.read_bytes()[5 * BLOCK:6 * BLOCK] == bytes(BLOCK)
    _w(chip.sdhc, "SYSCTL", FAST_SYSCTL | 3 << 25)          # RSTC | RSTD
    card.fail_writes = None
    assert _command(chip, 12, 0, R1B) & CC
    _settle(chip, 5e-3)
    assert card.state == "tran"
    _transfer(chip, 25, 5, 1, MULTI)
    assert _wait_tc(chip) == CC | TC
    assert path.read_bytes()[5 * BLOCK:6 * BLOCK] == b"\xAA" * BLOCK


def test_error_bits_in_the_response_for_status_failures_a_full_card_and_write_protection(
        tmp_path):
    card = SdCard(_card_image(tmp_path, blocks=1024))
    chip = _chip(card)
    assert _identify(chip) == (1024, False)
    card.fail_writes = "status"
    _transfer(chip, 25, 0, 1, MULTI)
    assert _wait_tc(chip) & (CC | DCE) == CC | DCE and _r(chip.sdhc, "CMDRSP0") & ERROR
    card.fail_writes = None
    _transfer(chip, 25, 1024, 1, MULTI)                     # past the end: a full card
    assert _wait_tc(chip) & (CC | DCE) == CC | DCE
    assert _r(chip.sdhc, "CMDRSP0") & OUT_OF_RANGE
    chip2 = _chip(SdCard(_card_image(tmp_path, blocks=1024, name="wp.img")))
    chip2.sdhc.card.write_protect = True
    assert _identify(chip2) == (1024, True)
    _transfer(chip2, 25, 0, 1, MULTI)
    _wait_tc(chip2)
    assert _r(chip2.sdhc, "CMDRSP0") & WP_VIOLATION


def test_a_card_that_holds_busy_keeps_dat0_low_for_the_hold(tmp_path):
    card = SdCard(_card_image(tmp_path))
    card.busy_hold = (0.25, 1.0)
    chip = _chip(card)
    _identify(chip)
    start = chip.machine.seconds()
    _transfer(chip, 25, 0, 1, MULTI)
    assert _wait_tc(chip, limit_s=1.0) == CC | TC
    assert 0.25 < chip.machine.seconds() - start < 0.27
    start = chip.machine.seconds()
    _transfer(chip, 25, 1, 1, MULTI)                        # same second: no hold
    assert _wait_tc(chip) == CC | TC
    assert chip.machine.seconds() - start < 0.01


def test_a_power_cut_leaves_exactly_the_acknowledged_blocks(tmp_path):
    path = _card_image(tmp_path)
    chip = _chip(SdCard(path))
    _identify(chip)
    chip.machine.write(BUFFER, b"\x11" * BLOCK + b"\x22" * BLOCK + b"\x33" * BLOCK)
    _transfer(chip, 25, 10, 3, MULTI)
    _settle(chip, 0.5e-3)                                   # one block acknowledged
    image = path.read_bytes()                               # the run stops here
    assert image[10 * BLOCK:11 * BLOCK] == b"\x11" * BLOCK
    assert image[11 * BLOCK:13 * BLOCK] == bytes(2 * BLOCK)


# ============================================================ the image's driver ===============

OK, BUSY, NO_CARD, WRITE_PROTECTED, OUT_OF_RANGE_STATUS, FAILED = range(6)   # hq::BlockStatus


def _probe(board):
    report = board.machine.image.symbol("hq_sd_probe")
    raw = board.machine.read(report.address, 8)
    return int.from_bytes(raw[:4], "little"), raw[4], raw[5], raw[6]


# hq_sd_probe for a card that start() refuses: (blocks, SdhcCard::Finding, BlockStatus)
# (A card that never gets ready, Finding NotReady, costs the image 1 s of ACMD41 tries: the
# register-level test shows the card model's side of it.)
REFUSED = {"none": (0, 1, NO_CARD), "version1": (0, 2, FAILED)}


@pytest.mark.parametrize("card", ["none", "version1", "card", "protected"])
def test_the_image_identifies_the_card_at_start_up(tmp_path, card):
    boot.require_image()
    pytest.importorskip("heliquad._firmware")
    image = tmp_path / "sd.img"
    if card != "none":
        image.write_bytes(bytes(8192 * BLOCK))
    board = Teensy35(boot.IMAGE, sd_image=image)
    if card == "protected":
        board.sd_card.write_protect = True
    elif card == "version1":
        board.sd_card.version1 = True
    stop = board.run_to_loop(1, instructions=boot.BOOT_BUDGET)
    assert stop.reason == "loop", stop
    blocks, finding, wp, status = _probe(board)
    if card in REFUSED:
        assert (blocks, finding, status) == REFUSED[card]
        return
    assert (blocks, finding, wp, status) == (8192, 5, int(card == "protected"), 0)
    assert board.sd_card.state == "tran" and not board.chip.notes, board.chip.notes


CARD_OBJECT = "_ZZ14hq_teensy_mainE4card"           # main.cpp's static SdhcCard
CALL_BUDGET = 2_000_000


class Driver:
    """The image's SdhcCard, called directly on the emulated board after its start-up (the
    file layer does not call it yet): each call enters the method with its arguments in
    r0-r3 and returns to a BKPT; between polls the board's time moves on as if the caller
    slept. Scratch memory (the return BKPT, the buffers) is above the static data."""

    def __init__(self, board):
        self.board, self.m = board, board.machine
        image = self.m.image
        self.this = image.symbol(CARD_OBJECT).address
        self.methods = {name: image.symbol(f"hq::teensy::SdhcCard::{name}").address
                        for name in ("begin_read", "begin_write", "poll")}
        self.ret = (image.ram_end() + 63) & ~31
        self.buffer = self.ret + 32

    def _call(self, method, *args):
        m = self.m
        stop = boot.call_in_image(m, self.ret, self.methods[method], (self.this,) + args,
                                  CALL_BUDGET)
        assert stop.reason == "bkpt" and stop.pc == self.ret, stop
        return m.reg("r0") & 0xFF

    def poll(self, limit_s=2.0, step_s=2e-4):
        for _ in range(int(limit_s / step_s)):
            status = self._call("poll")
            if status != BUSY:
                return status
            self.m.advance(self.m.cycles_after(step_s) - self.m.now())
        return BUSY

    def write(self, lba, data, offset=0):
        self.m.write(self.buffer + offset, data)
        return self._call("begin_write", lba, self.buffer + offset, len(data) // BLOCK)

    def read(self, lba, n, offset=0):
        self.m.write(self.buffer + offset, b"\xEE" * n * BLOCK)
        status = self._call("begin_read", lba, self.buffer + offset, n)
        if status != OK:
            return status, None
        status = self.poll()
        return status, self.m.read(self.buffer + offset, n * BLOCK)


@pytest.fixture
def driver(tmp_path):
    boot.require_image()
    pytest.importorskip("heliquad._firmware")
    image = tmp_path / "sd.img"
    image.write_bytes(bytes(2048 * BLOCK))
    board = Teensy35(boot.IMAGE, sd_image=image)
    stop = board.run_to_loop(1, instructions=boot.BOOT_BUDGET)
    assert stop.reason == "loop", stop
    assert _probe(board)[1] == 5, "the card is ready"
    driver = Driver(board)
    driver.path = image
    return driver


def test_the_image_driver_writes_and_reads_blocks_through_adma2(driver):
    data = bytes((7 * i) & 0xFF for i in range(300 * BLOCK))
    assert driver.write(1000, data) == OK                   # two chunks: 256 + 44 blocks
    assert driver.write(0, data[:BLOCK]) == BUSY            # the transfer is not finished
    assert driver.poll() == OK
    assert driver.path.read_bytes()[1000 * BLOCK:1300 * BLOCK] == data
    assert driver.read(1100, 3) == (OK, data[100 * BLOCK:103 * BLOCK])
    assert driver.read(1000, 1) == (OK, data[:BLOCK])
    # An unaligned buffer goes one block at a time through the bounce buffer.
    assert driver.write(5, data[:2 * BLOCK], offset=1) == OK and driver.poll() == OK
    assert driver.path.read_bytes()[5 * BLOCK:7 * BLOCK] == data[:2 * BLOCK]
    assert driver.read(5, 2, offset=3) == (OK, data[:2 * BLOCK])
    assert driver.write(2047, data[:2 * BLOCK]) == OUT_OF_RANGE_STATUS
    assert driver.board.sd_card.state == "tran" and not driver.board.chip.notes


def test_the_image_driver_fails_once_and_recovers(driver):
    card = driver.board.sd_card
    card.fail_writes = "crc"
    assert driver.write(20, b"\x55" * BLOCK) == OK
    assert driver.poll() == FAILED
    assert card.state == "rcv" and driver.poll() == OK      # failed once, then idle
    card.fail_writes = None
    assert driver.write(20, b"\x55" * BLOCK) == BUSY        # the stop (CMD12) goes first
    assert driver.poll() == OK                              # nothing of the caller's runs
    driver.m.advance(driver.m.cycles_after(1e-4) - driver.m.now())
    assert card.state in ("prg", "tran") and card.log[-1][:2] == (12, 0)
    status = BUSY
    for _ in range(50):
        status = driver.write(20, b"\x55" * BLOCK)
        if status != BUSY:
            break
        driver.m.advance(driver.m.cycles_after(2e-4) - driver.m.now())
    assert status == OK and driver.poll() == OK
    assert driver.path.read_bytes()[20 * BLOCK:21 * BLOCK] == b"\x55" * BLOCK
    driver.board.chip.sdhc.corrupt_data_crc = 1
    assert driver.read(20, 1)[0] == FAILED
    for _ in range(50):
        status, data = driver.read(20, 1)
        if status != BUSY:
            break
    assert (status, data) == (OK, b"\x55" * BLOCK)
