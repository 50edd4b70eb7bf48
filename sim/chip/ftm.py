"""FlexTimer (FTM0, FTM3) after the reference manual's "FlexTimer Module" chapter, for the
modes the flight controller uses: up-counting edge-aligned PWM and input capture.

* The counter runs when SC[CLKS] selects a clock: 1 = system clock (the bus clock for the
  FTMs on this chip), 2 = fixed frequency clock (MCGFFCLK), 3 = external (not modelled),
  divided by 2^SC[PS]. It counts CNTIN..MOD and wraps (a period of MOD - CNTIN + 1 ticks),
  setting SC[TOF] at each wrap (a TOIE interrupt is requested then). Writing CNT restarts it
  at CNTIN. CNT is computed from time when read.
* Edge-aligned PWM (CPWMS = 0, CnSC[MSB] = 1): the output goes active at CNTIN and inactive
  at the match with CnV; ELSB:ELSA = 10 is high-true, x1 low-true. With CLKS != 0 a written
  MOD or CnV takes effect when the counter next wraps from MOD to CNTIN (FTMEN = 0); with
  CLKS = 0 at once. CnV > MOD gives 100 % duty, CnV = CNTIN 0 %.
* Input capture (MSB:MSA = 00, ELSB:ELSA != 00): an edge of the selected polarity on the
  channel's pin copies CNT into CnV and sets CnSC[CHF] (and STATUS[CHnF]); with CHIE the
  FTM interrupt is requested while CHF is set. CHF clears by writing it 0.
* MODE[FTMEN] = 1 (the enhanced synchronisation of SYNC/SYNCONF), combined and
  dual-edge modes, dead time, fault control, quadrature decoding and write protection are
  not modelled: using them is recorded in ``unmodelled``.

Captures are kept with their time (``captures``: (cycle, channel, value)) until taken: a
caller clears the list; with the core's ``keep_records`` off (a long lockstep run) none are
kept.

The model is native (``heliquad._simcore.Mk64Core``, sim/chip/mk64_devices.cpp): the flight
loop writes FTM0's eight CnV registers every loop and FTM3's capture handler touches its
registers a dozen times an edge. This class is its view.
"""

from __future__ import annotations

import functools

from .machine import FTM0_DEVICE, FTM3_DEVICE
from .peripheral import NativeRegisters
from .registers import irq

N_CHANNELS = 8
DEVICE = {0: FTM0_DEVICE, 3: FTM3_DEVICE}
#: Channel modes by the native model's number (Ftm::Mode).
MODES = ("disabled", "edge-aligned PWM", "output compare", "capture rising", "capture falling",
         "capture both", "center-aligned PWM")


class Ftm(NativeRegisters):
    def __init__(self, machine, chip, instance, gate):
        if instance not in DEVICE:
            raise ValueError("only FTM0 and FTM3 are modelled")
        self.chip = chip
        self.instance = instance
        self.irq = irq(f"FTM{instance}")
        self.pin_of = {}            # channel -> (port letter, pin, mux) connecting it
        device = DEVICE[instance]
        core = machine.core
        super().__init__(machine, f"FTM{instance}", device,
                         functools.partial(core.ftm_reg, device),
                         gate=(chip.sim,) + gate, span=0x9C)
        core.ftm_setup(device, dict(self.layout(), irq=self.irq))
        self._captures, self._unmodelled = [], []

    def reset(self):
        self._captures, self._unmodelled = [], []   # the core resets the model with the machine

    # -- what the model holds ----------------------------------------------------------------
    @property
    def captures(self) -> list:
        """(cycle, channel, value) of each capture since reset (clearing this list forgets
        them too)."""
        self._captures.extend(self.machine.core.ftm_take_captures(self.device))
        return self._captures

    @property
    def unmodelled(self) -> list:
        """What the program used that the model does not model (see the notes above)."""
        self._unmodelled.extend(self.machine.core.ftm_take_unmodelled(self.device))
        return self._unmodelled

    def _state(self) -> dict:
        return self.machine.core.ftm_state(self.device)

    anchor = property(lambda self: self._state()["anchor"],
                      doc="(cycle, count) the running counter started from, or None")

    @property
    def pending(self) -> dict:
        """MOD/CnV writes waiting for the counter's wrap: register name -> value."""
        return {self._name_at(o): v for o, v in self._state()["pending"].items()}

    def _name_at(self, offset):
        return self._at[offset].name

    # -- the counter -----------------------------------------------------------------------
    def clock_hz(self) -> float:
        return self.machine.core.ftm_clock_hz(self.device)

    def count(self) -> int:
        """CNT as a read now would return it."""
        return self.machine.core.ftm_count(self.device)

    def cycles_per_tick(self) -> float:
        """Core cycles per count of the counter at the current clocks (0 when stopped)."""
        return self.machine.core.ftm_cycles_per_tick(self.device)

    def next_tick(self, cycle: int) -> int | None:
        """The first core cycle at or after ``cycle`` at which the running counter steps
        (None while it is stopped)."""
        return self.machine.core.ftm_next_tick(self.device, cycle)

    # -- what the pins see ----------------------------------------------------------------
    def channel_mode(self, ch) -> str:
        return MODES[self.machine.core.ftm_mode(self.device, ch)]

    def period_s(self) -> float | None:
        return self.machine.core.ftm_period_s(self.device)

    def pulse_s(self, ch) -> float | None:
        """Active time per period of an edge-aligned PWM channel (the CnV in effect now)."""
        return self.machine.core.ftm_pulse_s(self.device, ch)

    def commanded_value(self, ch) -> int | None:
        """An edge-aligned PWM channel's CnV for the next period: a write while the counter
        runs waits for the period's end, so this is what the pin carries from then on."""
        return self.machine.core.ftm_commanded_value(self.device, ch)

    def commanded_values(self) -> list:
        """commanded_value of every channel, 0 to 7, in one call."""
        return self.machine.core.ftm_commanded_values(self.device)

    def high_true(self, ch) -> bool:
        sc = self.v[f"C{ch}SC"]
        return bool(sc & self.bit("C0SC", "ELSB")) and not sc & self.bit("C0SC", "ELSA")

    def edge(self, ch, rising: bool):
        """A level change on channel ``ch``'s pin (called by the pin model)."""
        self.machine.core.ftm_edge(self.device, ch, bool(rising))
