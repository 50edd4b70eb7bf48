"""Command-line options, and the checks of them, shared by several subcommands."""

from __future__ import annotations

import argparse
import math
import os

import numpy as np

from ...sim.base import firmware_facts as facts
from ...sim.base.errors import InputError
from ...sim.rig.setup import BOARD_LINKS, DEFAULT_BOARD_LINK
from ..acquire.connection import CONNECTION_HELP
from ..acquire.link import DEFAULT_BAUD

__all__ = ["add_port_argument", "add_baud_argument", "add_board_actions", "require_port", "add_firmware_argument", "firmware_link", "add_param_store_argument",
           "add_sd_card_arguments", "sd_card",
           "add_fault_argument", "faults",
           "check_plant", "check_model", "vehicle_config", "transfer_function",
           "int_in", "number_in", "finite", "MAX_CYCLES", "MAX_SEED"]

#: The widest an excitation's cycle counts can be: HQ_EXCITATION carries them as uint16.
MAX_CYCLES = 65535
#: Seeds of the simulator's random generators (numpy: 0 .. 2**32 - 1).
MAX_SEED = 2**32 - 1
#: The highest degree of a plant or model (as of the fit's orders).
MAX_DEGREE = 12
#: A coefficient (den made monic) beyond this: the polynomial's roots drown in round-off.
MAX_COEFFICIENT = 1e30
#: A simulated plant's gain, rad/s per unit torque command: the median of |G(j omega)| over
#: 0.01 rad/s to the loop's Nyquist rate. Beyond it nothing a gyro measures is left to see.
PLANT_GAIN_RANGE = (1e-6, 1e6)
#: A model to validate: poles and zeros up to this, rad/s, and its gain (the median of
#: |G(j omega)| over 0.01..1e4 rad/s) in the range POINTS.csv's magnitudes may take.
MODEL_RATE_MAX = 1e6
MODEL_GAIN_RANGE = (1e-12, 1e12)


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


def _param_store(path: str) -> str:
    """A parameter store's path: a file (or none yet) in a folder that exists."""
    if os.path.isdir(path):
        raise argparse.ArgumentTypeError(f"{path} is a folder, not a parameter store file")
    if os.path.exists(path) and not os.path.isfile(path):
        raise argparse.ArgumentTypeError(f"{path} is not a regular file")
    folder = os.path.dirname(os.path.abspath(path))
    if not os.path.isdir(folder):
        raise argparse.ArgumentTypeError(f"folder {folder} does not exist")
    return path


def add_param_store_argument(p) -> None:
    """--param-store FILE: where the simulated board keeps its firmware parameters."""
    p.add_argument("--param-store", metavar="FILE", type=_param_store,
                   help="keep the firmware's parameters (docs/parameters.md) in FILE across runs, "
                        "as a board keeps them in its flash: read at start, written at each save "
                        "(default: every run starts with the defaults and nothing is saved)")


def _sd_image(path: str) -> str:
    """A card image's path: a file (or none yet: the firmware makes it) in a folder that
    exists."""
    if os.path.isdir(path):
        raise argparse.ArgumentTypeError(f"{path} is a folder, not a card image")
    folder = os.path.dirname(os.path.abspath(path))
    if not os.path.isdir(folder):
        raise argparse.ArgumentTypeError(f"folder {folder} does not exist")
    return path


def _sd_faults(text: str) -> str:
    """The host build's card faults, ``NAME=VALUE,...`` (a name alone is 1), each name
    checked by the firmware's own reading of them (its bindings)."""
    # the firmware's bindings, imported only when a fault is given
    from heliquad import _firmware

    card = _firmware.CardFiles(os.devnull)       # never mounted: its faults' names only
    for item in text.split(","):
        name, eq, value = item.partition("=")
        if not name or (eq and not value.isdigit()):
            raise argparse.ArgumentTypeError(f"{item!r} is not NAME or NAME=N (N a whole "
                                             "number)")
        number = int(value) if eq else 1
        if number >= 1 << 64:
            raise argparse.ArgumentTypeError(f"{item!r}: {name} is at most {(1 << 64) - 1}")
        try:
            card.set_faults(**{name: number})
        except ValueError:
            raise argparse.ArgumentTypeError(f"no card fault {name!r} (docs/sd-card.md)") \
                from None
    return text


