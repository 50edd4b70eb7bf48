"""The system memory protection unit (MPU at 0x4000_D000, the reference manual's "Memory
Protection Unit" chapter), modelled as far as the bus masters other than the core need it.

The core's own accesses are not checked (the image runs privileged with the MPU's reset
regions, which grant the core everything). What is modelled is the one rule that stops a DMA
master: the USB controller is bus master 4 and the SDHC master 5, and the reset value of
every region descriptor's access word (RGDn_WORD2 = 0x0061_F7DF) gives masters 4 and 5
neither read nor write. So while CESR.VLD is set (its reset value), such a master may reach an
address only through a valid region (RGD0 always, RGDn with WORD3.VLD) covering it whose WORD2
sets MnRE (reads) or MnWE (writes); an image must either grant the master (RGDAAC0, the alias
of RGD0_WORD2) or clear CESR.VLD before that controller touches memory, or the emulator stops
with a fault. :meth:`SysMpu.check_dma` is that check (with the memory map's: DMA reaches RAM,
and flash for reads), for every DMA model.

Registers: CESR (VLD writable, SPERR write-1-to-clear, the rest read only), the region
descriptors RGD0-11 (WORD0-3; RGD0's start and end are fixed at 0 and 0xFFFF_FFFF as on the
chip) and their access-control aliases RGDAAC0-11. The error registers (EARn/EDRn) read 0: no
access violation is recorded in them (a refused access stops the run instead).
"""

from __future__ import annotations

from .image import FLASH_BASE, FLASH_SIZE, SRAM_BASE, SRAM_SIZE
from .machine import Fault
from .peripheral import RegisterDevice

REGIONS = 12                    # MK64: 12 region descriptors (CESR.NRGD = 0b0001)
REGION_GRANULE = 32             # start/end addresses are in 32-byte units (WORD0/1 bits 31:5)
USB_MASTER = 4                  # the USB controller's crossbar master number (chip config.)
SDHC_MASTER = 5                 # the SDHC's


class SysMpu(RegisterDevice):
    READ_ONLY = ("RGD0_WORD0", "RGD0_WORD1") + tuple(f"EAR{i}" for i in range(5)) + \
        tuple(f"EDR{i}" for i in range(5))

    def __init__(self, machine, chip):
        self.chip = chip
        super().__init__(machine, "MPU", gate=(chip.sim, "SCGC7", "MPU"))
        # The masks master_may tests, looked up once (it runs at every USB DMA access).
        self._vld = self.map["CESR"].bit("VLD")
        self._region_vld = self.map["RGD0_WORD3"].bit("VLD")
        self._words = [tuple(f"RGD{n}_WORD{w}" for w in range(4)) for n in range(REGIONS)]

    def w_CESR(self, value, mask):
        sperr = self.map["CESR"].field("SPERR").mask
        keep = self.v["CESR"] & ~self.map["CESR"].bit("VLD") & ~(value & sperr)
        self.v["CESR"] = keep | (value & self.map["CESR"].bit("VLD"))

    def write(self, address, size, value):
        super().write(address, size, value)
        for n in range(REGIONS):                    # RGDAACn is RGDn_WORD2 seen twice
            alias, word = f"RGDAAC{n}", f"RGD{n}_WORD2"
            offset = address - self.base
            if self.map[alias].offset <= offset < self.map[alias].offset + 4:
                self.v[word] = self.v[alias]
            elif self.map[word].offset <= offset < self.map[word].offset + 4:
                self.v[alias] = self.v[word]
        self.chip.usb0.mpu_changed()

    def enabled(self) -> bool:
        return bool(self.v["CESR"] & self.map["CESR"].bit("VLD"))

    def master_may(self, master: int, address: int, size: int, write: bool) -> bool:
        """Whether bus master ``master`` may read (or write) ``size`` bytes at ``address``:
        always while the MPU is off; else some valid region covering all of them grants it
        (read: MnRE, write: MnWE, for masters 4-7)."""
        v = self.v
        if not v["CESR"] & self._vld:
            return True
        right = self.map["RGD0_WORD2"].bit(f"M{master}{'WE' if write else 'RE'}")
        last = address + max(size, 1) - 1
        for n, (word0, word1, word2, word3) in enumerate(self._words):
            if n and not v[word3] & self._region_vld:
                continue
            start = v[word0] & ~(REGION_GRANULE - 1)
            end = v[word1] | (REGION_GRANULE - 1)
            if start <= address and last <= end and v[word2] & right:
                return True
        return False

    def check_dma(self, device: str, master: int, address: int, n: int, write: bool,
                  what: str, flash_reads: bool = False):
        """A DMA access of ``device`` (bus master ``master``): ``n`` bytes at ``address`` must
        lie in RAM (or flash, for reads where ``flash_reads``) and the MPU must grant it;
        otherwise the run stops with a Fault naming the address and the rule."""
        m = self.machine
        in_ram = SRAM_BASE <= address and address + n <= SRAM_BASE + SRAM_SIZE
        in_flash = FLASH_BASE <= address and address + n <= FLASH_BASE + FLASH_SIZE
        kind = "write" if write else "read"
        if not (in_ram or (in_flash and flash_reads and not write)):
            where = "RAM or flash" if flash_reads and not write else "RAM"
            raise Fault("BusFault", f"{device} DMA {kind} of {what} at 0x{address:08X} "
                        f"({n} bytes): not {where}", m.pc, address)
        if not self.master_may(master, address, n, write):
            raise Fault("BusFault", f"{device} DMA {kind} of {what} at 0x{address:08X}: the "
                        f"system MPU grants bus master {master} no {kind} access (set "
                        f"MPU_RGDAAC0.M{master}RE/M{master}WE or clear MPU_CESR.VLD)",
                        m.pc, address)
