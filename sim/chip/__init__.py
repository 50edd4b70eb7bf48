"""An emulated NXP MK64FX512 (the Teensy 3.5's Cortex-M4F) for running the firmware image
without a board: a CPU executes the instructions (the engine's own interpreter, or unicorn:
cpu.py); this package supplies the memory map,
a deterministic time base, the exception model and register-level models of the
peripherals the image's boot and main loop use. See docs/teensy35-emulator.md.

    from heliquad.sim.chip import Teensy35
    board = Teensy35("build/teensy35/heliquad-fw-teensy35.elf")
    stop = board.run_to_loop(1, instructions=50_000_000)
"""

from .clocks import ClockTree
from .image import Image, ImageError, Symbol, exception_name
from .machine import ChipReset, EmulationError, Fault, Machine, Stop
from .mk64 import Mk64
from .teensy35 import Teensy35

__all__ = ["Mk64", "ClockTree", "Image", "ImageError", "Symbol", "exception_name", "ChipReset",
           "EmulationError", "Fault", "Machine", "Stop", "Teensy35"]
