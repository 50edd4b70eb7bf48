"""SDHC, the MK64's SD host controller (the reference manual's "Secured Digital Host Controller"
chapter), with the card in the Teensy 3.5's microSD socket (``sd_card.py``) on PTE0-PTE5.

A Python model (the card is not on the loop's hot path: a few commands and blocks a loop at
most). Registers: CMDARG, BLKATTR, DSADDR, ADSADDR, PROCTL, WML, IRQSTATEN, IRQSIGEN, VENDOR,
MMCBOOT store what is written; CMDRSP0-3, PRSSTAT, HTCAPBLT, HOSTVER, ADMAES are read only;
IRQSTAT is write 1 to clear (a flag is set only where IRQSTATEN enables it); SYSCTL's RSTA
resets the controller (its registers; the card keeps its state), RSTC the command circuit,
RSTD the data circuit, INITA (80 clocks) clears at once, all read 0. The IRQ line (81) is
IRQSTAT & IRQSIGEN.

A write to XFERTYP sends the command: CIHB (and CDIHB for a data or busy command) until the
response, which takes the command's and response's bits at the SD clock (SYSCTL: the system
clock (SIM_SOPT2.SDHCSRC 0) / (SDCLKFS prescaler x (DVS + 1)), SDCLKEN set). No card, the
clock off or PTE0-PTE5 not on ALT4: no response, CTOE. The response goes to CMDRSP0 (48-bit)
or CMDRSP0-3 (R2: bits 127:8); CC is set. The controller checks the response's CRC7
(XFERTYP.CCCEN) and index (CICEN): ``corrupt_command_crc`` makes the next n responses fail
it (CCE). Data (DPSEL): blocks of BLKATTR.BLKSIZE (512), BLKCNT of them with MSBSEL and
BCEN, each taking its bits on 1 or 4 lines (PROCTL.DTW) plus CRC16; only ADMA2 (PROCTL.DMAS 2,
DMAEN) is modelled: descriptors at ADSADDR (8 bytes: valid, end, act "tran" or "link" in the
low half, length in the high half (0 is 65536), then the address) walked in the emulated SRAM
as bus master 5, which the system MPU must grant (``mpu.py``); a descriptor not valid or a
table shorter than the transfer is DMAE with ADMAES. A read block's CRC16 is checked
(``corrupt_data_crc``: DCE); a written block is acknowledged by the card's CRC status
(negative: DCE). After a write the card holds DAT0 low (PRSSTAT.DLSL bit 0) while it
programs; TC is set when the last block is in and, for a write, the busy after it (with
AC12EN the auto-CMD12, its response in CMDRSP3) is over. ``log`` keeps each command
(cycle, index, argument, response kind or None), until cleared; ``transfer()`` says which data
transfer is under way and how far it got.

The model notes (``chip.note``) a command while CIHB is set, an identification clock over
400 kHz, a clock over 25 MHz, a block size other than 512 and a non-ADMA2 data transfer.
"""

from __future__ import annotations

from .mpu import SDHC_MASTER
from .peripheral import RegisterDevice
from .registers import irq
from .sd_card import BLOCK

CARD_PORT, CARD_PINS, CARD_MUX = "E", range(6), 4       # PTE0-5, ALT4
IDENT_MAX_HZ = 400e3            # SD specification: identification at 400 kHz at most
DEFAULT_SPEED_MAX_HZ = 25e6     # default speed
NCR_BITS = 8                    # clocks from a command to its response (stated model figure)
CRC16_BITS = 16 + 2             # CRC16 and the end bit, start bit
CRC_STATUS_BITS = 8             # the card's CRC status token after a written block
ADMA_VALID, ADMA_END = 1, 2
ADMA_ACT_TRAN, ADMA_ACT_LINK = 2, 3
IDENT_STATES = ("idle", "ready", "ident")

# Register bits used here (the SVD's field names)
XFERTYP_DMAEN, XFERTYP_BCEN, XFERTYP_AC12EN = 1 << 0, 1 << 1, 1 << 2
XFERTYP_DTDSEL, XFERTYP_MSBSEL, XFERTYP_CCCEN = 1 << 4, 1 << 5, 1 << 19
XFERTYP_DPSEL = 1 << 21
SYSCTL_SDCLKEN, SYSCTL_RSTA, SYSCTL_RSTC = 1 << 3, 1 << 24, 1 << 25
SYSCTL_RSTD, SYSCTL_INITA = 1 << 26, 1 << 27
IRQ_BITS = {"CC": 0, "TC": 1, "CTOE": 16, "CCE": 17, "DTOE": 20, "DCE": 21, "AC12E": 24,
            "DMAE": 28}
