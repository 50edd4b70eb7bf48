"""An SDHC memory card (block-addressed, version 2 CSD) backed by a card-image file: the card's
side of the SD bus, after the SD Physical Layer Simplified Specification.

:class:`SdCard` answers commands as a card does: its state (idle, ready, ident, stby, tran,
data, rcv, prg), the responses (R1 card status, R2 CID/CSD, R3 OCR, R6 RCA, R7 interface
condition) or silence (a command illegal in the state, or no card), the blocks read from and
written to the image file, and the busy time after a write. The controller side (CRC7 and
CRC16 checks, timing, DMA) is in ``sdhc.py``.

The card's size is the image's, rounded down to 512 KiB (C_SIZE counts 1024 blocks), so a
small image is a full card. A write reaches the file when the card acknowledges the block
(its CRC status), one ``os.pwrite`` each: a run stopped at any instruction leaves the image
with exactly what was acknowledged (a power cut).

Faults for tests (attributes, settable at any time): ``write_protect`` (CSD's
TMP_WRITE_PROTECT: writes refused with WP_VIOLATION), ``fail_writes`` ("crc": the card
answers every data block with a negative CRC status and stays in rcv; "status": CMD25/CMD24
are answered with the ERROR bit and no data is taken), ``busy_hold`` ((hold_s, period_s): the
first write in each period of emulated time holds busy hold_s longer), ``program_s`` (busy
per block written, 1 ms), ``busy_tries`` (ACMD41s answered busy before ready, 3; None: never
ready), ``version1`` (identification answered as a version 1 standard-capacity card: no
answer to CMD8, CCS clear; only its identification is modelled).
"""

from __future__ import annotations

import os

BLOCK = 512
BLOCKS_PER_C_SIZE = 1024                # version 2 CSD: capacity (C_SIZE + 1) x 512 KiB
STATES = ("idle", "ready", "ident", "stby", "tran", "data", "rcv", "prg")
# R1 card status bits (the specification's "Card Status").
OUT_OF_RANGE = 1 << 31
WP_VIOLATION = 1 << 26
ILLEGAL_COMMAND = 1 << 22
ERROR = 1 << 19
READY_FOR_DATA = 1 << 8
APP_CMD = 1 << 5
OCR_READY = 1 << 31
OCR_CCS = 1 << 30
OCR_VOLTAGES = 0x00FF8000               # 2.7-3.6 V
ACMD41_BUSY_TRIES = 3                   # ACMD41s answered busy before ready (initialisation)
CID = bytes.fromhex("1d4845534448435f01000000012a0100")[:15]    # "HE" "SDHC_" rev 1, serial 1
PROGRAM_S = 1e-3                        # busy per block written (a stated model parameter)


