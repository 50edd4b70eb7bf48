"""The Teensy 3.5 board around the chip, as the heliquad firmware uses it: a 16 MHz crystal,
the MPU6050 on I2C0 (pins 18/19, with the breakout board's pull-ups), eight ESC outputs on
FTM0, seven RC inputs on FTM3, telemetry on UART0 (pins 0/1), the status LED on pin 13 and the
microSD socket on the SDHC (PTE0-5), with a card when ``sd_image`` names a card-image file.

:class:`Teensy35` runs a firmware image on it and knows the image's symbol contract: the
fatal path ``hq_fatal(code)`` stops a run with reason ``fatal`` and the code, and
``hq::FlightController::step`` marks the main loop.
"""

from __future__ import annotations

import os
from dataclasses import dataclass

from heliquad._firmware import Mpu6050Emulator

from .i2c import Mpu6050Slave
from .machine import Stop
from .mk64 import Mk64
from .sd_card import SdCard

# Teensy 3.5 pin number -> (port, bit) for the pins the firmware uses (PJRC's pin table).
PINS = {0: ("B", 16), 1: ("B", 17), 2: ("D", 0), 5: ("D", 7), 6: ("D", 4), 7: ("D", 2),
        8: ("D", 3), 9: ("C", 3), 10: ("C", 4), 13: ("C", 5), 14: ("D", 1), 18: ("B", 3),
        19: ("B", 2), 20: ("D", 5), 21: ("D", 6), 22: ("C", 1), 23: ("C", 2), 35: ("C", 8),
        36: ("C", 9), 37: ("C", 10)}
# K64 signal multiplexing (data sheet, "K64 Signal Multiplexing and Pin Assignments"):
# (port, bit, MUX) -> signal, for those pins.
SIGNALS = {
    ("B", 2, 2): "I2C0_SCL", ("B", 3, 2): "I2C0_SDA",
    ("B", 16, 3): "UART0_RX", ("B", 17, 3): "UART0_TX",
    ("C", 1, 4): "FTM0_CH0", ("C", 2, 4): "FTM0_CH1", ("C", 3, 4): "FTM0_CH2",
    ("C", 4, 4): "FTM0_CH3", ("D", 4, 4): "FTM0_CH4", ("D", 5, 4): "FTM0_CH5",
    ("D", 6, 4): "FTM0_CH6", ("D", 7, 4): "FTM0_CH7",
    ("D", 0, 4): "FTM3_CH0", ("D", 1, 4): "FTM3_CH1", ("D", 2, 4): "FTM3_CH2",
    ("D", 3, 4): "FTM3_CH3", ("C", 8, 3): "FTM3_CH4", ("C", 9, 3): "FTM3_CH5",
    ("C", 10, 3): "FTM3_CH6",
}
I2C_PINS = {"SDA": 18, "SCL": 19}
UART_PINS = {"RX": 0, "TX": 1}
ESC_PINS = (22, 23, 9, 10, 6, 20, 21, 5)     # FTM0 channels 0..7, rotor i on channel i
RC_PINS = (2, 14, 7, 8, 35, 36, 37)     # FTM3 channels 0..6
LED_PIN = 13
CRYSTAL_HZ = 16e6
MPU6050_ADDRESS = 0x68

FATAL_SYMBOL = "hq_fatal"
STEP_SYMBOL = "hq::FlightController::step"
#: The parameter storage's flash sectors, [start, end) (the linker script's symbols).
PARAM_FLASH_SYMBOLS = ("hq_param_flash_start", "hq_param_flash_end")
#: The on-board program's two sectors, below the parameters' (mk64fx512.ld).
PROGRAM_FLASH_SYMBOLS = ("hq_program_flash_start", "hq_program_flash_end")
#: The image's stored records in flash: which sectors (their symbols) keep what.
STORED_SECTORS = {"parameters": PARAM_FLASH_SYMBOLS, "program": PROGRAM_FLASH_SYMBOLS}


