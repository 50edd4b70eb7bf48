"""Clock generation: SIM (clock gates, dividers, clock selects), OSC0 and the MCG.

The MCG's status register follows its control registers the way the reference manual
describes (K64 Sub-Family Reference Manual, chapter "Multipurpose Clock Generator"): OSCINIT0
sets once the crystal oscillator has started (never with a dead crystal), IREFST, CLKST,
PLLST and IRCST follow their selects after a synchronisation delay and only when the
selected source runs, LOCK0 sets after the PLL's lock time when its reference and VCO are
in range. From the status the model derives the MCG mode (FEI, FBE, PBE, PEE, ...) and the
clock tree (MCGOUTCLK, core/system, bus, FlexBus, flash, USB). It records every mode
change, every read of MCG_S and every value of the tree, and flags what the data sheet
forbids: a clock above its maximum, a PLL reference or VCO out of range, a mode change the
state diagram does not allow, a switch to the PLL before it locked.

Timing parameters not given by the manuals are stated as model parameters here.
"""

from __future__ import annotations

from dataclasses import dataclass

from .peripheral import RegisterDevice

# -- facts ------------------------------------------------------------------------------------
SLOW_IRC_HZ = 32_768.0                  # MCG slow internal reference, trimmed nominal
FAST_IRC_HZ = 4_000_000.0
IRC48M_HZ = 48_000_000.0
# FLL factors by (DMX32, DRST_DRS) (MCG_C4 description)
FLL_FACTOR = {(0, 0): 640, (0, 1): 1280, (0, 2): 1920, (0, 3): 2560,
              (1, 0): 732, (1, 1): 1464, (1, 2): 2197, (1, 3): 2929}
# FRDIV dividers for RANGE = 0 and for RANGE != 0 (MCG_C1 description)
FRDIV_LOW = (1, 2, 4, 8, 16, 32, 64, 128)
FRDIV_HIGH = (32, 64, 128, 256, 512, 1024, 1280, 1536)
# Data sheet limits, normal run mode
LIMITS_HZ = {"core": 120e6, "bus": 60e6, "flexbus": 50e6, "flash": 25e6}
PLL_REF_RANGE_HZ = (2e6, 4e6)
PLL_VCO_RANGE_HZ = (48e6, 120e6)
FLL_REF_RANGE_HZ = (31.25e3, 39.0625e3)
USB_HZ, USB_TOLERANCE = 48e6, 0.0025
# MCG state diagram: which mode may follow which
TRANSITIONS = {"FEI": {"FEE", "FBI", "FBE"}, "FEE": {"FEI", "FBI", "FBE"},
               "FBI": {"FEI", "FEE", "FBE", "BLPI"}, "FBE": {"FEI", "FEE", "FBI", "PBE", "BLPE"},
               "PBE": {"FBE", "PEE", "BLPE"}, "PEE": {"PBE"}, "BLPI": {"FBI"},
               "BLPE": {"FBE", "PBE"}}

# -- model parameters (not figures from a manual) ---------------------------------------------
CRYSTAL_STARTUP_S = 1e-3        # crystal oscillator start-up until OSCINIT0
MCG_SYNC_S = 2e-6               # a select (IREFS, CLKS, PLLS, IRCS) reaching its status bit
PLL_LOCK_REF_CYCLES = 1075      # lock detection, in PLL reference periods
PLL_LOCK_FIXED_S = 150e-6       # plus a fixed part


@dataclass(frozen=True)
class ClockTree:
    mode: str
    mcgout: float
    core: float
    bus: float
    flexbus: float
    flash: float
    usb: float | None
    pll: float | None           # MCGPLLCLK when the PLL runs
    fll: float                  # MCGFLLCLK
    oscer: float | None         # OSCERCLK

    def mhz(self) -> dict:
        return {k: (v / 1e6 if isinstance(v, float) else v) for k, v in self.__dict__.items()}