ADMAES_LENGTH_MISMATCH, ADMAES_DESCRIPTOR_ERROR = 1 << 2, 1 << 3


class Sdhc(RegisterDevice):
    READ_ONLY = ("CMDRSP0", "CMDRSP1", "CMDRSP2", "CMDRSP3", "PRSSTAT", "HTCAPBLT", "HOSTVER",
                 "ADMAES", "AC12ERR")

    def __init__(self, machine, chip):
        self.chip = chip
        self.card = None
        self.irq = irq("SDHC")
        self.corrupt_command_crc = 0    # the next n responses fail the CRC7 check
        self.corrupt_data_crc = 0       # the next n blocks fail the CRC16 check
        super().__init__(machine, "SDHC", gate=(chip.sim, "SCGC3", "SDHC"))

    def insert(self, card):
        """Puts ``card`` (an SdCard, or None: an empty socket) in the socket."""
        self.card = card

    def reset(self):
        super().reset()
        self._cmd = None                # the pending response's event
        self._data = None               # the transfer under way (a dict) or None
        self._event = None              # the next data event
        self._busy_until = 0            # cycle at which the card releases DAT0
        self._busy_event = None
        self.log = []
        if getattr(self, "card", None) is not None:
            self.card.power_on()

    # -- registers ---------------------------------------------------------------------------
    def r_PRSSTAT(self):
        busy = self.machine.now() < self._busy_until
        data = self._data is not None
        v = 1 << 3                                      # SDSTB: the clock is stable
        v |= (self._cmd is not None) << 0               # CIHB
        v |= (data or busy) << 1 | (data or busy) << 2  # CDIHB, DLA
        if data:
            v |= 1 << (8 if self._data["write"] else 9)     # WTA / RTA
        v |= (self.card is not None) << 16              # CINS
        v |= 1 << 23                                    # CLSL: CMD high
        v |= (0xFE | (not busy)) << 24                  # DLSL: DAT0 low while busy
        return v

    def w_IRQSTAT(self, value, mask):
        self.v["IRQSTAT"] &= ~(value & mask)
        self._update_irq()

    def w_IRQSIGEN(self, value, mask):
        self.v["IRQSIGEN"] = value
        self._update_irq()

    def w_SYSCTL(self, value, mask):
        if value & SYSCTL_RSTA:
            card = self.card
            self._cancel_all()
            RegisterDevice.reset(self)
            self.log = []
            self.card = card
            self._update_irq()
            return
        if value & SYSCTL_RSTC and self._cmd is not None:
            self._cmd.cancel()
            self._cmd = None
        if value & SYSCTL_RSTD:
            self._end_data()
        self.v["SYSCTL"] = value & ~(SYSCTL_RSTA | SYSCTL_RSTC | SYSCTL_RSTD | SYSCTL_INITA)

    def w_XFERTYP(self, value, mask):
        self.v["XFERTYP"] = value
        if self._cmd is not None:
            self.chip.note("SDHC: XFERTYP written while CIHB is set (command ignored)")
            return
        hz = self.sd_hz()
        rsptyp = value >> 16 & 3
        bits = 48 + NCR_BITS + {0: 0, 1: 136, 2: 48, 3: 48}[rsptyp]
        index, arg = value >> 24 & 0x3F, self.v["CMDARG"]
        self._cmd = self.machine.after(bits / hz if hz else 1e-6,
                                       lambda: self._response(index, arg, value, hz))

    # -- the SD clock ----------------------------------------------------------------------
    def sd_hz(self) -> float:
        """The SD clock (0: off): SYSCTL's prescaler and divisor of the SDHC's clock."""
        sysctl = self.v["SYSCTL"]
        if not sysctl & SYSCTL_SDCLKEN:
            return 0.0
        source = self.chip.sim.field("SOPT2", "SDHCSRC")
        base = {0: self.chip.core_hz(), 2: self.chip.tree().oscer}.get(source)
        if not base:
            self.chip.note(f"SDHC: SIM_SOPT2.SDHCSRC {source}: no clock modelled")
            return 0.0
        fs = sysctl >> 8 & 0xFF
        if fs & (fs - 1):
            self.chip.note(f"SDHC: SDCLKFS 0x{fs:02X} is not a power of two")
        return base / ((2 * fs if fs else 1) * ((sysctl >> 4 & 0xF) + 1))

    def _connected(self) -> bool:
        ports = self.chip.ports
        return self.card is not None and all(
            ports.mux(CARD_PORT, n) == CARD_MUX for n in CARD_PINS)

    # -- commands ----------------------------------------------------------------------------
    def _response(self, index, arg, xfertyp, hz):
        self._cmd = None
        card = self.card
        answer = None
        if hz and self._connected():
            if card.state in IDENT_STATES and hz > IDENT_MAX_HZ:
                self.chip.note(f"SDHC: CMD{index} at {hz / 1e3:.0f} kHz during identification "
                               f"(400 kHz at most)")
            if hz > DEFAULT_SPEED_MAX_HZ:
                self.chip.note(f"SDHC: SD clock {hz / 1e6:.1f} MHz over 25 MHz")
            answer = card.command(index, arg)
        self.log.append((self.machine.now(), index, arg, answer[0] if answer else None))
        rsptyp = xfertyp >> 16 & 3
        if rsptyp == 0:
            self._flag("CC")
            return
        if answer is None:
            self._flag("CTOE")
            return
        kind, word = answer
        if kind == "R2":
            for i in range(4):
                self.v[f"CMDRSP{i}"] = word >> (8 + 32 * i) & 0xFFFF_FFFF
        else:
            self.v["CMDRSP0"] = word
        if self.corrupt_command_crc and xfertyp & XFERTYP_CCCEN:
            self.corrupt_command_crc -= 1
            self._flag("CC", "CCE")
            return
        self._flag("CC")
        if xfertyp & XFERTYP_DPSEL:
            self._start_data(kind == "data", xfertyp, arg)
        elif rsptyp == 3:                       # R1b: the card's busy (a stop after a write)
            self._hold_busy(card.busy_s(self.machine.seconds()) if card.state == "prg" else 0,
                            tc=True)

    def _hold_busy(self, seconds, tc):
        m = self.machine
        self._busy_until = m.cycles_after(seconds)
        if self._busy_event is not None:
            self._busy_event.cancel()

        def done():
            self._busy_event = None
            if self.card is not None:
                self.card.transfer_done()
            if tc:
                self._flag("TC")
        self._busy_event = m.after(seconds, done)

    # -- data ------------------------------------------------------------------------------
    def _start_data(self, accepted, xfertyp, arg):
        write = not xfertyp & XFERTYP_DTDSEL
        blocks = self.v["BLKATTR"] >> 16 if xfertyp & XFERTYP_MSBSEL and \
            xfertyp & XFERTYP_BCEN else 1
        size = self.v["BLKATTR"] & 0x1FFF
        if size != BLOCK:
            self.chip.note(f"SDHC: block size {size} (the card's is {BLOCK})")
        if not accepted:                        # the card answered with an error: no data
            self._flag("DCE" if write else "DTOE")
            return
        if not xfertyp & XFERTYP_DMAEN or (self.v["PROCTL"] >> 8 & 3) != 2:
            self.chip.note("SDHC: a data transfer without ADMA2 (only ADMA2 is modelled)")
            self._flag("DMAE")
            return
        segments = self._adma_table(blocks * BLOCK)
        if segments is None:
            return
        self._data = {"write": write, "lba": arg, "blocks": blocks, "left": blocks,
                      "segments": segments,
                      "ac12": bool(xfertyp & XFERTYP_AC12EN) and blocks > 1}
        self._event = self.machine.after(self._block_s(write), self._block)

    def transfer(self) -> tuple | None:
        """The data transfer under way: (write, blocks done, blocks left), or None."""
        d = self._data
        return None if d is None else (d["write"], d["blocks"] - d["left"], d["left"])

    def _block_s(self, write) -> float:
        lines = 4 if self.v["PROCTL"] >> 1 & 3 == 1 else 1
        bits = BLOCK * 8 // lines + CRC16_BITS + (CRC_STATUS_BITS if write else NCR_BITS)
        hz = self.sd_hz()
        return bits / hz if hz else 1e-6

    def _adma_table(self, need):
        """The ADMA2 table's (address, length) pieces for ``need`` bytes, or None after an
        error (DMAE, ADMAES)."""
        segments, at, total = [], self.v["ADSADDR"] & ~3, 0
        for _ in range(1024):                   # a table that loops forever is an error too
            word = int.from_bytes(self._dma_read(at, 8, "an ADMA2 descriptor"), "little")
            attr, length, address = word & 0xFFFF, word >> 16 & 0xFFFF, word >> 32
            if not attr & ADMA_VALID:
                return self._adma_error(ADMAES_DESCRIPTOR_ERROR)
            act = attr >> 4 & 3
            if act == ADMA_ACT_LINK:
                at = address & ~3
                continue
            if act == ADMA_ACT_TRAN:
                length = length or 0x10000
                segments.append((address, length))
                total += length
            if attr & ADMA_END or total >= need:
                break
            at += 8
        if total < need:
            return self._adma_error(ADMAES_LENGTH_MISMATCH)
        return segments

    def _adma_error(self, why):
        self.v["ADMAES"] = why
        self._flag("DMAE")
        return None

    def _pieces(self, n):
        """The next ``n`` bytes' (address, length) pieces of the transfer's table."""
        out, segs = [], self._data["segments"]
        while n:
            address, length = segs[0]
            take = min(n, length)
            out.append((address, take))
            if take == length:
                segs.pop(0)
            else:
                segs[0] = (address + take, length - take)
            n -= take
        return out

    def _block(self):
        self._event = None
        d, card = self._data, self.card
        if d is None:
            return
        if d["write"]:
            data = b"".join(self._dma_read(a, n, "write data") for a, n in self._pieces(BLOCK))
            if self.corrupt_data_crc:           # the card sees a bad CRC16: negative status
                self.corrupt_data_crc -= 1
                ok = False
            else:
                ok = card is not None and self._connected() and card.write_block(d["lba"], data)
            if not ok:
                return self._fail("DCE")
            wait = card.busy_s(self.machine.seconds())
        else:
            data = card.read_block(d["lba"]) if card is not None and self._connected() else None
            if data is None:
                return self._fail("DTOE")
            if self.corrupt_data_crc:
                self.corrupt_data_crc -= 1
                return self._fail("DCE")
            for address, n in self._pieces(BLOCK):
                self._dma_write(address, data[:n])
                data = data[n:]
            wait = 0.0
        d["lba"] += 1
        d["left"] -= 1
        if d["left"]:
            self._busy_until = self.machine.cycles_after(wait)
            self._event = self.machine.after(wait + self._block_s(d["write"]), self._block)
            return
        self._finish(d, wait)

    def _finish(self, d, wait):
        """The last block is in: the auto-CMD12 (its response in CMDRSP3), then TC once the
        card's busy is over."""
        self._data = None
        card = self.card
        if d["ac12"]:
            answer = card.command(12, 0)
            self.log.append((self.machine.now(), 12, 0, answer[0] if answer else None))
            if answer is None:
                self._flag("AC12E")
                return
            self.v["CMDRSP3"] = answer[1]
        elif card.state == "rcv":
            card.state = "prg"
        self._hold_busy(wait, tc=True)

    def _fail(self, flag):
        self._data = None
        self._flag(flag)

    def _end_data(self):
        """RSTD: the transfer is abandoned (the card keeps its state and its busy)."""
        if self._event is not None:
            self._event.cancel()
            self._event = None
        self._data = None

    def _cancel_all(self):
        for ev in (self._cmd, self._event, self._busy_event):
            if ev is not None:
                ev.cancel()
        self._cmd = self._event = self._busy_event = None
        self._data = None

    # -- DMA ---------------------------------------------------------------------------------
    def _check(self, address, n, write, what):
        self.chip.mpu.check_dma("SDHC ADMA2", SDHC_MASTER, address, n, write, what)

    def _dma_read(self, address, n, what) -> bytes:
        self._check(address, n, False, what)
        return self.machine.read(address, n)

    def _dma_write(self, address, data):
        self._check(address, len(data), True, "read data")
        self.machine.write(address, data)

    # -- flags -------------------------------------------------------------------------------
    def _flag(self, *names):
        for name in names:
            self.v["IRQSTAT"] |= (1 << IRQ_BITS[name]) & self.v["IRQSTATEN"]
        self._update_irq()

    def _update_irq(self):
        self.machine.set_irq(self.irq, bool(self.v["IRQSTAT"] & self.v["IRQSIGEN"]))