def add_sd_card_arguments(p, prefix: str = "") -> None:
    """--sd-image FILE and --sd-faults: the simulated board's SD card."""
    p.add_argument("--sd-image", metavar="FILE", type=_sd_image,
                   help=prefix + "the board's SD card, a card-image file (heliquad sd-image; "
                        "a missing FILE is made at the default size): it logs each arming "
                        "there (LOGS/00000001.BIN ...) and serves those logs (heliquad logs; "
                        "docs/sd-card.md); default: no card")
    p.add_argument("--sd-faults", metavar="NAME=VALUE,...", type=_sd_faults,
                   help=prefix + "the card's faults, host firmware only: no_card, "
                        "write_protected, writable_blocks=N, failing_writes, "
                        "busy_after_write_us=T, busy_every_us=P with busy_for_us=T, "
                        "power_cut_after_writes=N (docs/sd-card.md)")


def sd_card(args) -> dict:
    """The SD card's options for the rig (``sd_image``, ``sd_faults``), their combinations
    checked."""
    if args.sd_faults and args.sd_image is None:
        raise InputError("--sd-faults needs --sd-image")
    if args.sd_faults and args.firmware != "host":
        raise InputError("--sd-faults: only the host firmware's card takes faults")
    return {"sd_image": args.sd_image, "sd_faults": args.sd_faults}


TURBULENCE_LEVELS = ("light", "moderate", "severe")


def add_vehicle_arguments(p, rigs=None) -> None:
    """The 6-DoF vehicle's options (--plant vehicle): its parameter file, turbulence, the
    seed and the ideal sensor; with ``rigs``, --rig too (default: the --axis one)."""
    if rigs is not None:
        p.add_argument("--rig", choices=rigs, default=None,
                       help="--plant vehicle: the test rig (default: the --axis one)")
    p.add_argument("--params", metavar="FILE",
                   help="--plant vehicle: parameter file (default: the shipped vehicle.toml)")
    p.add_argument("--turbulence", choices=TURBULENCE_LEVELS,
                   help="--plant vehicle: Dryden turbulence (MIL-F-8785C) at this level")
    p.add_argument("--seed", type=int_in(0, MAX_SEED), default=0,
                   help="turbulence and sensor-noise seed (default 0)")
    p.add_argument("--ideal-sensor", action="store_true",
                   help="--plant vehicle: no IMU noise, bias or DMP latency")
    p.add_argument("--hinge-friction", type=number_in(0, 1), metavar="N_M",
                   help="--plant vehicle: the free hinge's Coulomb friction, N m (default: "
                        "the parameter file's, 0 in the shipped one; the roll rig's full "
                        "mixer command is about 0.18 N m), to study a rig that is not linear")


def vehicle_config(args) -> dict:
    """SilConfig's fields from :func:`add_vehicle_arguments`' options (the rig aside)."""
    return {"params": args.params, "turbulence": args.turbulence, "seed": args.seed,
            "ideal_sensor": args.ideal_sensor, "hinge_friction_n_m": args.hinge_friction}


def vehicle_rig(args) -> str:
    """The rig a run flies on: --rig, else the --axis one. On a rig only its own axis is
    free (or every axis, on the free rig), so --plant vehicle refuses any other."""
    rig = args.rig or args.axis
    if args.plant == "vehicle" and rig not in (args.axis, "free"):
        raise InputError(f"on the {rig} rig only {rig} is free: use --axis {rig}")
    return rig


def add_port_argument(p, required: bool = True) -> None:
    """--port CONN: the board's telemetry link (host/acquire/connection.py), or auto
    (host/acquire/ports.py: the command's run resolves it with ``resolve_port``)."""
    p.add_argument("--port", required=required, metavar="CONN", help=CONNECTION_HELP)


def add_baud_argument(p) -> None:
    """--baud: a serial device's rate (the Teensy's UART0 by default)."""
    p.add_argument("--baud", type=int_in(50, 12_000_000), default=DEFAULT_BAUD,
                   help=f"serial rate (default {DEFAULT_BAUD}, the Teensy's UART0; ignored by USB, "
                        "ptys and network links)")