class Sim(RegisterDevice):
    """System integration module: clock gates (SCGC1-7), dividers (CLKDIV1/2), SOPT2."""

    READ_ONLY = ("SDID", "FCFG2", "UIDH", "UIDMH", "UIDML", "UIDL")
    #: The emulated chip's unique identification (SIM_UIDH, UIDMH, UIDML, UIDL; the SVD's
    #: reset value is 0, a real chip's is its own): one fixed id, "HQ" "EMU" "MK64" and 1,
    #: the same in every run (docs/teensy35-emulator.md).
    UID = {"UIDH": 0x0000_4851, "UIDMH": 0x0045_4D55, "UIDML": 0x4D4B_3634, "UIDL": 0x0000_0001}

    def __init__(self, machine, chip):
        self.chip = chip
        super().__init__(machine, "SIM", span=0x1064)

    def reset(self):
        super().reset()
        self.v.update(self.UID)

    def w_CLKDIV1(self, value, mask):
        self.v["CLKDIV1"] = value & 0xFFFF_0000
        self.chip.clocks_changed("SIM_CLKDIV1")

    def w_CLKDIV2(self, value, mask):
        self.v["CLKDIV2"] = value & 0xF
        self.chip.clocks_changed("SIM_CLKDIV2")

    def w_SOPT2(self, value, mask):
        self.v["SOPT2"] = value
        self.chip.clocks_changed("SIM_SOPT2")

    def gated(self, reg: str, fld: str) -> bool:
        return not self.v[reg] & self.map[reg].bit(fld)

    def write(self, address, size, value):
        super().write(address, size, value)
        self.chip.gates_changed()


class Osc(RegisterDevice):
    """OSC0_CR: external reference enable and load capacitors (16 MHz crystal on the board)."""

    def __init__(self, machine, chip):
        self.chip = chip
        super().__init__(machine, "OSC", name="OSC0", span=1)

    def w_CR(self, value, mask):
        self.v["CR"] = value & sum(f.mask for f in map(self.map["CR"].field, self.map["CR"].fields))
        self.chip.mcg.update()

    def load_pf(self) -> int:
        """Load capacitance switched in by SC2P/SC4P/SC8P/SC16P, in pF."""
        return sum(pf * self.field("CR", f"SC{pf}P") for pf in (2, 4, 8, 16))


