"""The flash memory module (FTFE) and the program flash it erases and programs, after the K64
reference manual's "Flash Memory Module (FTFE)" chapter, and the flash memory controller's
cache control (FMC).

* Registers: FSTAT (CCIF, RDCOLERR, ACCERR, FPVIOL, MGSTAT0), FCNFG, FSEC and FOPT (read
  only), FCCOB0-FCCOBB (the command and its parameters), FPROT0-3, FEPROT, FDPROT. At reset
  FPROT3..0, FSEC, FOPT, FEPROT and FDPROT load from the flash configuration field
  (0x408-0x40F) and CCIF reads 1. Protection can only be added (FPROT bits 1 -> 0).
* Launch: writing 1 to CCIF while it reads 1. ACCERR, FPVIOL and RDCOLERR are write-1-to-
  clear; a launch while ACCERR or FPVIOL is still set is not launched (noted). FCCOB writes
  while a command runs are ignored (noted).
* Commands: Erase Flash Sector (0x09: FCCOB1-3 an address in the 4 KiB sector, 16-byte
  aligned) and Program Phrase (0x07: FCCOB1-3 an 8-byte aligned address, FCCOB4-B the eight
  bytes, byte k at address + k in FCCOB 7, 6, 5, 4, B, A, 9, 8). Any other command, an
  address outside the 512 KiB of program flash or a misaligned one: ACCERR at launch (the
  command does not run); a target in a protected region: FPVIOL.
* Duration: CCIF reads 0 for the command's time (:data:`ERASE_SECTOR_S`,
  :data:`PROGRAM_PHRASE_S`: the data sheet's typical figures; :attr:`Ftfe.times` sets
  others, such as the maxima in :data:`MAX_TIMES`). The flash's bytes change when the command
  completes: an erase sets the sector to 0xFF; a program can only clear bits (the cells keep
  old AND new), and a phrase that does not then read as asked fails the module's verify
  (MGSTAT0). Programming a phrase that is not erased breaks the manual's rule of one program
  per erase: noted.
* Read collision: an instruction fetched from program flash while a command runs stops the
  run with ``Fault("ReadCollision", ...)`` and sets RDCOLERR (on the chip the fetch reads
  undefined bits: the MK64FX512's program flash is one block, so the code that launches a
  command and waits for it must run from RAM, with interrupts masked, since every vector and
  handler is in flash). Data reads from flash during a command are not checked.
* A reset abandons a running command: the cells keep what they held (on the chip they are
  undefined; a test that wants a torn sector writes one). The flash's bytes survive a reset,
  as on the chip; only :meth:`Machine.load` (flashing an image) rewrites them.
* The program can never write flash with a store: flash is mapped read/execute, and a store
  there is a bus fault (``Fault("BusFault", "write to flash ...")``).
* Not modelled: the other commands (Read 1s, Program Check, Read Resource, Program Section,
  the FlexNVM and EEPROM commands, Erase All Blocks), the command-complete and read-collision
  interrupts and erase suspend (FCNFG writes that set them are noted), security, margin
  levels, the FlexNVM block (0x1000_0000) and its FlexRAM.

The model is native (``heliquad._simcore.Mk64Core``, sim/chip/mk64_devices.cpp): a command's
wait polls FSTAT hundreds of thousands of times a save. This class is its view.

The FMC (:class:`Fmc`, Python) keeps its registers; writes that invalidate the cache ways or
the prefetch speculation buffer (PFB0CR.CINV_WAY, S_B_INV; they read back 0) are recorded in
``invalidations``. The cache itself is not modelled (the emulated flash never reads stale),
so ``invalidations`` is what tells whether code that changed the flash would read the new
bytes on the chip.
"""

from __future__ import annotations

from dataclasses import dataclass

from .image import FLASH_CONFIG, FLASH_SIZE
from .machine import FTFE_DEVICE
from .peripheral import NativeRegisters, RegisterDevice

SECTOR_BYTES = 4096
PHRASE_BYTES = 8
ERASE_FLASH_SECTOR, PROGRAM_PHRASE = 0x09, 0x07
#: K64 data sheet, flash command timing: Erase Flash Sector (tersscr) and Program Phrase
#: (tpgm8) execution times, typical.
ERASE_SECTOR_S = 15e-3
PROGRAM_PHRASE_S = 90e-6
#: The same figures' maxima.
MAX_TIMES = (115e-3, 150e-6)


@dataclass(frozen=True)
class Command:
    """One launched command: cycles at launch and at completion (equal when the launch check
    refused it), its code, address, and FSTAT when it ended."""
    start: int
    end: int
    code: int
    address: int
    fstat: int


class Ftfe(NativeRegisters):
    def __init__(self, machine, chip):
        self.chip = chip
        core = machine.core
        super().__init__(machine, "FTFE", FTFE_DEVICE, core.ftfe_reg,
                         gate=(chip.sim, "SCGC6", "FTF"), span=0x18)
        core.ftfe_setup(dict(self.layout(), flash_size=FLASH_SIZE, sector=SECTOR_BYTES,
                             config=FLASH_CONFIG, erase_sector_s=ERASE_SECTOR_S,
                             program_phrase_s=PROGRAM_PHRASE_S))
        self._log = []

    def reset(self):
        self._log = []                  # the core resets the model with the machine

    def _state(self) -> dict:
        return self.machine.core.ftfe_state()

    busy = property(lambda self: self._state()["busy"], doc="a command runs (CCIF reads 0)")
    changes = property(lambda self: self._state()["changes"],
                       doc="commands that changed the flash since the machine was made "
                           "(resets included)")

    @property
    def times(self) -> tuple:
        """(Erase Flash Sector, Program Phrase) durations in seconds, for the next commands."""
        return tuple(self.machine.core.ftfe_times())

    @times.setter
    def times(self, value: tuple):
        erase, program = value
        self.machine.core.ftfe_set_times(float(erase), float(program))

    @property
    def log(self) -> list:
        """Every command launched since reset (:class:`Command`), until cleared."""
        self._log.extend(Command(*e) for e in self.machine.core.ftfe_take_log())
        return self._log

    def take_notes(self) -> list:
        """(cycle, text) of documented misuse since the last call."""
        return self.machine.core.ftfe_take_notes()


class Fmc(RegisterDevice):
    """The flash memory controller's registers; cache and speculation-buffer invalidations
    recorded (cycle, CINV_WAY ways, S_B_INV) in ``invalidations``."""

    def __init__(self, machine, chip):
        self.chip = chip
        super().__init__(machine, "FMC")

    def reset(self):
        super().reset()
        self.invalidations = []

    def w_PFB0CR(self, value, mask):
        ways = self.map["PFB0CR"].field("CINV_WAY")
        buffer = self.bit("PFB0CR", "S_B_INV")
        if ways.get(value) or value & buffer:
            self.invalidations.append((self.machine.now(), ways.get(value), bool(value & buffer)))
        self.v["PFB0CR"] = value & ~(ways.mask | buffer)
