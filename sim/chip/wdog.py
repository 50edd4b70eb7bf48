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
cycle) so a test can check nothing ran before it, the writes it ignored (``ignored``), and
every write (``log``: instruction count, cycle, register, value) until taken (none with the
core's ``keep_records`` off). A reset stops the run and raises ``ChipReset("WDOG", why)``.

The model is native (``heliquad._simcore.Mk64Core``, sim/chip/mk64_devices.cpp): the loop
refreshes it every tick. This class is its view.
"""

from __future__ import annotations

from .machine import WDOG_DEVICE
from .peripheral import NativeRegisters

WCT_BUS_CYCLES = 256
SEQUENCE_GAP_BUS_CYCLES = 20
UNLOCK = (0xC520, 0xD928)
REFRESH = (0xA602, 0xB480)
LPO_HZ = 1000.0
WRITE_ONCE = ("STCTRLH", "TOVALH", "TOVALL", "WINH", "WINL", "PRESC")


class Wdog(NativeRegisters):
    def __init__(self, machine, chip):
        self.chip = chip
        core = machine.core
        super().__init__(machine, "WDOG", WDOG_DEVICE, core.wdog_reg, span=0x18)
        core.wdog_setup(dict(self.layout(), wct=WCT_BUS_CYCLES, gap=SEQUENCE_GAP_BUS_CYCLES,
                             unlock=UNLOCK, refresh=REFRESH, lpo_hz=LPO_HZ))
        self._log = []

    def reset(self):
        self._log = []                  # the core resets the model with the machine
        if getattr(self.chip, "ready", False):
            # The first unlock word must arrive within the WCT after reset; the timeout
            # runs from reset. Timed with the clocks the chip resets to (the core learns
            # them only after every device has reset).
            self.machine.core.wdog_power_on(self.chip.core_hz(), self.chip.bus_hz())

    def _state(self) -> dict:
        return self.machine.core.wdog_state()

    def _name(self, offset) -> str:
        return self._at[offset].name

    @property
    def enabled(self) -> bool:
        return bool(self.v["STCTRLH"] & self.bit("STCTRLH", "WDOGEN"))

    def timeout_s(self) -> float:
        return self.machine.core.wdog_timeout_s()

    first_unlock = property(lambda self: self._state()["first_unlock"],
                            doc="cycle of a pending first unlock word, or None")
    unlocked_at = property(lambda self: self._state()["unlocked_at"],
                           doc="cycle the last unlock completed, or None")
    first_refresh = property(lambda self: self._state()["first_refresh"])
    disabled_at = property(lambda self: self._state()["disabled_at"],
                           doc="(instruction count, cycle) when WDOGEN was cleared, or None")

    @property
    def written(self) -> set:
        """The write-once registers written since the unlock."""
        return {self._name(o) for o in self._state()["written"]}

    @property
    def ignored(self) -> list:
        """(instruction count, register, value, why) of the writes the watchdog ignored."""
        return [(i, self._name(o), v, why) for i, o, v, why in self._state()["ignored"]]

    @property
    def log(self) -> list:
        """(instruction count, cycle, register, value) of every write since reset (clearing
        this list forgets them too)."""
        self._log.extend((i, c, self._name(o), v)
                         for i, c, o, v in self.machine.core.wdog_take_log())
        return self._log
