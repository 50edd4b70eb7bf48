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
"""

from __future__ import annotations

from .peripheral import RegisterDevice
from .registers import irq, peripheral

N_CHANNELS = 8
_MAP = peripheral("FTM0")
_TOF, _TOIE, _CPWMS = (_MAP["SC"].bit(f) for f in ("TOF", "TOIE", "CPWMS"))
_CLKS_PS = _MAP["SC"].field("CLKS").mask | _MAP["SC"].field("PS").mask
_CHF, _CHIE = _MAP["C0SC"].bit("CHF"), _MAP["C0SC"].bit("CHIE")
_CNSC_WRITABLE = _CHIE | _MAP["C0SC"].bit("MSB") | _MAP["C0SC"].bit("MSA") | \
    _MAP["C0SC"].bit("ELSB") | _MAP["C0SC"].bit("ELSA") | _MAP["C0SC"].bit("DMA")
_FTMEN = _MAP["MODE"].bit("FTMEN")
_CHANNELS_AT = _MAP["C0SC"].offset         # CnSC, CnV pairs, 8 bytes apart


class Ftm(RegisterDevice):
    def __init__(self, machine, chip, instance, gate):
        self.chip = chip
        self.instance = instance
        self.irq = irq(f"FTM{instance}")
        self.pin_of = {}            # channel -> (port letter, pin, mux) connecting it
        super().__init__(machine, f"FTM{instance}", gate=(chip.sim,) + gate, span=0x9C)

    def reset(self):
        super().reset()
        self.anchor = None          # (cycle, count) while the counter runs
        self.pending = {}           # register -> value loaded at the next wrap
        self.written_at = {}        # register -> cycle of that write
        self.captures = []          # (cycle, channel, value)
        self.unmodelled = []
        self._tof_clear = 0
        self._line = False
        self._tof_event = None
        self._rate_key, self._rate = None, 0.0

    # -- the counter -----------------------------------------------------------------------
    def clock_hz(self) -> float:
        clks, ps = self.field("SC", "CLKS"), self.field("SC", "PS")
        if clks == 1:
            src = self.chip.bus_hz()
        elif clks == 2:
            src = self.chip.fixed_hz()
        else:
            return 0.0
        return src / (1 << ps)

    def _ticks_per_cycle(self):
        # Read at every counter and buffered-write computation: kept until SC's clock
        # select or prescaler or the clock tree changes.
        key = (self.v["SC"] & _CLKS_PS, self.chip._tree)
        if key != self._rate_key:
            hz = self.clock_hz()
            self._rate = hz / self.machine.core_hz if hz else 0.0
            self._rate_key = key
        return self._rate

    def _limits(self):
        cntin, mod = self.v["CNTIN"] & 0xFFFF, self.v["MOD"] & 0xFFFF
        return cntin, mod

    def _period_ticks(self):
        cntin, mod = self._limits()
        return (mod - cntin + 1) if mod >= cntin else 0x10000

    def _raw_ticks(self, now):
        start, count0 = self.anchor
        return int((now - start) * self._ticks_per_cycle()), count0

    def count(self, now=None) -> int:
        now = self.machine.now() if now is None else now
        self._load_pending(now)
        if self.anchor is None:
            return self.v["CNT"] & 0xFFFF
        ticks, count0 = self._raw_ticks(now)
        cntin, _ = self._limits()
        return cntin + (count0 - cntin + ticks) % self._period_ticks()

    def _next_wrap_after(self, cycle):
        """First core cycle > cycle at which the counter wraps from MOD to CNTIN."""
        if self.anchor is None:
            return None
        start, count0 = self.anchor
        per_cycle = self._ticks_per_cycle()
        cntin, _ = self._limits()
        period = self._period_ticks()
        ticks = int((cycle - start) * per_cycle)
        pos = (count0 - cntin + ticks) % period
        to_wrap = period - pos
        return start + int(-(-(ticks + to_wrap) // per_cycle))

    def cycles_per_tick(self) -> float:
        """Core cycles per count of the counter at the current clocks (0 when stopped)."""
        rate = self._ticks_per_cycle()
        return 1 / rate if rate else 0.0

    def next_tick(self, cycle: int) -> int | None:
        """The first core cycle at or after ``cycle`` at which the running counter steps
        (None while it is stopped)."""
        if self.anchor is None:
            return None
        start, _ = self.anchor
        per_cycle = self._ticks_per_cycle()
        ticks = -(-(cycle - start) * per_cycle // 1)
        return start + int(-(-ticks // per_cycle))

    def _load_pending(self, now):
        """Apply buffered MOD/CnV writes whose wrap has come."""
        if not self.pending:
            return
        for name in list(self.pending):
            wrap = self._next_wrap_after(self.written_at[name])
            if wrap is None or wrap <= now:
                value = self.pending.pop(name)
                if name == "MOD" and wrap is not None:
                    # re-anchor at the wrap so the new modulus counts from CNTIN
                    self.anchor = (wrap, self._limits()[0])
                self.v[name] = value
                del self.written_at[name]

    def _restart(self, now):
        self._load_pending(now)
        if self.field("SC", "CLKS") in (1, 2):
            self.anchor = (now, self.count(now) if self.anchor else self.v["CNT"] & 0xFFFF)
        else:
            if self.anchor is not None:
                self.v["CNT"] = self.count(now)
            self.anchor = None
        self._schedule_tof()

    def _schedule_tof(self):
        if self._tof_event:
            self._tof_event.cancel()
            self._tof_event = None
        if self.anchor is not None and self.v["SC"] & _TOIE:
            wrap = self._next_wrap_after(self.machine.now())
            self._tof_event = self.machine.at(wrap, self._tof)

    def _tof(self):
        self._tof_event = None
        self.v["SC"] |= _TOF
        self._update_irq()
        self._schedule_tof()

    # -- interrupt ---------------------------------------------------------------------------
    def _update_irq(self):
        level = bool(self.v["SC"] & _TOF and self.v["SC"] & _TOIE)
        for ch in range(N_CHANNELS):
            sc = self.v[f"C{ch}SC"]
            if sc & _CHF and sc & _CHIE:
                level = True
        if level != self._line:
            self._line = level
            self.machine.set_irq(self.irq, level)

    # -- registers ---------------------------------------------------------------------------
    def r_CNT(self):
        return self.count()

    def w_CNT(self, value, mask):
        now = self.machine.now()
        self.v["CNT"] = self.v["CNTIN"] & 0xFFFF
        if self.anchor is not None:
            self.anchor = (now, self.v["CNTIN"] & 0xFFFF)
        self._schedule_tof()

    def r_SC(self):
        if self.anchor is not None and not self.v["SC"] & _TOIE:
            # TOF without TOIE: computed, not scheduled
            wrap = self._next_wrap_after(self._tof_cleared_at())
            if wrap is not None and wrap <= self.machine.now():
                self.v["SC"] |= _TOF
        return self.v["SC"]

    def _tof_cleared_at(self):
        return max(self._tof_clear, self.anchor[0])

    def w_SC(self, value, mask):
        now = self.machine.now()
        old = self.v["SC"]
        tof = old & _TOF if value & _TOF else 0     # TOF: cleared by writing 0
        if not tof:
            self._tof_clear = now
        self.v["SC"] = (value & ~_TOF) | tof
        if (old ^ value) & (_CLKS_PS | _TOIE):
            self._restart(now)
        if value & _CPWMS:
            self.unmodelled.append("center-aligned PWM (CPWMS)")
        self._update_irq()

    def _buffered(self, name, value):
        now = self.machine.now()
        self._load_pending(now)
        if self.anchor is None:
            self.v[name] = value
            self.pending.pop(name, None)
        else:
            self.pending[name] = value
            self.written_at[name] = now

    def w_MOD(self, value, mask):
        self._buffered("MOD", value & 0xFFFF)
        self._schedule_tof()

    def w_CNTIN(self, value, mask):
        self.v["CNTIN"] = value & 0xFFFF

    def w_MODE(self, value, mask):
        self.v["MODE"] = value
        if value & _FTMEN:
            self.unmodelled.append("MODE[FTMEN] = 1 (enhanced synchronisation)")

    def r_STATUS(self):
        return sum(1 << ch for ch in range(N_CHANNELS) if self.v[f"C{ch}SC"] & _CHF)

    def w_STATUS(self, value, mask):
        for ch in range(N_CHANNELS):
            if not value & (1 << ch):
                self.v[f"C{ch}SC"] &= ~_CHF
        self._update_irq()

    def w_COMBINE(self, value, mask):
        self.v["COMBINE"] = value
        if value:
            self.unmodelled.append("combined / dual-edge channel modes")

    def _channel_write(self, ch, name, value):
        if name.endswith("SC"):
            old = self.v[name]
            chf = old & _CHF if value & _CHF else 0     # CHF: cleared by writing 0
            self.v[name] = (value & _CNSC_WRITABLE) | chf
            self._update_irq()
        else:
            self._buffered(name, value & 0xFFFF)

    def write(self, address, size, value):
        offset = address - self.base
        if _CHANNELS_AT <= offset < _CHANNELS_AT + 8 * N_CHANNELS:
            reg = self._reg_for(offset, size, True)
            shift = 8 * (offset - reg.offset)
            m = ((1 << (8 * size)) - 1) << shift
            merged = (self.v[reg.name] & ~m) | ((value << shift) & m)
            self._channel_write((reg.offset - _CHANNELS_AT) // 8, reg.name, merged)
            return
        super().write(address, size, value)

    def read(self, address, size):
        offset = address - self.base
        if _CHANNELS_AT <= offset < _CHANNELS_AT + 8 * N_CHANNELS:
            self._load_pending(self.machine.now())
        return super().read(address, size)

    # -- what the pins see ----------------------------------------------------------------
    def channel_mode(self, ch) -> str:
        sc = self.v[f"C{ch}SC"]
        ms, els = (sc >> 4) & 3, (sc >> 2) & 3
        if self.v["SC"] & _CPWMS:
            return "center-aligned PWM"
        if ms & 2:
            return "edge-aligned PWM" if els else "disabled"
        if ms == 1:
            return "output compare" if els else "disabled"
        return {0: "disabled", 1: "capture rising", 2: "capture falling", 3: "capture both"}[els]

    def period_s(self) -> float | None:
        hz = self.clock_hz()
        if not hz:
            return None
        self._load_pending(self.machine.now())
        return self._period_ticks() / hz

    def pulse_s(self, ch) -> float | None:
        """Active time per period of an edge-aligned PWM channel (the CnV in effect now)."""
        if self.channel_mode(ch) != "edge-aligned PWM":
            return None
        hz = self.clock_hz()
        if not hz:
            return None
        self._load_pending(self.machine.now())
        cntin, mod = self._limits()
        cnv = self.v[f"C{ch}V"] & 0xFFFF
        if cnv > mod:
            ticks = self._period_ticks()
        else:
            ticks = max(0, cnv - cntin)
        return ticks / hz

    def commanded_value(self, ch) -> int | None:
        """An edge-aligned PWM channel's CnV for the next period: a write while the counter
        runs waits for the period's end, so this is what the pin carries from then on."""
        if self.channel_mode(ch) != "edge-aligned PWM":
            return None
        self._load_pending(self.machine.now())
        return self.pending.get(f"C{ch}V", self.v[f"C{ch}V"]) & 0xFFFF

    def high_true(self, ch) -> bool:
        return (self.v[f"C{ch}SC"] >> 2) & 3 == 2

    def edge(self, ch, rising: bool):
        """A level change on channel ``ch``'s pin (called by the pin model)."""
        mode = self.channel_mode(ch)
        if not mode.startswith("capture") or self.anchor is None:
            return
        if (mode == "capture rising" and not rising) or (mode == "capture falling" and rising):
            return
        now = self.machine.now()
        value = self.count(now)
        name = f"C{ch}SC"
        self.v[f"C{ch}V"] = value
        self.v[name] |= _CHF
        self.captures.append((now, ch, value))
        self._update_irq()
