"""Command-line options shared by several subcommands."""

from __future__ import annotations

import argparse
import math

__all__ = ["add_firmware_argument", "int_in", "number_in", "finite"]

#: The widest an excitation's cycle counts can be: HQ_EXCITATION carries them as uint16.
MAX_CYCLES = 65535
#: Seeds of the simulator's random generators (numpy: 0 .. 2**32 - 1).
MAX_SEED = 2**32 - 1


def int_in(lo: int, hi: int):
    """An argparse type: an integer in [lo, hi], or a one-line error saying so."""
    def parse(text: str) -> int:
        try:
            value = int(text, 10)
        except ValueError:
            raise argparse.ArgumentTypeError(f"{text!r} is not a whole number") from None
        if not lo <= value <= hi:
            raise argparse.ArgumentTypeError(f"{value} is outside {lo}..{hi}")
        return value
    return parse


def finite(text: str) -> float:
    """An argparse type: a finite number (no nan or inf)."""
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a number") from None
    if not math.isfinite(value):
        raise argparse.ArgumentTypeError(f"{text!r} is not a finite number")
    return value


def number_in(lo: float, hi: float, *, lo_open: bool = False, hi_open: bool = False):
    """An argparse type: a finite number in the interval from lo to hi (open ends as
    given), or a one-line error naming the interval."""
    interval = f"{'(' if lo_open else '['}{lo:g}, {hi:g}{')' if hi_open else ']'}"

    def parse(text: str) -> float:
        value = finite(text)
        if value < lo or value > hi or (lo_open and value == lo) or (hi_open and value == hi):
            raise argparse.ArgumentTypeError(f"{value:g} is outside {interval}")
        return value
    return parse


def add_firmware_argument(p) -> None:
    """--firmware: which firmware flies the simulated rig (sim.lockstep.FIRMWARES)."""
    p.add_argument("--firmware", choices=("host", "teensy35"), default="host",
                   help="host: the firmware's host build (default); teensy35: the Teensy 3.5 "
                        "image itself, run instruction by instruction in the emulated "
                        "MK64FX512 (processor in the loop: slower; the install builds the "
                        "image when the ARM toolchain is present)")
