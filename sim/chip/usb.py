"""USB0, the full-speed USB controller in device mode, after the reference manual's "Universal
Serial Bus OTG Controller (USBOTG)" chapter: its registers, the buffer descriptor table (BDT)
in RAM, and the serial interface engine (SIE) answering the tokens of the host model
(``usb_host.py``). docs/teensy35-emulator.md lists what is and is not modelled.

* Registers: PERID/IDCOMP/REV/ADDINFO (read only), ISTAT and ERRSTAT (write 1 to clear),
  INTEN, ERREN, STAT (the last token done), CTL (USBENSOFEN, ODDRST, RESUME,
  TXSUSPENDTOKENBUSY, SE0/JSTATE read from the line), ADDR, BDTPAGE1-3, FRMNUML/H (read
  only), ENDPT0-15, USBCTRL, OBSERVE (read only: the pull-up and pull-downs), CONTROL
  (DPPULLUPNONOTG: the device attaches), USBTRC0 (USBRESET resets the module and reads 0
  at once; bit 6 stores what is written, as software must set it; USB_RESUME_INT), and
  the rest storing what is written. The SIM gate SCGC4.USBOTG; IRQ 53, level-sensitive:
  (ISTAT & INTEN) != 0, or USBTRC0.USB_RESUME_INT.
* BDT: at BDTPAGE3:2:1 (512-byte aligned), 8 bytes per descriptor at ENDP x 32 + TX x 16 +
  ODD x 8. The firmware writes OWN (bit 7), DATA0/1 (6), KEEP (5), NINC (4), DTS (3),
  BDT_STALL (2), BC (bits 25:16) and the buffer address; on completion the SIE writes back
  OWN = 0, the DATA bit, TOK_PID (bits 5:2) and BC.
* A token to this device (ADDR) on an endpoint enabled for its direction (EPRXEN for OUT and
  SETUP, EPTXEN for IN; SETUP only where EPCTLDIS is clear): NAK while the current BD (the
  endpoint's ODD pointer) is not owned by the SIE or CTL.TXSUSPENDTOKENBUSY is set (a SETUP
  is never NAKed: without a BD it gets no handshake), STALL when ENDPT.EPSTALL or the BD's
  BDT_STALL is set (ISTAT.STALL; the BD stays owned); a SETUP clears EPSTALL as the
  hardware does. With DTS, an OUT or SETUP whose DATA0/1 differs from the BD's is ACKed
  and dropped (no write-back, no TOKDNE), as the USB specification has a device do with a
  retransmission; an IN sends the BD's DATA PID. A completed token flips the ODD pointer,
  sets STAT (ENDP, TX, ODD) and ISTAT.TOKDNE (and after a SETUP, TXSUSPENDTOKENBUSY). One
  STAT at a time: the host model sends no token while TOKDNE is set (the chip has a
  four-entry STAT FIFO; the model never needs it).
* An OUT or SETUP packet longer than the BD's BC is not handshaken and sets ERRSTAT.DMAERR
  (ISTAT.ERROR where ERREN enables it).
* DMA: the SIE reads the BD and the IN data and writes the OUT data through the machine's
  memory as bus master 4, which the system MPU (``mpu.py``) must grant; an address outside
  RAM (flash too, for data it writes) or not granted stops the run with a ``Fault``.
* The SIE leaves ADDR and the ODD pointers alone at a bus reset: the reference manual has the
  firmware write ADDR = 0 and set CTL.ODDRST on USBRST, and the model holds it to that.
* It talks only while the module is enabled (CTL.USBENSOFEN), attached (the pull-up), not
  suspended (USBCTRL.SUSP) and clocked at 48 MHz (the SIM's USB clock within the 0.25 % a
  full-speed device must hold). SOF: ISTAT.SOFTOK and FRMNUM. SLEEP: 3 ms of idle bus while
  enabled. With USBCTRL.SUSP and USBTRC0.USBRESMEN, bus activity sets USB_RESUME_INT.

The registers, the ping-pong pointers, the frame number, the SOF and the idle timer live in the
native core (``heliquad._simcore``, sim/chip/mk64_usb.cpp), which also takes the byte accesses
the image's interrupt makes (all but CTL, CONTROL, USBCTRL and USBTRC0 writes) and answers
the host's bulk IN polls whose answer is plain: a NAK, or the BD's data from RAM
(``usb_host.py``); ``native = False`` leaves both to this class, the reference the native
path is compared with. ``writes`` lists the writes this class took.
"""