class SdCard:
    def __init__(self, path: str | os.PathLike):
        self.path = os.fspath(path)
        self._fd = os.open(self.path, os.O_RDWR)
        size = os.fstat(self._fd).st_size
        self.blocks = size // BLOCK // BLOCKS_PER_C_SIZE * BLOCKS_PER_C_SIZE
        if self.blocks == 0:
            os.close(self._fd)
            raise ValueError(f"{self.path}: a card image holds at least 512 KiB, not {size} bytes")
        self.write_protect = False
        self.fail_writes = None         # None, "crc" or "status"
        self.busy_hold = None           # (hold_s, period_s)
        self.program_s = PROGRAM_S
        self.busy_tries = ACMD41_BUSY_TRIES     # ACMD41s answered busy (None: never ready)
        self.version1 = False           # answer identification as a version 1 (SDSC) card
        self._next_hold_s = 0.0
        self.log = []                   # (command, argument, state before): until cleared
        self.power_on()

    def close(self):
        if self._fd is not None:
            os.close(self._fd)
            self._fd = None

    def power_on(self):
        self.state = "idle"
        self.rca = 0
        self._app = False
        self._illegal = False           # ILLEGAL_COMMAND, reported with the next response
        self._acmd41_tries = 0
        self._next_hold_s = 0.0

    # -- registers ---------------------------------------------------------------------------
    def csd(self) -> int:
        """The 128-bit version 2 CSD (bit 127 first), CRC7 field 0 (the controller drops it)."""
        c_size = self.blocks // BLOCKS_PER_C_SIZE - 1
        csd = 1 << 126                              # CSD_STRUCTURE 1
        csd |= 0x0E << 112 | 0x32 << 96             # TAAC 1 ms, TRAN_SPEED 25 MHz
        csd |= 0x5B5 << 84 | 9 << 80                # CCC, READ_BL_LEN 9
        csd |= c_size << 48                         # C_SIZE 69:48
        csd |= 1 << 46 | 0x7F << 39 | 2 << 26 | 9 << 22   # ERASE_BLK_EN, SECTOR, R2W, WRITE_BL_LEN
        if self.write_protect:
            csd |= 1 << 12                          # TMP_WRITE_PROTECT
        return csd | 1                              # bit 0 always 1

    def status(self) -> int:
        """R1: the card status (state in 12:9), ILLEGAL_COMMAND of the command before."""
        s = STATES.index(self.state) << 9 | READY_FOR_DATA
        if self._illegal:
            s |= ILLEGAL_COMMAND
        if self._app:
            s |= APP_CMD
        return s

    # -- commands ----------------------------------------------------------------------------
    def command(self, index: int, arg: int):
        """The card's answer to CMD``index`` (an ACMD after CMD55): ("R1", status),
        ("R2", 128-bit), ("R3", ocr), ("R6", word), ("R7", word), ("data", status) for a
        command that starts a transfer, or None (no response)."""
        self.log.append((index, arg, self.state))
        app, self._app = self._app, False
        handler = getattr(self, f"_acmd{index}" if app else f"_cmd{index}", None)
        answer = handler(arg) if handler else None
        if answer is None and index != 0:
            self._illegal = True
        return answer

    def _r1(self, kind="R1", extra=0):
        status = self.status() | extra
        self._illegal = False
        return kind, status

    def _cmd0(self, arg):
        self.power_on()
        return None

    def _cmd8(self, arg):
        if self.state != "idle" or self.version1:          # version 1: CMD8 is illegal
            return None
        return "R7", arg & 0xFFF                    # voltage accepted, pattern echoed

    def _cmd55(self, arg):
        if self.state not in ("idle", "tran", "stby") or \
                (self.state != "idle" and arg >> 16 != self.rca):
            return None
        self._app = True
        return self._r1()

    def _acmd41(self, arg):
        if self.state not in ("idle", "ready"):
            return None
        self._acmd41_tries += 1
        if self.busy_tries is None or self._acmd41_tries <= self.busy_tries or \
                not arg & OCR_VOLTAGES:
            return "R3", OCR_VOLTAGES
        self.state = "ready"
        return "R3", OCR_READY | (0 if self.version1 else OCR_CCS) | OCR_VOLTAGES

    def _cmd2(self, arg):
        if self.state != "ready":
            return None
        self.state = "ident"
        return "R2", int.from_bytes(CID, "big") << 8 | 1

    def _cmd3(self, arg):
        if self.state not in ("ident", "stby"):
            return None
        self.state, self.rca = "stby", 0x4853                # "HS"
        status = self.status()
        # R6 carries status bits 23, 22, 19 and 12:0 in its low 16 bits.
        return "R6", self.rca << 16 | (status >> 8 & 0xC000) | (status >> 6 & 0x2000) | \
            (status & 0x1FFF)

    def _cmd9(self, arg):
        if self.state != "stby" or arg >> 16 != self.rca:
            return None
        return "R2", self.csd()

    def _cmd7(self, arg):
        if self.state not in ("stby", "tran") or arg >> 16 not in (self.rca, 0):
            return None
        answer = self._r1()
        self.state = "tran" if arg >> 16 == self.rca else "stby"
        return answer

    def _acmd6(self, arg):
        return self._r1() if self.state == "tran" and arg & 3 in (0, 2) else None

    def _cmd16(self, arg):
        return self._r1() if self.state == "tran" and arg == BLOCK else None

    def _cmd13(self, arg):
        return self._r1() if self.state in ("stby", "tran", "data", "rcv", "prg") else None

    def _cmd12(self, arg):
        if self.state not in ("data", "rcv"):
            return None
        answer = self._r1()
        self.state = "prg" if self.state == "rcv" else "tran"
        return answer

    def _transfer(self, arg, state, write):
        if self.state != "tran":
            return None
        if arg >= self.blocks:
            return self._r1(extra=OUT_OF_RANGE)
        if write and self.write_protect:
            return self._r1(extra=WP_VIOLATION)
        if write and self.fail_writes == "status":
            return self._r1(extra=ERROR)
        answer = self._r1("data")
        self.state = state
        return answer

    def _cmd17(self, arg):
        return self._transfer(arg, "data", False)

    _cmd18 = _cmd17

    def _cmd24(self, arg):
        return self._transfer(arg, "rcv", True)

    _cmd25 = _cmd24

    # -- data ----------------------------------------------------------------------------
    def read_block(self, lba: int) -> bytes | None:
        """Block ``lba`` (None past the end: the card stops sending)."""
        if lba >= self.blocks:
            return None
        return os.pread(self._fd, BLOCK, lba * BLOCK).ljust(BLOCK, b"\0")

    def write_block(self, lba: int, data: bytes) -> bool:
        """One data block received: True (CRC status positive, written) or False (negative,
        nothing written)."""
        if self.state != "rcv" or self.fail_writes == "crc" or lba >= self.blocks:
            return False
        os.pwrite(self._fd, data, lba * BLOCK)
        return True

    def busy_s(self, now_s: float) -> float:
        """How long the card holds DAT0 low after a block written at ``now_s``."""
        busy = self.program_s
        if self.busy_hold is not None:
            hold_s, period_s = self.busy_hold
            if now_s >= self._next_hold_s:
                busy += hold_s
                self._next_hold_s = (now_s // period_s + 1) * period_s
        return busy

    def transfer_done(self):
        """The end of a transfer (auto-CMD12 done, or the programming after it)."""
        if self.state in ("data", "prg"):
            self.state = "tran"
