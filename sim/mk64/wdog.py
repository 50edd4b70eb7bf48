"""The watchdog (WDOG), as the reference manual's "Watchdog Timer" chapter describes it:

* The unlock sequence is 0xC520 then 0xD928 written to WDOG_UNLOCK, the second within 20
  bus clock cycles of the first; any other value, or a later second word, resets the chip.
* The first word of the unlock sequence must come within the watchdog configuration time
  (WCT, 256 bus clocks) after reset, or the watchdog resets the chip.
* After an unlock, the write-once registers (STCTRLH, TOVALH/L, WINH/L, PRESC) may each be
  written once within the WCT; if none is written in that window the watchdog resets the
  chip. Later writes are ignored (and recorded).
* While enabled, it resets the chip when its counter reaches TOVAL (clock: LPO 1 kHz, or
  with CLKSRC the bus clock; divided by PRESCVAL + 1). A refresh is 0xA602 then 0xB480
  within 20 bus clocks.

The model records when the watchdog was disabled (``disabled_at``: instruction count and
cycle) so a test can check nothing ran before it.
"""

from __future__ import annotations

from .machine import ChipReset
from .peripheral import RegisterDevice

WCT_BUS_CYCLES = 256
SEQUENCE_GAP_BUS_CYCLES = 20
UNLOCK = (0xC520, 0xD928)
REFRESH = (0xA602, 0xB480)
LPO_HZ = 1000.0
WRITE_ONCE = ("STCTRLH", "TOVALH", "TOVALL", "WINH", "WINL", "PRESC")