def signal(letter: str, bit: int, mux: int):
    if mux == 1:
        return f"PT{letter}{bit}"
    return SIGNALS.get((letter, bit, mux))


@dataclass
class PinState:
    pin: int
    port: str
    bit: int
    mux: int
    signal: str | None
    open_drain: bool
    pcr: int


class Teensy35:
    """A Teensy 3.5 running ``image`` (an Image or an ELF path). ``crystal_ok`` False: a
    dead crystal. ``mpu6050``: the ``heliquad._firmware.Mpu6050Emulator`` on I2C0 (a new
    one if None); ``with_mpu6050=False`` leaves the bus empty (every address NACKs).
    ``track_loops=False`` does not stop at each FlightController::step entry to count the
    loops (``loops``, ``loop_starts``, :meth:`run_to_loop`): a long lockstep run that finds
    its loop boundary itself saves that call into Python at every loop. ``sd_image``: a
    card-image file for the microSD socket (``sd_card.py``; a missing file: no card)."""

    def __init__(self, image, *, crystal_ok: bool = True, mpu6050=None, with_mpu6050=True,
                 track_loops: bool = True, uid: tuple | None = None, sd_image=None):
        self.chip = Mk64(image, crystal_hz=CRYSTAL_HZ, crystal_ok=crystal_ok, uid=uid)
        self.machine = self.chip.machine
        # The microSD socket: a card backed by sd_image if that file exists, else empty.
        self.sd_card = SdCard(sd_image) if sd_image is not None and \
            os.path.exists(sd_image) else None
        self.chip.sdhc.insert(self.sd_card)
        self.mpu = None
        if with_mpu6050:
            if mpu6050 is None:
                mpu6050 = Mpu6050Emulator()
            self.mpu = Mpu6050Slave(mpu6050, self.machine, MPU6050_ADDRESS)
            self.chip.i2c0.slaves.append(self.mpu)
        self.chip.i2c0.pins_connected = self._i2c_pins_connected
        for pin in I2C_PINS.values():               # the breakout board's pull-ups
            self.chip.ports.set_pull(*PINS[pin], 1)
        self.chip.ports.edge_listeners.append(self._pin_edge)
        self.chip.ports.listeners.append(self._pin_muxed)
        self._clear()
        self._loop_limit = None
        image = self.machine.image
        if image.has(FATAL_SYMBOL):
            self.machine.break_at(FATAL_SYMBOL, self._on_fatal)
        if track_loops and image.has(STEP_SYMBOL):
            self.machine.break_at(STEP_SYMBOL, self._on_step)

    def _clear(self):
        self.esc_first_edges = {}   # ESC pin -> (seconds, FTM0 period, pulse) when first muxed
        self.fatal_code = None
        self.loops = 0
        self.loop_starts = []       # (instruction count, cycle) at each step() entry

    def reset(self):
        """The chip's power-on reset (the MPU6050 keeps its state, as a separate chip)."""
        self.machine.reset()
        self._clear()

    # -- the image's contract -----------------------------------------------------------------
    def _on_fatal(self, m):
        self.fatal_code = m.reg("r0")
        return Stop("fatal", m.pc, {"code": self.fatal_code})

    def _on_step(self, m):
        self.loops += 1
        self.loop_starts.append((m.instructions_now(), m.now()))
        if self._loop_limit is not None and self.loops >= self._loop_limit:
            return Stop("loop", m.pc, {"loops": self.loops})
        return None

    def run_to_loop(self, n: int = 1, *, instructions: int) -> Stop:
        """Run until the main loop has entered FlightController::step ``n`` times in all
        (stops at that entry), within an instruction budget."""
        self._loop_limit = n
        try:
            return self.machine.run(instructions=instructions)
        finally:
            self._loop_limit = None

    def run(self, instructions=None, seconds=None) -> Stop:
        return self.machine.run(instructions=instructions, seconds=seconds)

    # -- the stored records' flash --------------------------------------------------------------
    def stored_range(self, what: str = "parameters") -> tuple:
        """[start, end) of the image's sectors keeping ``what`` (STORED_SECTORS: "parameters"
        or "program"); KeyError for an image without them (one older than that storage)."""
        image = self.machine.image
        start, end = (image.symbol(name).address for name in STORED_SECTORS[what])
        return start, end

    def read_stored(self, what: str = "parameters") -> bytes:
        """Those sectors' bytes as the flash holds them now."""
        start, end = self.stored_range(what)
        return self.machine.read(start, end - start)

    def write_stored(self, data: bytes, what: str = "parameters"):
        """Set those sectors' bytes (all of them) as a debug probe would; the program itself
        can change them only through the flash module."""
        start, end = self.stored_range(what)
        if len(data) != end - start:
            raise ValueError(f"{len(data)} bytes for {end - start} bytes of {what} flash")
        self.machine.write(start, bytes(data))

    def param_flash_range(self) -> tuple:
        """[start, end) of the parameter sectors (:meth:`stored_range`)."""
        return self.stored_range("parameters")

    def read_param_flash(self) -> bytes:
        return self.read_stored("parameters")

    def write_param_flash(self, data: bytes):
        self.write_stored(data, "parameters")

    # -- board wiring ---------------------------------------------------------------------------
    def _i2c_pins_connected(self) -> bool:
        ports = self.chip.ports
        return all(ports.mux(*PINS[p]) == 2 for p in I2C_PINS.values())

    def _pin_edge(self, letter, bit, level):
        sig = signal(letter, bit, self.chip.ports.mux(letter, bit))
        if sig and sig.startswith("FTM3_CH"):
            self.chip.ftm3.edge(int(sig[-1]), bool(level))

    def _pin_muxed(self, letter, bit):
        """What an ESC sees from the moment its pin is switched to FTM0."""
        sig = signal(letter, bit, self.chip.ports.mux(letter, bit))
        if not sig or not sig.startswith("FTM0_CH"):
            return
        number = next(p for p, lb in PINS.items() if lb == (letter, bit))
        if number not in self.esc_first_edges:
            ch, ftm = int(sig[-1]), self.chip.ftm0
            self.esc_first_edges[number] = (self.machine.seconds(), ftm.period_s(),
                                            ftm.pulse_s(ch))

    def pin(self, number: int) -> PinState:
        letter, bit = PINS[number]
        ports = self.chip.ports
        pcr = ports.pcr(letter, bit)
        mux = (pcr >> 8) & 7
        return PinState(number, letter, bit, mux, signal(letter, bit, mux), bool(pcr & 0x20), pcr)

    def led(self) -> int:
        return self.chip.ports.level(*PINS[LED_PIN])

    def led_changes(self) -> list:
        """(seconds, level) of every change of the LED pin."""
        letter, bit = PINS[LED_PIN]
        m = self.machine
        return [(m.seconds(c), lvl) for c, l_, b, lvl in self.chip.ports.level_log
                if (l_, b) == (letter, bit)]

    def esc_outputs(self) -> list:
        """Per ESC pin: (pin, signal on it, PWM period in s, pulse width in s)."""
        out = []
        ftm = self.chip.ftm0
        for ch, number in enumerate(ESC_PINS):
            p = self.pin(number)
            on_ftm = p.signal == f"FTM0_CH{ch}"
            out.append((number, p.signal, ftm.period_s() if on_ftm else None,
                        ftm.pulse_s(ch) if on_ftm else None))
        return out

    def rc_pulse(self, channel: int, width_s: float):
        """A PWM pulse of ``width_s`` on RC input ``channel`` (0..6), starting now."""
        letter, bit = PINS[RC_PINS[channel]]
        ports, m = self.chip.ports, self.machine
        ports.drive(letter, bit, 1)
        m.after(width_s, lambda: ports.drive(letter, bit, 0))

    def rc_capture_pulse(self, channel: int, us: int):
        """A servo pulse on RC input ``channel`` (0..6) that FTM3 captures as ``us`` whole
        microseconds: it rises on the next count of the running counter and lasts
        ceil(us x counts per microsecond) counts, so a capture that truncates counts to
        microseconds reads exactly ``us``. Nothing happens while FTM3 does not count."""
        self.rc_capture_pulses({channel: us})

    def rc_capture_pulses(self, widths: dict):
        """Pulses as :meth:`rc_capture_pulse` makes them, on several channels at once
        ({channel: us}), as a receiver's frame sends them: all rise on the same count, and
        the pins whose pulses end on the same count fall together (one event per edge time,
        not per pin). The native core drives them (no call into Python at the edges) when
        every pin is low and on its FTM3 channel and nothing else listens to the pins'
        edges; the pin model's own view of those pins then stays low through the pulses
        (PDIR, read by the program, has them)."""
        ftm, ports, m = self.chip.ftm3, self.chip.ports, self.machine
        rise = ftm.next_tick(m.now())
        if rise is None or not widths:
            return
        hz, per_tick = round(ftm.clock_hz()), ftm.cycles_per_tick()
        pins = {ch: PINS[RC_PINS[ch]] for ch in widths}
        falls = {}
        for ch, us in widths.items():
            counts = -(-us * hz // 1_000_000)
            falls.setdefault(ftm.next_tick(rise + int(counts * per_tick)), []).append(ch)
        native = self.native_pins(pins)
        if native is not None:
            m.core.pin_edge(rise, True, list(native.values()))
            for fall, group in falls.items():
                m.core.pin_edge(fall, False, [native[ch] for ch in group])
            return
        falls = {fall: [pins[ch] for ch in group] for fall, group in falls.items()}

        def drive(group, level):
            for letter, bit in group:
                ports.drive(letter, bit, level)

        m.at(rise, lambda: drive(pins.values(), 1), scaled=False)
        for fall, group in falls.items():
            m.at(fall, lambda group=group: drive(group, 0), scaled=False)

    def native_pins(self, pins: dict, *, driven_only: bool = False):
        """{channel: (PDIR address, bit, FTM3 channel)} for Mk64Core.pin_edge when the core
        can drive these pins' pulses (each low and muxed to an FTM3 channel, no listener to
        their edges but the capture's), else None; each pin is then held low from outside
        (its level after the pulse about to be made: no change). ``driven_only``: a table
        for pulses to come (PilFrames), of only the pins an outside driver already holds
        low (a pulse has ended there), the others left out and nothing changed."""
        ports = self.chip.ports
        if ports.edge_listeners != [self._pin_edge]:
            return None
        out = {}
        for ch, (letter, bit) in pins.items():
            sig = signal(letter, bit, ports.mux(letter, bit))
            usable = bool(sig) and sig.startswith("FTM3_CH") and not ports.level(letter, bit)
            if driven_only and (not usable or ports.external.get((letter, bit)) != 0):
                continue
            if not usable:
                return None
            out[ch] = (ports.gpio[letter].pdir_address, bit, int(sig[-1]))
        if not driven_only:
            for letter, bit in pins.values():
                ports.external[(letter, bit)] = 0
        return out

    def telemetry(self) -> bytes:
        """What has left UART0's TX pin since reset (or since the last take_telemetry())."""
        return self.chip.uart0.sent_bytes()

    def take_telemetry(self) -> bytes:
        """The bytes that left UART0's TX pin since the last call (or reset), forgotten by the
        emulator: a long run keeps none of them."""
        return self.chip.uart0.take_sent()

    def receive(self, data: bytes):
        """Bytes for the board's UART0 RX pin (the telemetry link's uplink), arriving back to
        back at the configured baud rate from now on."""
        self.chip.uart0.receive(data)