def add_board_actions(sub, name: str, help_text: str, description: str, fmt,
                      port_required: bool = True):
    """A command that talks to a board over its link and does one of its ACTIONs: its
    parser with --port (required, unless some ACTION needs no board: then the command's run
    checks it with :func:`require_port`) and --baud, and the ACTION subparsers (one
    required)."""
    p = sub.add_parser(name, help=help_text, description=description, formatter_class=fmt)
    add_port_argument(p, required=port_required)
    add_baud_argument(p)
    actions = p.add_subparsers(dest="action", metavar="ACTION")
    actions.required = True
    return p, actions


def require_port(args) -> None:
    """The check argparse makes of a required --port, for a command whose --port is required
    by some of its ACTIONs only (:func:`add_board_actions`): the same words, exit 2."""
    if args.port is None:
        raise InputError(f"the following arguments are required: --port (see heliquad "
                         f"{args.command} --help)")


def add_firmware_argument(p) -> None:
    """--firmware: which firmware flies the simulated rig (sim.lockstep.FIRMWARES)."""
    p.add_argument("--firmware", choices=("host", "teensy35"), default="host",
                   help="host: the firmware's host build (default); teensy35: the Teensy 3.5 "
                        "image itself, run instruction by instruction in the emulated "
                        "MK64FX512 (processor in the loop: slower; the install builds the "
                        "image when the ARM toolchain is present)")
    p.add_argument("--link", choices=BOARD_LINKS, default=None,
                   help="--firmware teensy35: the board's link the tools talk over: usb (its "
                        "own USB port, which an emulated USB host enumerates and holds open; "
                        "the default) or uart (UART0, pins 0 and 1, where a telemetry radio "
                        "goes): docs/processor-in-the-loop.md")


def firmware_link(args) -> str:
    """--link (default: the board's USB port), refused with the host build (whose one link
    is a pty)."""
    if args.link is not None and args.firmware != "teensy35":
        raise InputError(f"--link {args.link} needs --firmware teensy35 (the host build's "
                         "link is a pty)")
    return args.link or DEFAULT_BOARD_LINK


def add_fault_argument(p, prefix="") -> None:
    p.add_argument("--fault", action="append", default=[], metavar="KIND@T[:D]",
                   help=prefix + "inject a fault at T seconds of simulated time (repeatable): "
                        "silent, nack (for D seconds, or to the end), reset, overflow (the "
                        "MPU6050), link (the host closes its telemetry link); e.g. silent@3:0.5")


def faults(args) -> tuple:
    # imported only when the option is checked: every command's parser imports this module
    from ...sim.rig.faults import parse_fault

    return tuple(parse_fault(text) for text in args.fault)


def transfer_function(what: str, num, den, leading_zeros: bool = False):
    """``num/den`` as arrays with den monic, or an InputError naming ``what``: the
    denominator of degree 1..MAX_DEGREE with a leading coefficient that is not zero, the
    model proper, every coefficient finite and, den made monic, within MAX_COEFFICIENT.
    ``leading_zeros``: a numerator may start with zeros (they are dropped)."""
    num, den = np.asarray(num, dtype=float), np.asarray(den, dtype=float)
    if leading_zeros:
        num = np.trim_zeros(num, "f")
    if num.size == 0 or not np.any(num):
        raise InputError(f"{what}: the numerator is zero (no response)")
    if not 2 <= den.size <= MAX_DEGREE + 1:
        raise InputError(f"{what}: the denominator needs 2 to {MAX_DEGREE + 1} coefficients "
                         f"(degree 1 to {MAX_DEGREE}), got {den.size}")
    if not (np.all(np.isfinite(num)) and np.all(np.isfinite(den))):
        raise InputError(f"{what}: coefficients must be finite numbers")
    if den[0] == 0 or num[0] == 0:
        part = "denominator" if den[0] == 0 else "numerator"
        raise InputError(f"{what}: the leading coefficient of the {part} is 0: drop leading "
                         "zeros")
    if num.size > den.size:
        raise InputError(f"{what}: not proper (numerator degree {num.size - 1} above the "
                         f"denominator's {den.size - 1}); a physical response is proper")
    with np.errstate(all="ignore"):
        num, den = num / den[0], den / den[0]
    if not np.all(np.abs(np.concatenate([num, den])) <= MAX_COEFFICIENT):
        raise InputError(f"{what}: with the denominator made monic a coefficient is beyond "
                         f"{MAX_COEFFICIENT:g} (the poles would be lost in round-off)")
    return num, den


