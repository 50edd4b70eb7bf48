"""Pin control (PORTA-E) and general-purpose I/O (GPIOA-E).

PORTx_PCRn holds each pin's multiplexer (MUX: 0 disabled/analog, 1 GPIO, 2-7 the
peripheral functions of the data sheet's signal multiplexing table) and its electrical
settings (pull, slew rate, open drain, drive strength); LK locks the low half until reset;
ISF is write-1-to-clear. GPCLR/GPCHR write one value to several PCRs. Every change of a
pin's PCR is logged with its time.

GPIO: PDOR/PSOR/PCOR/PTOR/PDDR/PDIR. A pin's level is the GPIO output when MUX = 1 and its
PDDR bit is set (an open-drain output only pulls low), otherwise what drives it from outside
(:meth:`Ports.drive`), or its pull resistor, or 0. Level changes of output pins are logged
(the status LED's blink pattern is readable from it).

The model is here; the native core serves reads of PDIR from the word this model gives it
(:meth:`Ports.publish`) whenever a pin's level may have changed (a PCR, a GPIO output or
direction, an outside driver, a pull), so an interrupt handler reading a pin costs no call
into Python.
"""

from __future__ import annotations

from .machine import GPIO_IN_DEVICE, GPIO_OUT_DEVICE
from .peripheral import RegisterDevice

PORT_NAMES = "ABCDE"
MUX = (8, 3)


class Port(RegisterDevice):
    def __init__(self, machine, ports, letter, sim):
        self.ports, self.letter = ports, letter
        super().__init__(machine, f"PORT{letter}", gate=(sim, "SCGC5", f"PORT{letter}"),
                         span=0xA4)

    def reset(self):
        super().reset()
        self._digital = None

    def _set_pcr(self, n, value, mask):
        name = f"PCR{n}"
        old = self.v[name]
        if old & (1 << 15):                         # LK: bits 15:0 locked until reset
            value = (value & ~0xFFFF) | (old & 0xFFFF)
        isf = old & (1 << 24) & ~value              # ISF: write 1 to clear
        new = (value & 0x000F_8777) | isf
        self.v[name] = new
        if (new ^ old) & (7 << 8):
            self._digital = None
        if new != old:
            m = self.machine
            self.ports.log.append((m.instructions_now(), m.now(), self.letter, n, new))
            self.ports.publish(self.letter)
            self.ports.pin_changed(self.letter, n)

    def write(self, address, size, value):
        offset = address - self.base
        if offset < 0x80:
            reg = self._reg_for(offset, size, True)
            n = reg.offset // 4
            shift = 8 * (offset - reg.offset)
            mask = ((1 << (8 * size)) - 1) << shift
            merged = (self.v[reg.name] & ~mask) | ((value << shift) & mask)
            self._set_pcr(n, merged, mask)
            return
        super().write(address, size, value)

    def _global(self, first, value):
        data, enable = value & 0xFFFF, value >> 16
        for i in range(16):
            if enable & (1 << i):
                n = first + i
                self._set_pcr(n, (self.v[f"PCR{n}"] & ~0xFFFF) | data, 0xFFFF)

    def w_GPCLR(self, value, mask):
        self._global(0, value)

    def w_GPCHR(self, value, mask):
        self._global(16, value)

    def r_GPCLR(self):
        return 0

    def r_GPCHR(self):
        return 0

    def r_ISFR(self):
        return sum(1 << n for n in range(32) if self.v[f"PCR{n}"] & (1 << 24))

    def w_ISFR(self, value, mask):
        for n in range(32):
            if value & (1 << n):
                self.v[f"PCR{n}"] &= ~(1 << 24)

    def mux(self, n) -> int:
        return (self.v[f"PCR{n}"] >> 8) & 7

    def digital_pins(self) -> tuple:
        """The pins with a digital function (MUX != 0): the only ones PDIR can read as 1.
        Cached until a PCR's MUX changes (PDIR is read in interrupt handlers)."""
        if self._digital is None:
            self._digital = tuple(n for n in range(32) if self.mux(n))
        return self._digital


class Gpio(RegisterDevice):
    READ_ONLY = ("PDIR",)

    def __init__(self, machine, ports, letter):
        self.ports, self.letter = ports, letter
        super().__init__(machine, f"GPIO{letter}", span=0x18)
        self.pdir_address = self.base + self.map["PDIR"].offset
        machine.core.add_route(GPIO_IN_DEVICE, self.pdir_address, self.pdir_address + 4)
        # A write to PDOR, PSOR, PCOR or PTOR that leaves PDOR as it is: taken natively
        # (nothing to do), from the copy of PDOR kept there (_output, reset).
        machine.core.add_route(GPIO_OUT_DEVICE, self.base, self.base + 0x10)

    def reset(self):
        super().reset()
        self.machine.core.set_gpio_output(self.base, self.v["PDOR"])

    def r_PDIR(self):
        """PDIR as the program reads it: the native core's word (which has the levels of
        pins it drives itself, Teensy35.rc_capture_pulses), once the pins are published."""
        native = self.machine.core.dev_read(GPIO_IN_DEVICE, self.pdir_address, 4)
        return self.pins_word() if native is None else native

    def pins_word(self):
        """The input word from the pin model's levels."""
        ports, letter = self.ports, self.letter
        return sum(ports.level(letter, n) << n for n in ports.port[letter].digital_pins())

    def r_PSOR(self):
        return 0

    def r_PCOR(self):
        return 0

    def r_PTOR(self):
        return 0

    def _levels(self, changed):
        """The levels of the pins whose output or direction bits are in ``changed``: the
        only ones a GPIO write can move."""
        level, letter = self.ports.level, self.letter
        return {n: level(letter, n) for n in range(32) if changed >> n & 1}

    def _output(self, pdor):
        pdor &= 0xFFFF_FFFF
        before = self._levels(self.v["PDOR"] ^ pdor)
        self.v["PDOR"] = pdor
        self.machine.core.set_gpio_output(self.base, pdor)
        self.ports.outputs_changed(self.letter, before)
        self.ports.publish(self.letter, before)

    def w_PDOR(self, value, mask):
        self._output(value)

    def w_PSOR(self, value, mask):
        self._output(self.v["PDOR"] | value)

    def w_PCOR(self, value, mask):
        self._output(self.v["PDOR"] & ~value)

    def w_PTOR(self, value, mask):
        self._output(self.v["PDOR"] ^ value)

    def w_PDDR(self, value, mask):
        before = self._levels(self.v["PDDR"] ^ value)
        self.v["PDDR"] = value
        self.ports.outputs_changed(self.letter, before)
        self.ports.publish(self.letter, before)


