"""The MK64FX512VMD12: a Machine with the peripheral models attached and the clock tree
that connects them."""

from __future__ import annotations

from .clocks import IRC48M_HZ, ClockTree, Mcg, Osc, Sim, check_tree
from .ftfe import Fmc, Ftfe
from .ftm import Ftm
from .i2c import I2c
from .image import Image
from .machine import Machine
from .mpu import SysMpu
from .port import Ports
from .rcm import Rcm
from .scs import Dwt, SystemControlSpace
from .sdhc import Sdhc
from .uart import Uart
from .usb import Usb
from .wdog import Wdog


class Mk64:
    """The chip. ``crystal_hz`` is the crystal on EXTAL0/XTAL0 (16 MHz on the Teensy 3.5);
    ``crystal_ok`` False models a dead or missing crystal (the oscillator never starts)."""

    def __init__(self, image: Image | str | None = None, *, crystal_hz: float = 16e6,
                 crystal_ok: bool = True, uid: tuple | None = None):
        if isinstance(image, (str, bytes)) or hasattr(image, "__fspath__"):
            image = Image(image)
        self._tree = None
        self.crystal_hz = crystal_hz
        self.crystal_ok = crystal_ok
        self.ready = False
        self._notes = []                # (instruction count, text): documented misuse
        self.clock_history = []         # (instruction count, cycle, ClockTree)
        self.clock_violations = []      # (instruction count, cycle, text)
        m = self.machine = Machine()
        self.scs = m.attach(SystemControlSpace(m))
        self.dwt = m.dwt = m.attach(Dwt(m, self.scs))
        self.sim = m.attach(Sim(m, self))
        if uid is not None:                  # this chip's own (UIDH, UIDMH, UIDML, UIDL)
            self.sim.UID = dict(zip(("UIDH", "UIDMH", "UIDML", "UIDL"), uid))
            self.sim.reset()
        self.osc = m.attach(Osc(m, self))
        self.mcg = m.attach(Mcg(m, self))
        self.wdog = m.attach(Wdog(m, self))
        self.rcm = m.attach(Rcm(m))
        self.ports = Ports(m, self.sim)
        self.i2c0 = m.attach(I2c(m, self, 0))
        self.uart0 = m.attach(Uart(m, self, 0))
        self.ftm0 = m.attach(Ftm(m, self, 0, ("SCGC6", "FTM0")))
        self.ftm3 = m.attach(Ftm(m, self, 3, ("SCGC3", "FTM3")))
        self.ftfe = m.attach(Ftfe(m, self))
        self.fmc = m.attach(Fmc(m, self))
        self.mpu = m.attach(SysMpu(m, self))
        self.usb0 = m.attach(Usb(m, self))
        self.sdhc = m.attach(Sdhc(m, self))
        m.pre_reset_listeners.append(self._before_reset)
        m.reset_listeners.append(self._on_reset)
        self.ready = True
        if image is not None:
            m.load(image)
        else:
            m.reset()

    @property
    def image(self) -> Image:
        return self.machine.image

    def _before_reset(self):
        self._tree = None

    def _on_reset(self):
        self._notes = []
        self.gates_changed()
        self.usb0.mpu_changed()
        self.clock_history = []
        self.clock_violations = []
        self._tree = None
        self.clocks_changed("reset")

    # -- clocks ------------------------------------------------------------------------------
    def tree(self) -> ClockTree:
        mcg, sim = self.mcg, self.sim
        mcgout = mcg.mcgout_hz()
        div = {f: sim.field("CLKDIV1", f) + 1 for f in ("OUTDIV1", "OUTDIV2", "OUTDIV3", "OUTDIV4")}
        core, bus = mcgout / div["OUTDIV1"], mcgout / div["OUTDIV2"]
        flexbus, flash = mcgout / div["OUTDIV3"], mcgout / div["OUTDIV4"]
        pll = mcg.pll_hz() if mcg.pll_enabled() and mcg.pll_locked else None
        fll = mcg.fll_hz()
        usb = None
        if sim.field("SOPT2", "USBSRC"):            # the PLL/FLL/IRC48M select, divided
            src = {0: fll, 1: pll, 3: IRC48M_HZ}.get(sim.field("SOPT2", "PLLFLLSEL"))
            if src:
                usb = src * (sim.field("CLKDIV2", "USBFRAC") + 1) / \
                    (sim.field("CLKDIV2", "USBDIV") + 1)
        oscer = self.crystal_hz if mcg.osc_running and self.osc.field("CR", "ERCLKEN") else None
        return ClockTree(mcg.mode(), mcgout, core, bus, flexbus, flash, usb, pll, fll, oscer)

    def core_hz(self) -> float:
        return self._tree.core if self._tree else self.tree().core

    def bus_hz(self) -> float:
        return self._tree.bus if self._tree else self.tree().bus

    def usb_hz(self) -> float | None:
        """The USB module's clock (None: no source selected)."""
        return self._tree.usb if self._tree else self.tree().usb

    def fixed_hz(self) -> float:
        return self.mcg.fll_ref_hz()

    def clocks_changed(self, cause: str):
        if not self.ready:
            return
        tree = self.tree()
        if tree == getattr(self, "_tree", None):
            return
        self._tree = tree
        m = self.machine
        at = (m.instructions_now(), m.now())
        self.clock_history.append(at + (tree,))
        for text in check_tree(tree, self.sim):
            self.clock_violations.append(at + (f"{text} (after {cause})",))
        m.core.fixed_hz = self.fixed_hz()           # MCGFFCLK, for the FTMs
        self.usb0.clocks_changed()
        m.set_clocks(tree.core, tree.bus)

    def gates_changed(self):
        """A SIM clock gate may have changed: the native models take accesses only while
        clocked (a gated access goes to Python, which faults)."""
        if not self.ready:
            return
        core = self.machine.core
        for dev in (self.uart0, self.i2c0, self.ftm0, self.ftm3, self.wdog, self.ftfe, self.usb0):
            core.set_clocked(dev.device, dev.clocked())

    @property
    def notes(self) -> list:
        """(instruction count, text): documented misuse the models saw."""
        if self.ready:
            self._notes.extend(self.uart0.take_notes())
        return self._notes

    def note(self, text: str):
        self._notes.append((self.machine.instructions_now(), text))

    # -- running -----------------------------------------------------------------------------
    def run(self, instructions=None, seconds=None):
        return self.machine.run(instructions=instructions, seconds=seconds)

    def reset(self):
        self.machine.reset()