def _log_gain(num, den, omega) -> float:
    """The median over ``omega`` of log10 |G(j omega)| (a resonance on the grid does not
    dominate it, nor a pole on the imaginary axis)."""
    with np.errstate(all="ignore"):
        s = 1j * omega
        return float(np.median(np.log10(np.abs(np.polyval(num, s) / np.polyval(den, s)))))


def check_model(what: str, num, den) -> None:
    """An identified model the cascade can be validated with (continuous time): see
    :func:`transfer_function`, poles and zeros within MODEL_RATE_MAX, its gain across
    0.01..1e4 rad/s within MODEL_GAIN_RANGE. A zero model (no response at all) is
    validated as it is: only its denominator is checked."""
    if np.all(np.asarray(num, dtype=float) == 0):
        transfer_function(what, [1.0], den)
        return
    num, den = transfer_function(what, num, den, leading_zeros=True)
    for name, roots in (("pole", np.roots(den)), ("zero", np.roots(num))):
        if roots.size and np.max(np.abs(roots)) > MODEL_RATE_MAX:
            raise InputError(f"{what}: a {name} at {np.max(np.abs(roots)):.3g} rad/s, beyond "
                             f"{MODEL_RATE_MAX:g} rad/s: not an attitude model")
    lo, hi = MODEL_GAIN_RANGE
    gain = _log_gain(num, den, np.logspace(-2, 4, 200))
    if not math.log10(lo) <= gain <= math.log10(hi):
        raise InputError(f"{what}: its gain (about {10 ** gain:.3g}) is outside "
                         f"[{lo:g}, {hi:g}]")


def check_plant(args) -> None:
    """The simulated rig can fly this plant: a transfer function (:func:`transfer_function`,
    leading zeros refused) whose poles are no faster than the loop's Nyquist rate and whose
    gain is within PLANT_GAIN_RANGE, or a vehicle file whose fastest mode the integrator can
    follow at this loop rate and whose rotors the firmware flies, in its mixer's places
    (:func:`~heliquad.sim.plant.vehicle_plant.check_loop_vehicle`). An unstable plant
    is allowed: the firmware's abort is what such a run tests. A ``--dmp-image`` file is read
    here too, so a bad one is refused before anything starts."""
    if getattr(args, "dmp_image", None):
        # imported only when the option is checked: every command's parser imports this module
        from .dmp_image import read_dmp_file

        read_dmp_file(args.dmp_image)
    if not 0 <= args.collective <= 1:
        raise InputError("--collective must be in [0, 1]")
    loop_hz = getattr(args, "loop_hz", facts.LOOP_RATE_HZ)
    if not 0 < loop_hz <= facts.MAX_LOOP_RATE_HZ:
        raise InputError(f"--loop-hz must be in (0, {facts.MAX_LOOP_RATE_HZ:g}]")
    if getattr(args, "plant", "tf") == "vehicle":
        # imported only when the option is checked: every command's parser imports this module
        from ...sim.plant.vehicle_params import load_params
        from ...sim.plant.vehicle_plant import check_loop_vehicle

        check_loop_vehicle(load_params(args.params), 1.0 / loop_hz)   # a bad file fails here
        return
    num, den = transfer_function("--num/--den", args.num, args.den)
    nyquist = math.pi * loop_hz
    fastest = float(np.max(np.abs(np.roots(den))))
    if fastest > nyquist:
        raise InputError(f"--num/--den: a pole at {fastest:.3g} rad/s is faster than the "
                         f"{loop_hz:g} Hz loop's Nyquist rate ({nyquist:.3g} rad/s): its "
                         "samples cannot show it (drop it; its DC gain stays in the numerator)")
    lo, hi = PLANT_GAIN_RANGE
    gain = _log_gain(num, den, np.logspace(-2, math.log10(nyquist), 200))
    if not math.log10(lo) <= gain <= math.log10(hi):
        raise InputError(f"--num/--den: the plant's gain (about {10 ** gain:.3g} rad/s per unit "
                         f"torque command up to the Nyquist rate) is outside [{lo:g}, {hi:g}]")