class Ports:
    """All five ports and their GPIO, with the pins' external world."""

    def __init__(self, machine, sim):
        self.machine = machine
        self.port = {c: machine.attach(Port(machine, self, c, sim)) for c in PORT_NAMES}
        self.gpio = {c: machine.attach(Gpio(machine, self, c)) for c in PORT_NAMES}
        self.external = {}          # (letter, n) -> level driven from outside
        self.pulls = {}             # (letter, n) -> level of an external pull resistor
        self.listeners = []         # fn(letter, n) on a PCR change
        self.edge_listeners = []    # fn(letter, n, level) on an input level change
        self.log = []               # (instruction count, cycle, letter, n, PCR)
        self.level_log = []         # (cycle, letter, n, level) of GPIO outputs
        self._published = {}        # letter -> the PDIR word the native core holds
        machine.reset_listeners.append(self.reset)

    def reset(self):
        self.log.clear()
        self.level_log.clear()
        self.external.clear()
        self._published.clear()
        for letter in PORT_NAMES:
            self.publish(letter)

    def publish(self, letter, pins=None):
        """Give the native core the port's input word (PDIR as a read would return it):
        recomputed whole, or only for ``pins`` (an iterable of pin numbers) when only their
        levels can have changed."""
        gpio = self.gpio[letter]
        if pins is None or letter not in self._published:
            word = gpio.pins_word()
        else:
            word = self._published[letter]
            digital = self.port[letter].digital_pins()
            for n in pins:
                bit = 1 << n
                word = (word | bit) if n in digital and self.level(letter, n) else (word & ~bit)
        if self._published.get(letter) != word:
            self._published[letter] = word
            self.machine.core.set_gpio_input(gpio.pdir_address, word)

    def set_pull(self, letter, n, level):
        """An external pull resistor on a pin (None: none)."""
        if level is None:
            self.pulls.pop((letter, n), None)
        else:
            self.pulls[(letter, n)] = int(bool(level))
        self.publish(letter)

    def pcr(self, letter, n) -> int:
        return self.port[letter].v[f"PCR{n}"]

    def mux(self, letter, n) -> int:
        return self.port[letter].mux(n)

    def level(self, letter, n) -> int:
        """The pin's level as PDIR reads it: 0 unless the pin has a digital function
        (MUX != 0); a GPIO output drives it; else an outside driver, a pull, or 0."""
        gpio = self.gpio[letter]
        pcr = self.pcr(letter, n)
        if (pcr >> 8) & 7 == 0:
            return 0
        if (pcr >> 8) & 7 == 1 and gpio.v["PDDR"] & (1 << n):
            out = (gpio.v["PDOR"] >> n) & 1
            if not (pcr & (1 << 5)) or out == 0:    # open drain only pulls low
                return out
        if (letter, n) in self.external:
            return self.external[(letter, n)]
        if (letter, n) in self.pulls:
            return self.pulls[(letter, n)]
        if pcr & 2:                                  # PE: internal pull, PS selects up
            return pcr & 1
        return 0

    def pin_changed(self, letter, n):
        for fn in self.listeners:
            fn(letter, n)

    def outputs_changed(self, letter, before):
        m = self.machine
        for n, old in before.items():
            new = self.level(letter, n)
            if new != old:
                self.level_log.append((m.now(), letter, n, new))

    def drive(self, letter, n, level):
        """Drive a pin from outside (None: release it)."""
        old = self.level(letter, n)
        if level is None:
            self.external.pop((letter, n), None)
        else:
            self.external[(letter, n)] = int(bool(level))
        new = self.level(letter, n)
        if new != old:
            self.publish(letter, (n,))
            for fn in self.edge_listeners:
                fn(letter, n, new)

    def describe(self, letter, n) -> dict:
        pcr = self.pcr(letter, n)
        return {"mux": (pcr >> 8) & 7, "pull_enable": bool(pcr & 2), "pull_up": bool(pcr & 1),
                "slew_slow": bool(pcr & 4), "filter": bool(pcr & 0x10),
                "open_drain": bool(pcr & 0x20), "drive_high": bool(pcr & 0x40),
                "locked": bool(pcr & 0x8000), "irqc": (pcr >> 16) & 0xF}