class Mcg(RegisterDevice):
    READ_ONLY = ("S",)

    def __init__(self, machine, chip):
        self.chip = chip
        super().__init__(machine, "MCG", span=0xE)

    def reset(self):
        super().reset()
        self.osc_running = False
        self.pll_locked = False
        self._pending = {}          # status name -> Event
        self._pending_want = {}
        self._want = {}
        self.modes = []             # (instruction, cycle, mode)
        self.log = []               # (instruction, cycle, 'W'/'R', register, value)
        self.violations = []        # (instruction, cycle, text)
        self._mode = None
        if getattr(self.chip, "ready", False):
            self._note_mode()

    # -- program's view ---------------------------------------------------------------------
    def r_S(self):
        value = self.v["S"]
        m = self.machine
        self.log.append((m.instructions_now(), m.now(), "R", "S", value))
        return value

    def _write(self, name, value):
        m = self.machine
        self.log.append((m.instructions_now(), m.now(), "W", name, value))
        self.v[name] = value
        self.update()

    def w_C1(self, value, mask):
        self._write("C1", value)

    def w_C2(self, value, mask):
        self._write("C2", value)

    def w_C4(self, value, mask):
        self._write("C4", value)

    def w_C5(self, value, mask):
        self._write("C5", value & sum(self.map["C5"].field(f).mask for f in self.map["C5"].fields))

    def w_C6(self, value, mask):
        self._write("C6", value)

    def w_C7(self, value, mask):
        self._write("C7", value & 3)

    def w_SC(self, value, mask):
        old = self.v["SC"]
        w1c = self.map["SC"].bit("LOCS0") | self.map["SC"].bit("ATMF")
        self._write("SC", (value & ~w1c) | (old & w1c & ~value))

    # -- the hardware's view ----------------------------------------------------------------
    def f(self, reg, fld):
        return self.field(reg, fld)

    def _status(self, fld):
        return self.map["S"].field(fld).get(self.v["S"])

    def _set_status(self, fld, value):
        self.v["S"] = self.map["S"].field(fld).put(self.v["S"], value)

    def osc_requested(self) -> bool:
        """Something needs the crystal oscillator: OSCERCLK, the MCG's external reference
        (CLKS = 2 or IREFS = 0) or the PLL. Only with C2[EREFS] (a crystal, not a clock)."""
        if not self.f("C2", "EREFS"):
            return False
        return bool(self.chip.osc.field("CR", "ERCLKEN") or self.f("C1", "CLKS") == 2 or
                    not self.f("C1", "IREFS") or self.pll_enabled())

    def ext_ref_running(self) -> bool:
        """The external reference clock runs: the crystal oscillator has started."""
        return self.osc_running

    def pll_enabled(self) -> bool:
        return bool(self.f("C6", "PLLS") or self.f("C5", "PLLCLKEN0"))

    def pll_ref_hz(self):
        return self.chip.crystal_hz / (self.f("C5", "PRDIV0") + 1)

    def pll_hz(self):
        return self.pll_ref_hz() * (self.f("C6", "VDIV0") + 24)

    def pll_in_range(self) -> bool:
        ref, vco = self.pll_ref_hz(), self.pll_hz()
        return PLL_REF_RANGE_HZ[0] <= ref <= PLL_REF_RANGE_HZ[1] and \
            PLL_VCO_RANGE_HZ[0] <= vco <= PLL_VCO_RANGE_HZ[1]

    def _after(self, key, seconds, fn):
        ev = self._pending.pop(key, None)
        if ev:
            ev.cancel()
        self._pending[key] = self.machine.after(seconds, lambda: self._fire(key, fn))

    def _cancel(self, key):
        ev = self._pending.pop(key, None)
        if ev:
            ev.cancel()

    def _fire(self, key, fn):
        """A status change is due: apply it, and any other falling due at the same time, as
        one change (so the recorded modes have no zero-length intermediate states)."""
        self._pending.pop(key, None)
        fn()
        now = self.machine.cycles
        for other, ev in list(self._pending.items()):
            if ev.due <= now and not ev.cancelled:
                ev.cancel()
                self._pending.pop(other)
                self._due_now(other)
        self.update()

    def _due_now(self, key):
        if key == "osc":
            self._osc_started()
        elif key == "lock":
            self._locked()
        else:
            self._apply(key)

    def update(self):
        """Re-evaluate every status bit after a control write or a status change."""
        chip = self.chip
        # crystal oscillator
        if self.osc_requested() and chip.crystal_ok:
            if not self.osc_running and "osc" not in self._pending:
                self._after("osc", CRYSTAL_STARTUP_S, self._osc_started)
        else:
            self._cancel("osc")
            if self.osc_running:
                self.osc_running = False
                self._set_status("OSCINIT0", 0)
        # IREFST follows IREFS (the external reference must run)
        want_irefst = self.f("C1", "IREFS")
        self._follow("IREFST", want_irefst, want_irefst == 1 or self.ext_ref_running())
        # IRCST follows IRCS
        self._follow("IRCST", self.f("C2", "IRCS"), True)
        # PLLST follows PLLS (with the PLL's reference running)
        want_pllst = self.f("C6", "PLLS")
        self._follow("PLLST", want_pllst, want_pllst == 0 or self.ext_ref_running())
        # LOCK0
        if self.pll_enabled() and self.ext_ref_running() and self.pll_in_range():
            if not self.pll_locked and "lock" not in self._pending:
                lock_s = PLL_LOCK_FIXED_S + PLL_LOCK_REF_CYCLES / self.pll_ref_hz()
                self._after("lock", lock_s, self._locked)
        else:
            self._cancel("lock")
            if self.pll_locked:
                self.pll_locked = False
                self._set_status("LOCK0", 0)
        # CLKST follows CLKS
        clks = self.f("C1", "CLKS")
        want_clkst = {0: 3 if self._status("PLLST") else 0, 1: 1, 2: 2, 3: None}[clks]
        if want_clkst is not None:
            self._follow("CLKST", want_clkst, want_clkst != 2 or self.ext_ref_running())
        self._note_mode()
        chip.clocks_changed("MCG")

    def _follow(self, fld, want, possible):
        """Status ``fld`` moves to ``want`` MCG_SYNC_S after the select asked for it, if the
        source it names runs; a select changed meanwhile restarts the synchronisation."""
        self._want[fld] = (want, possible)
        if self._status(fld) == want or not possible:
            self._cancel(fld)
        elif fld not in self._pending or self._pending_want.get(fld) != want:
            self._pending_want[fld] = want
            self._after(fld, MCG_SYNC_S, lambda: self._apply(fld))

    def _apply(self, fld):
        want, possible = self._want[fld]
        if not possible:
            return
        if fld == "CLKST" and want == 3 and not self.pll_locked:
            self._violation("MCGOUTCLK switched to the PLL before LOCK0 was set")
        self._set_status(fld, want)

    def _osc_started(self):
        self.osc_running = True
        self._set_status("OSCINIT0", 1)

    def _locked(self):
        self.pll_locked = True
        self._set_status("LOCK0", 1)

    def _violation(self, text):
        m = self.machine
        self.violations.append((m.instructions_now(), m.now(), text))

    def mode(self) -> str:
        clkst, irefst, pllst = self._status("CLKST"), self._status("IREFST"), self._status("PLLST")
        lp = self.f("C2", "LP")
        if clkst == 0:
            return "FEI" if irefst else "FEE"
        if clkst == 1:
            return "BLPI" if lp else "FBI"
        if clkst == 2:
            if lp:
                return "BLPE"
            return "PBE" if pllst else "FBE"
        return "PEE"

    def _note_mode(self):
        mode = self.mode()
        if mode == self._mode:
            return
        m = self.machine
        if self._mode is not None and mode not in TRANSITIONS[self._mode]:
            self._violation(f"MCG mode {self._mode} -> {mode} is not a transition the state "
                            "diagram allows")
        self._mode = mode
        self.modes.append((m.instructions_now(), m.now(), mode))

    def fll_ref_hz(self) -> float:
        if self._status("IREFST"):
            return SLOW_IRC_HZ
        divs = FRDIV_LOW if self.f("C2", "RANGE") == 0 else FRDIV_HIGH
        return self.chip.crystal_hz / divs[self.f("C1", "FRDIV")]

    def fll_hz(self) -> float:
        return self.fll_ref_hz() * FLL_FACTOR[(self.f("C4", "DMX32"), self.f("C4", "DRST_DRS"))]

    def mcgout_hz(self) -> float:
        clkst = self._status("CLKST")
        if clkst == 0:
            return self.fll_hz()
        if clkst == 1:
            if self._status("IRCST"):
                return FAST_IRC_HZ / (1 << self.f("SC", "FCRDIV"))
            return SLOW_IRC_HZ
        if clkst == 2:
            return self.chip.crystal_hz
        return self.pll_hz()

    def wait_log(self) -> list:
        """The program's accesses to the MCG in order: ('W', register, value) and ('R', 'S',
        value), with consecutive identical reads of S folded into one (count appended)."""
        out = []
        for instr, cycle, kind, reg, value in self.log:
            if out and kind == "R" and out[-1][1] == "R" and out[-1][3] == value:
                out[-1] = out[-1][:4] + (out[-1][4] + 1,)
                continue
            out.append((instr, kind, reg, value, 1))
        return out


def check_tree(tree: ClockTree, sim: Sim) -> list:
    """What the data sheet forbids in a clock tree."""
    bad = []
    for name, limit in LIMITS_HZ.items():
        value = getattr(tree, name)
        if value > limit * (1 + 1e-9):
            bad.append(f"{name} clock {value / 1e6:.3f} MHz is above its {limit / 1e6:g} MHz maximum")
    core_div = sim.field("CLKDIV1", "OUTDIV1") + 1
    for name, fld in (("bus", "OUTDIV2"), ("FlexBus", "OUTDIV3"), ("flash", "OUTDIV4")):
        div = sim.field("CLKDIV1", fld) + 1
        if div % core_div:
            bad.append(f"{name} clock is not an integer divide of the core clock "
                       f"(OUTDIV1 = {core_div - 1}, divider {div})")
    return bad
