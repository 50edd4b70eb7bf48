"""Command-line options, and the checks of them, shared by several subcommands."""

from __future__ import annotations

import argparse
import math

import numpy as np

from .errors import InputError

__all__ = ["add_firmware_argument", "add_fault_argument", "faults", "check_plant", "check_excitation",
           "int_in", "number_in", "finite", "MAX_CYCLES", "MAX_SEED"]

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


def add_fault_argument(p, prefix="") -> None:
    p.add_argument("--fault", action="append", default=[], metavar="KIND@T[:D]",
                   help=prefix + "inject a fault at T seconds of simulated time (repeatable): "
                        "silent, nack (for D seconds, or to the end), reset, overflow (the "
                        "MPU6050), link (the host closes its telemetry link); e.g. silent@3:0.5")


def faults(args) -> tuple:
    from ..sim.faults import parse_fault

    return tuple(parse_fault(text) for text in args.fault)


def check_plant(args) -> None:
    if len(args.den) < 2 or args.den[0] == 0 or len(args.num) > len(args.den):
        raise InputError("--den needs a leading non-zero coefficient and a degree at least "
                         "that of --num")
    if not 0 <= args.collective <= 1:
        raise InputError("--collective must be in [0, 1]")
    if not 0 < getattr(args, "loop_hz", 200.0) <= 2000:
        raise InputError("--loop-hz must be in (0, 2000]")
    if getattr(args, "plant", "tf") == "vehicle":
        from ..sim.params import load_params

        load_params(args.params)                       # a bad file fails here, in one line


def check_excitation(freqs_hz, cycles, fade_cycles, loop_hz, amplitude=None, inject=None):
    """Refuse, before anything starts, an excitation the firmware would refuse: the limits
    are the firmware's own defaults (heliquad._firmware.SafetyLimits, the same C++ the
    firmware compiles)."""
    from heliquad import _firmware

    from .link import INJECTIONS

    f32 = lambda x: float(np.float32(x))       # noqa: E731 - the firmware compares in float
    lim = _firmware.SafetyLimits()
    hi = f32(lim.max_freq_fraction * f32(loop_hz))
    for f in freqs_hz:
        if not lim.min_freq_hz <= f32(f) <= hi:
            raise InputError(f"{f:g} Hz is outside the firmware's excitation band "
                             f"[{lim.min_freq_hz:g}, {hi:g}] Hz at a {loop_hz:g} Hz loop")
        duration = (cycles + 2 * fade_cycles) / f
        if duration > lim.max_duration_s:
            raise InputError(f"{cycles} cycles with {fade_cycles} of fade each way at {f:g} Hz "
                             f"last {duration:.0f} s; the firmware allows "
                             f"{lim.max_duration_s:g} s: fewer --cycles")
    if fade_cycles < lim.min_fade_cycles:
        raise InputError(f"--fade-cycles must be at least {lim.min_fade_cycles}")
    if amplitude is not None:
        top = lim.max_amplitude[INJECTIONS[inject]]
        if f32(amplitude) > top:
            unit = {"angle": f"{math.degrees(top):g} deg", "rate": f"{math.degrees(top):g} deg/s",
                    "mixer": f"{top:g}"}[inject]
            raise InputError(f"--amplitude is above the firmware's bound for {inject} "
                             f"injection ({unit})")