from __future__ import annotations

import dataclasses

from .image import SRAM_BASE, SRAM_SIZE
from .machine import USB0_DEVICE
from .mpu import USB_MASTER
from .peripheral import RegisterDevice
from .registers import irq, peripheral

USB_CLOCK_HZ = 48e6             # the USB module's clock (reference manual, USB clocking)
USB_CLOCK_TOLERANCE = 0.0025    # full-speed data rate +-0.25 % (USB 2.0, 7.1.11)
ENDPOINTS = 16
BD_BYTES = 8
PID_OUT, PID_IN, PID_SETUP = 0x1, 0x9, 0xD      # token PIDs (USB 2.0, table 8-1)
# BD bits (the reference manual's "Buffer Descriptor Table" figure)
BD_OWN, BD_DATA1, BD_KEEP, BD_NINC, BD_DTS, BD_STALL = 0x80, 0x40, 0x20, 0x10, 0x08, 0x04
BD_BC_SHIFT, BD_BC_MASK = 16, 0x3FF
USBTRC0_SOFTWARE_BIT = 0x40     # "software must set this bit" (its reset value is 0)
IDLE_TO_SLEEP_S = 3e-3          # ISTAT.SLEEP after 3 ms of idle bus (USB 2.0, 7.1.7.6)

ACK, NAK, STALL, NONE = "ACK", "NAK", "STALL", None     # a token's handshake (None: silence)


def _mask(reg: str, fld: str) -> int:
    return peripheral("USB0")[reg].bit(fld)


# The one-bit fields the model tests, as masks (looked up once: the SIE answers a token
# every frame).
CONTROL_DPPULLUPNONOTG = _mask("CONTROL", "DPPULLUPNONOTG")
CTL_HOSTMODEEN, CTL_JSTATE, CTL_ODDRST, CTL_SE0, CTL_TXSUSPENDTOKENBUSY, CTL_USBENSOFEN = (
    _mask("CTL", f) for f in ("HOSTMODEEN", "JSTATE", "ODDRST", "SE0", "TXSUSPENDTOKENBUSY",
                              "USBENSOFEN"))
ENDPT0_EPCTLDIS, ENDPT0_EPSTALL, ENDPT0_EPRXEN, ENDPT0_EPTXEN = (
    _mask("ENDPT0", f) for f in ("EPCTLDIS", "EPSTALL", "EPRXEN", "EPTXEN"))
ERREN_DMAERREN = _mask("ERREN", "DMAERREN")
ERRSTAT_DMAERR = _mask("ERRSTAT", "DMAERR")
ISTAT = {f: _mask("ISTAT", f) for f in peripheral("USB0")["ISTAT"].fields}
ISTAT_TOKDNE = ISTAT["TOKDNE"]
OBSERVE_DMPD, OBSERVE_DPPD, OBSERVE_DPPU = (_mask("OBSERVE", f) for f in ("DMPD", "DPPD", "DPPU"))
USBCTRL_PDE, USBCTRL_SUSP = _mask("USBCTRL", "PDE"), _mask("USBCTRL", "SUSP")
USBTRC0_USBRESET, USBTRC0_USBRESMEN, USBTRC0_USB_RESUME_INT = (
    _mask("USBTRC0", f) for f in ("USBRESET", "USBRESMEN", "USB_RESUME_INT"))


@dataclasses.dataclass
class Token:
    """One transaction as the SIE saw it: the token, what it answered, and (for IN) the data
    and its DATA0/1. ``commit`` is what the SIE does when the transaction ends."""
    pid: int
    endpoint: int
    handshake: str | None
    data: bytes = b""
    data1: bool = False
    commit: tuple | None = None     # (bd address, odd, write-back word, OUT data, buffer)


def native_field(holder: str, name: str, doc: str) -> property:
    """An attribute kept in a native object (the attribute ``holder`` names) as ``name``."""
    return property(lambda self: getattr(getattr(self, holder), name),
                    lambda self, value: setattr(getattr(self, holder), name, value), doc=doc)


class _Store:
    """``v``: the registers by name, kept in the native core."""

    def __init__(self, device):
        self._native, self._offset = device.native_state, \
            {r.name: r.offset for r in device.map.registers.values()}

    def __getitem__(self, name: str) -> int:
        return self._native.reg(self._offset[name])

    def __setitem__(self, name: str, value: int):
        self._native.set_reg(self._offset[name], value & 0xFF)

    def __contains__(self, name):
        return name in self._offset

    def keys(self):
        return self._offset.keys()