class Wdog(RegisterDevice):
    def __init__(self, machine, chip):
        self.chip = chip
        super().__init__(machine, "WDOG", span=0x18)

    def reset(self):
        super().reset()
        self.first_unlock = None        # cycle of a pending 0xC520
        self.unlocked_at = None         # cycle the unlock completed
        self.written = set()            # write-once registers written since the unlock
        self.first_refresh = None
        self.disabled_at = None         # (instruction count, cycle) when WDOGEN was cleared
        self.ignored = []               # (instruction count, register, value, why)
        self.log = []                   # (instruction count, cycle, register, value)
        self._timeout = None
        self._window = None
        self._started = 0
        m = self.machine
        if getattr(self.chip, "ready", False):
            # The first unlock word must arrive within the WCT after reset.
            self._window = m.at(self._bus_cycles_to_core(WCT_BUS_CYCLES, 0),
                                self._no_unlock_after_reset)
            self._arm_timeout()

    # -- time in bus clocks -------------------------------------------------------------------
    def _bus_ratio(self):
        return self.chip.core_hz() / self.chip.bus_hz()

    def _bus_cycles_to_core(self, n, start):
        return start + int(round(n * self._bus_ratio()))

    def _bus_elapsed(self, since, now):
        return (now - since) / self._bus_ratio()

    @property
    def enabled(self) -> bool:
        return bool(self.v["STCTRLH"] & 1)

    def timeout_s(self) -> float:
        clk = self.chip.bus_hz() if self.v["STCTRLH"] & 2 else LPO_HZ
        toval = (self.v["TOVALH"] << 16) | self.v["TOVALL"]
        presc = (self.v["PRESC"] >> 8) & 7
        return toval * (presc + 1) / clk

    def _arm_timeout(self):
        if self._timeout:
            self._timeout.cancel()
            self._timeout = None
        if self.enabled:
            self._started = self.machine.now()
            self._timeout = self.machine.after(self.timeout_s(), self._expired)

    def _expired(self):
        raise ChipReset("WDOG", f"watchdog timeout ({self.timeout_s():.3f} s) while enabled")

    def _no_unlock_after_reset(self):
        self._window = None
        if self.first_unlock is None and self.unlocked_at is None:
            raise ChipReset("WDOG", f"no unlock sequence within the WCT ({WCT_BUS_CYCLES} bus "
                            "clocks) after reset")

    def _no_update_after_unlock(self):
        self._window = None
        if not self.written:
            raise ChipReset("WDOG", "no configuration register written within the WCT after "
                            "the unlock")

    # -- registers ---------------------------------------------------------------------------
    def r_TMROUTH(self):
        return (self._count() >> 16) & 0xFFFF

    def r_TMROUTL(self):
        return self._count() & 0xFFFF

    def _count(self):
        if not self.enabled:
            return 0
        clk = self.chip.bus_hz() if self.v["STCTRLH"] & 2 else LPO_HZ
        presc = (self.v["PRESC"] >> 8) & 7
        elapsed = (self.machine.now() - self._started) / self.machine.core_hz
        return int(elapsed * clk / (presc + 1))

    def write(self, address, size, value):
        name = self._reg_for(address - self.base, size, True).name
        m = self.machine
        self.log.append((m.instructions_now(), m.now(), name, value))
        if name == "UNLOCK" and size != 2:
            raise ChipReset("WDOG", f"{8 * size}-bit write to WDOG_UNLOCK: the sequence is two "
                            "16-bit writes")
        super().write(address, size, value)

    def w_UNLOCK(self, value, mask):
        now = self.machine.now()
        if not self.v["STCTRLH"] & 0x10:            # ALLOWUPDATE clear: no more updates
            self.ignored.append((self.machine.instructions_now(), "UNLOCK", value,
                                 "ALLOWUPDATE is clear"))
            return
        if value == UNLOCK[0]:
            self.first_unlock = now
        elif value == UNLOCK[1] and self.first_unlock is not None:
            gap = self._bus_elapsed(self.first_unlock, now)
            if gap > SEQUENCE_GAP_BUS_CYCLES:
                raise ChipReset("WDOG", f"unlock words {gap:.0f} bus clocks apart (at most "
                                f"{SEQUENCE_GAP_BUS_CYCLES})")
            self.first_unlock = None
            self.unlocked_at = now
            self.written = set()
            if self._window:
                self._window.cancel()
            self._window = self.machine.at(self._bus_cycles_to_core(WCT_BUS_CYCLES, now),
                                           self._no_update_after_unlock)
        else:
            raise ChipReset("WDOG", f"invalid unlock sequence: 0x{value:04X} written to WDOG_UNLOCK")

    def w_REFRESH(self, value, mask):
        now = self.machine.now()
        if value == REFRESH[0]:
            self.first_refresh = now
        elif value == REFRESH[1] and self.first_refresh is not None and \
                self._bus_elapsed(self.first_refresh, now) <= SEQUENCE_GAP_BUS_CYCLES:
            self.first_refresh = None
            self._arm_timeout()
        else:
            raise ChipReset("WDOG", f"invalid refresh sequence (0x{value:04X})")

    def w_STCTRLL(self, value, mask):
        if value & 0x8000:                          # INTFLG: write 1 to clear
            self.v["STCTRLL"] &= ~0x8000

    def w_RSTCNT(self, value, mask):
        self.v["RSTCNT"] &= ~value                  # write 1 to clear

    def _write_once(self, name, value):
        m = self.machine
        now = m.now()
        why = None
        if self.unlocked_at is None:
            why = "not unlocked"
        elif self._bus_elapsed(self.unlocked_at, now) > WCT_BUS_CYCLES:
            why = "WCT after the unlock has passed"
        elif name in self.written:
            why = "already written once since the unlock"
        if why:
            self.ignored.append((m.instructions_now(), name, value, why))
            return
        self.written.add(name)
        was_enabled = self.enabled
        self.v[name] = value
        if name == "STCTRLH" and was_enabled and not self.enabled and self.disabled_at is None:
            self.disabled_at = (m.instructions_now(), now)
        self._arm_timeout()

    def w_STCTRLH(self, value, mask):
        self._write_once("STCTRLH", value)

    def w_TOVALH(self, value, mask):
        self._write_once("TOVALH", value)

    def w_TOVALL(self, value, mask):
        self._write_once("TOVALL", value)

    def w_WINH(self, value, mask):
        self._write_once("WINH", value)

    def w_WINL(self, value, mask):
        self._write_once("WINL", value)

    def w_PRESC(self, value, mask):
        self._write_once("PRESC", value)

    def w_TMROUTH(self, value, mask):
        pass

    def w_TMROUTL(self, value, mask):
        pass