class Usb(RegisterDevice):
    READ_ONLY = ("PERID", "IDCOMP", "REV", "ADDINFO", "STAT", "FRMNUML", "FRMNUMH", "OBSERVE")

    def __init__(self, machine, chip):
        self.chip = chip
        self.irq = irq("USB0")
        self.listeners = []         # host models: attached(bool), tokens_free()
        self.notes = []             # (instruction count, text): misuse the model saw
        self.device = USB0_DEVICE
        self.native_state = machine.core.usb0
        self._map(machine, "USB0", (chip.sim, "SCGC4", "USBOTG"), None, None)
        machine.core.usb_setup(dict(self.layout(), irq=self.irq,
                                    sram_base=SRAM_BASE, sram_size=SRAM_SIZE))
        super().__init__(machine, "USB0", gate=(chip.sim, "SCGC4", "USBOTG"))
        machine.core.add_route(USB0_DEVICE, self.base, self.base + self.size)

    def reset(self):
        self.v = _Store(self)
        self.writes = []
        self.native_state.reset_registers()
        self.native_state.reset_odd()
        self.frame = 0
        self.in_reset = False           # the host holds SE0

    native = native_field("native_state", "native", "the native path on (the default); False: "
                          "this class makes every access and the host's pump every poll "
                          "(the reference)")
    frame = native_field("native_state", "frame", "FRMNUM: the last SOF's frame number")
    in_reset = native_field("native_state", "in_reset", "the host holds SE0")

    @property
    def odd(self) -> list:
        """The ping-pong pointers, [endpoint][tx] (a copy)."""
        n = self.native_state
        return [[n.odd(ep, 0), n.odd(ep, 1)] for ep in range(ENDPOINTS)]

    def clocks_changed(self):
        """The clock tree changed: the native path answers only at 48 MHz."""
        self.native_state.clock_ok = self.clock_ok()

    def mpu_changed(self):
        """The system MPU changed: the native path moves data only where all of SRAM is
        granted to the USB controller (reads; writes for the BD write-back)."""
        n, mpu = self.native_state, self.chip.mpu
        n.dma_reads_ram = mpu.master_may(USB_MASTER, SRAM_BASE, SRAM_SIZE, False)
        n.dma_writes_ram = mpu.master_may(USB_MASTER, SRAM_BASE, SRAM_SIZE, True)

    # -- registers ------------------------------------------------------------------------
    def w_ISTAT(self, value, mask):
        written = value & mask
        was_busy = self.token_busy()
        self.v["ISTAT"] &= ~written
        self._update_irq()
        if was_busy and not self.token_busy():
            for listener in self.listeners:
                listener.tokens_free()

    def w_ERRSTAT(self, value, mask):
        self.v["ERRSTAT"] &= ~(value & mask)

    def w_INTEN(self, value, mask):
        self.v["INTEN"] = value
        self._update_irq()

    def w_CTL(self, value, mask):
        self.v["CTL"] = value & ~(CTL_SE0 | CTL_JSTATE)
        if value & CTL_ODDRST:
            self.native_state.reset_odd()
        if value & CTL_HOSTMODEEN:
            self.note("CTL.HOSTMODEEN set: host mode is not modelled")
        self._idle_watch()

    def r_CTL(self):
        line = 0
        if self.attached():
            line = CTL_SE0 if self.in_reset else CTL_JSTATE
        return self.v["CTL"] | line

    def w_BDTPAGE1(self, value, mask):
        self.v["BDTPAGE1"] = value & self.map["BDTPAGE1"].field("BDTBA").mask

    def w_CONTROL(self, value, mask):
        before = self.attached()
        self.v["CONTROL"] = value
        self._attach_changed(before)

    def w_USBCTRL(self, value, mask):
        before = self.attached()
        self.v["USBCTRL"] = value
        if not value & USBCTRL_SUSP:        # leaving suspend clears it
            self.v["USBTRC0"] &= ~USBTRC0_USB_RESUME_INT
            self._update_irq()
        self._attach_changed(before)

    def r_OBSERVE(self):
        pde = bool(self.v["USBCTRL"] & USBCTRL_PDE)
        pulled_up = bool(self.v["CONTROL"] & CONTROL_DPPULLUPNONOTG)
        return (OBSERVE_DPPU * pulled_up |
                (OBSERVE_DPPD | OBSERVE_DMPD) * pde)

    def w_USBTRC0(self, value, mask):
        if value & USBTRC0_USBRESET:
            before = self.attached()
            self.native_state.reset_registers()     # the module's registers: reset values
            self.writes = []
            self.native_state.reset_odd()
            self._update_irq()
            self._attach_changed(before)
            return
        writable = USBTRC0_SOFTWARE_BIT | USBTRC0_USBRESMEN
        self.v["USBTRC0"] = (self.v["USBTRC0"] & ~writable) | (value & writable)

    def r_FRMNUML(self):
        return self.frame & 0xFF

    def r_FRMNUMH(self):
        return (self.frame >> 8) & 0x7

    # -- state ----------------------------------------------------------------------------
    def note(self, text: str):
        self.notes.append((self.machine.instructions_now(), text))

    def attached(self) -> bool:
        """The pull-up on D+ is on (CONTROL.DPPULLUPNONOTG) and the module is clocked."""
        return self.clocked() and bool(self.v["CONTROL"] & CONTROL_DPPULLUPNONOTG)

    def enabled(self) -> bool:
        return bool(self.v["CTL"] & CTL_USBENSOFEN)

    def suspended(self) -> bool:
        return bool(self.v["USBCTRL"] & USBCTRL_SUSP)

    def clock_ok(self) -> bool:
        usb = self.chip.usb_hz()
        return usb is not None and abs(usb / USB_CLOCK_HZ - 1) <= USB_CLOCK_TOLERANCE

    def token_busy(self) -> bool:
        """ISTAT.TOKDNE is set: the firmware has not taken the last token's STAT yet."""
        return bool(self.v["ISTAT"] & ISTAT_TOKDNE)

    def bdt_base(self) -> int:
        return self.v["BDTPAGE3"] << 24 | self.v["BDTPAGE2"] << 16 | self.v["BDTPAGE1"] << 8

    def _attach_changed(self, before: bool):
        now = self.attached()
        if now != before:
            for listener in self.listeners:
                listener.attached(now)
        self._idle_watch()

    def _flag(self, *bits: str):
        for b in bits:
            self.v["ISTAT"] |= ISTAT[b]
        self._update_irq()

    def _update_irq(self):
        level = bool(self.v["ISTAT"] & self.v["INTEN"]) or \
            bool(self.v["USBTRC0"] & USBTRC0_USB_RESUME_INT)
        self.machine.set_irq(self.irq, level)

    def _bus_activity(self):
        """Something happened on the bus: the idle timer restarts, and a suspended module
        armed for it (USBRESMEN) raises the asynchronous resume interrupt."""
        if self.suspended() and self.v["USBTRC0"] & USBTRC0_USBRESMEN:
            self.v["USBTRC0"] |= USBTRC0_USB_RESUME_INT
            self._update_irq()
        self._idle_watch()

    def _idle_watch(self):
        """ISTAT.SLEEP IDLE_TO_SLEEP_S after now while attached, enabled and not in reset (the
        timer is native)."""
        self.machine.core.usb_idle_watch()

    # -- the bus (called by the host model) ---------------------------------------------------
    def bus_reset(self, active: bool):
        """The host drives SE0 (``active``) or ends the reset. USBRST is set as the reset
        is decoded (the SIE changes nothing else: the firmware does, on USBRST)."""
        self.in_reset = active
        self._bus_activity()
        if active and self.attached():
            self._flag("USBRST")

    def sof(self, frame: int):
        """A SOF: FRMNUM, bus activity, ISTAT.SOFTOK while attached, enabled, awake (native:
        the host's frames make it there)."""
        self.machine.core.usb_sof(frame)

    def token(self, pid: int, address: int, endpoint: int, data: bytes = b"",
              data1: bool = False) -> Token:
        """A token (and for OUT/SETUP its data packet) arriving now: the SIE's answer. The
        BD's write-back, STAT and TOKDNE follow at the end of the transaction, in
        :meth:`complete`."""
        self._bus_activity()
        silent = Token(pid, endpoint, NONE)
        if not (self.attached() and self.enabled() and not self.suspended() and
                self.clock_ok() and not self.in_reset):
            return silent
        if address != self.v["ADDR"] & 0x7F or endpoint >= ENDPOINTS:
            return silent
        ctl = self.v[f"ENDPT{endpoint}"]
        tx = pid == PID_IN
        if not ctl & (ENDPT0_EPTXEN if tx else ENDPT0_EPRXEN):
            return silent
        if pid == PID_SETUP:
            if ctl & ENDPT0_EPCTLDIS:
                return silent
            if ctl & ENDPT0_EPSTALL:
                self.v[f"ENDPT{endpoint}"] = ctl & ~ENDPT0_EPSTALL
                ctl = self.v[f"ENDPT{endpoint}"]
        return self._answer(Token(pid, endpoint, NONE, data, data1), ctl, tx)

    def _answer(self, tok: Token, ctl: int, tx: bool) -> Token:
        ep, setup = tok.endpoint, tok.pid == PID_SETUP
        if ctl & ENDPT0_EPSTALL:
            tok.handshake = STALL
            self._flag("STALL")
            return tok
        odd = self.native_state.odd(ep, int(tx))
        bd_at = self.bdt_base() | ep << 5 | int(tx) << 4 | odd << 3
        word, buffer = self._read_bd(bd_at)
        busy = self.v["CTL"] & CTL_TXSUSPENDTOKENBUSY
        if not word & BD_OWN or (busy and not setup):
            tok.handshake = NONE if setup else NAK
            return tok
        if word & BD_STALL:
            tok.handshake = STALL
            self._flag("STALL")
            return tok
        bc = (word >> BD_BC_SHIFT) & BD_BC_MASK
        bd_data1 = bool(word & BD_DATA1)
        if tx:
            tok.data = self._dma_read(buffer, bc, word & BD_NINC)
            tok.data1 = bd_data1
            tok.handshake = ACK
            tok.commit = (bd_at, odd, word, b"", buffer)
            return tok
        if len(tok.data) > bc:
            self.v["ERRSTAT"] |= ERRSTAT_DMAERR
            if self.v["ERREN"] & ERREN_DMAERREN:
                self._flag("ERROR")
            return tok
        tok.handshake = ACK
        if word & BD_DTS and tok.data1 != bd_data1:
            return tok                      # a retransmission: ACKed, dropped
        tok.commit = (bd_at, odd, word, tok.data, buffer)
        return tok

    def complete(self, tok: Token):
        """The transaction ``tok`` ended on the bus: the SIE writes the OUT data and the BD
        back, flips the ODD pointer and reports the token (STAT, TOKDNE)."""
        if tok.commit is None:
            return
        bd_at, odd, word, data, buffer = tok.commit
        ep, tx = tok.endpoint, tok.pid == PID_IN
        n = len(tok.data)
        if not tx:
            self._dma_write(buffer, data, word & BD_NINC)
        if not word & BD_KEEP:
            back = (word & BD_DATA1) | tok.pid << 2 | n << BD_BC_SHIFT
            self._dma_write_word(bd_at, back)
        self.native_state.set_odd(ep, int(tx), odd ^ 1)
        self.v["STAT"] = ep << 4 | int(tx) << 3 | odd << 2
        if tok.pid == PID_SETUP:
            self.v["CTL"] |= CTL_TXSUSPENDTOKENBUSY
        self._flag("TOKDNE")

    # -- DMA ------------------------------------------------------------------------------
    def _check(self, address: int, n: int, write: bool, what: str):
        self.chip.mpu.check_dma("USB0", USB_MASTER, address, n, write, what, flash_reads=True)

    def check_write_back(self, bd_at: int):
        """The DMA rule for a BD's write-back (a Fault if it is broken)."""
        self._check(bd_at, 4, True, "a buffer descriptor")

    def _read_bd(self, bd_at: int) -> tuple:
        self._check(bd_at, BD_BYTES, False, "a buffer descriptor")
        raw = self.machine.read(bd_at, BD_BYTES)
        return int.from_bytes(raw[:4], "little"), int.from_bytes(raw[4:], "little")

    def _dma_read(self, address: int, n: int, ninc: bool) -> bytes:
        if n == 0:
            return b""
        self._check(address, 1 if ninc else n, False, "IN data")
        if ninc:
            return self.machine.read(address, 1) * n
        return self.machine.read(address, n)

    def _dma_write(self, address: int, data: bytes, ninc: bool):
        if not data:
            return
        self._check(address, 1 if ninc else len(data), True, "OUT data")
        self.machine.write(address, data[-1:] if ninc else data)

    def _dma_write_word(self, address: int, word: int):
        self._check(address, 4, True, "a buffer descriptor")
        self.machine.write(address, word.to_bytes(4, "little"))
