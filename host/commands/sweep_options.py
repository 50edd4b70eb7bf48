"""A sweep's design options and its plan, shared by ``heliquad sweep`` and ``heliquad program
set``: the signal (dwell, multisine, chirp), its frequencies, amplitude and length, checked
against the firmware's limits before anything flies."""

from __future__ import annotations

import numpy as np

from ...sim.base import firmware_facts as facts
from ...sim.base.errors import InputError
from ..acquire import design
from ..acquire.chirp import LAWS as CHIRP_LAWS, SWEEP_S as CHIRP_SWEEP_S
from ..acquire.excitation import amplitude_bound, bound_text, defaults_text, firmware_amplitude, units_text
from ..acquire.linearity import PERIODS as LINEARITY_PERIODS, REALISATIONS, SMALL_SHARE
from ..acquire.multisine import LINES, MAX_LINES, RIG_TIME_S
from .shared_options import MAX_CYCLES, int_in, number_in

__all__ = ["check_excitation", "add_design_arguments", "apply_tuning_band", "sweep_plan"]


def check_excitation(freqs_hz, cycles, fade_cycles, loop_hz, amplitude=None, inject=None):
    """Refuse, before anything starts, an excitation the firmware would refuse: the limits
    are the firmware's own defaults (:mod:`heliquad.sim.base.firmware_facts`, read from the
    same C++ the firmware compiles)."""
    f32 = lambda x: float(np.float32(x))       # noqa: E731 - the firmware compares in float
    hi = f32(facts.MAX_FREQ_FRACTION * f32(loop_hz))
    for f in freqs_hz:
        if not facts.MIN_FREQ_HZ <= f32(f) <= hi:
            raise InputError(f"{f:g} Hz is outside the firmware's excitation band "
                             f"[{facts.MIN_FREQ_HZ:g}, {hi:g}] Hz at a {loop_hz:g} Hz loop")
        duration = (cycles + 2 * fade_cycles) / f
        if duration > facts.MAX_DURATION_S:
            raise InputError(f"{cycles} cycles with {fade_cycles} of fade each way at {f:g} Hz "
                             f"last {duration:.0f} s; the firmware allows "
                             f"{facts.MAX_DURATION_S:g} s: fewer --cycles or --fade-cycles")
    if fade_cycles < facts.MIN_FADE_CYCLES:
        raise InputError(f"--fade-cycles must be at least {facts.MIN_FADE_CYCLES}")
    if amplitude is not None and f32(amplitude) > amplitude_bound(inject):
        raise InputError(f"--amplitude is above the firmware's bound for {inject} "
                         f"injection ({bound_text(inject)})")


def add_design_arguments(p, on_board: bool = False) -> None:
    """A sweep's design options (``heliquad sweep``; ``heliquad program set`` with
    ``on_board``: a program the board runs alone has no host to judge a dwell or design an
    amplitude from what it measured, so it has a fixed dwell and fixed amplitudes)."""
    p.add_argument("--freqs-hz", type=number_in(0, 1e6, lo_open=True), nargs="+", metavar="F",
                   help="frequencies (default: 15 log-spaced over the paper's band for the axis)")
    p.add_argument("--tuning-band", action="store_true",
                   help="instead of the paper's band: 16 frequencies log-spaced from its "
                        "bottom up to 45 Hz, so that the model holds where heliquad tune reads "
                        "every margin (docs/tuning.md)")
    mixer = ("a quarter of the firmware's bound (mixer, the design's first)" if on_board else
             "designed per frequency (mixer)")
    p.add_argument("--amplitude", type=number_in(0, 1e6, lo_open=True), metavar="A", help="one amplitude for all "
                   f"frequencies: {units_text()}; default: "
                   f"{mixer}, {defaults_text()}")
    if not on_board:
        p.add_argument("--swing-deg", type=number_in(0, 45, lo_open=True), metavar="D",
                       help=f"mixer: the rig swing each designed amplitude aims at (default "
                            f"{design.TARGET_SWING_DEG:g} deg)")
    p.add_argument("--cycles", type=int_in(1, MAX_CYCLES), metavar="N",
                   help="a fixed dwell: N measured cycles per frequency (the paper's: 8); "
                        "default: " + ("8" if on_board else "the sequential dwell"))
    if not on_board:
        p.add_argument("--target-sigma", type=number_in(0, 1, lo_open=True), metavar="S",
                       help=f"sequential dwell: end a frequency once its point's standard deviation "
                            f"is S of its magnitude (default {design.TARGET_SIGMA:g}); with "
                            "--signal multisine, a sequential multisine: whole base periods "
                            "until every line's is, or --rig-time (default "
                            f"{design.SEQUENTIAL_RIG_TIME_S:g} s)")
        p.add_argument("--max-cycles", type=int_in(design.MIN_CYCLES, MAX_CYCLES), metavar="N",
                       help=f"sequential dwell: the most measured cycles of a frequency (default "
                            f"{design.MAX_CYCLES}; at most {design.MAX_DWELL_S:g} s of them)")
    p.add_argument("--signal", choices=("dwell", "multisine") + (() if on_board else ("chirp",)),
                   default="dwell",
                   help="dwell (default, the paper's): one sine per frequency; multisine: "
                        "every line of the band at once, in one periodic record"
                        + ("" if on_board else "; chirp: one frequency sweep over the band"))
    if not on_board:
        p.add_argument("--chirp", choices=CHIRP_LAWS, default="log",
                       help="chirp: how its frequency moves, log (default: a constant factor "
                            "per second) or linear")
    if not on_board:
        p.add_argument("--redesign", action="store_true",
                       help="with --signal multisine --target-sigma, two passes: the first for "
                            "its least periods, then the same lines with each one's amplitude "
                            "from the disturbance the first measured there (more where the "
                            "response is buried), within the same peak, sequential to the rest "
                            "of --rig-time; identify combines the passes line by line")
        p.add_argument("--linearity", nargs="?", type=int_in(2, 50), const=REALISATIONS,
                       metavar="M",
                       help="with --signal multisine, a linearity campaign: odd multisines "
                            f"with random phases, M realisations (default {REALISATIONS}) at "
                            f"the peak and again at {SMALL_SHARE:g} of it; identify then "
                            "separates each line's noise from the nonlinear distortion and "
                            "fits the larger amplitude's best linear approximation")
    _add_shape_arguments(p, on_board)


def _add_shape_arguments(p, on_board: bool) -> None:
    """A multisine's lines, length and grid, and the fades of a dwell or a multisine."""
    p.add_argument("--lines", type=int_in(2, MAX_LINES), metavar="N",
                   help=f"multisine: log-spaced lines over the band (default {LINES}), each on "
                        "the nearest harmonic of the base period")
    p.add_argument("--rig-time", type=number_in(10, facts.MAX_DURATION_S), metavar="S",
                   help=f"multisine: the seconds it may last, fades included (default "
                        f"{RIG_TIME_S:g}); as many whole base periods as fit"
                        + ("" if on_board else f"; chirp: its sweep's seconds at full "
                                               f"amplitude (default {CHIRP_SWEEP_S:g})"))
    p.add_argument("--base-period", type=number_in(0.1, facts.MAX_DURATION_S), metavar="S",
                   help="multisine: its base period, s, its lines on harmonics of 1/S Hz "
                        "(default: chosen for --rig-time, the most distinct lines, then the "
                        "most periods); the same S with another --rig-time flies the same "
                        "lines for longer or shorter")
    p.add_argument("--fade-cycles", type=int_in(facts.MIN_FADE_CYCLES, MAX_CYCLES),
                   metavar="N",
                   help="dwell: each frequency faded in and out over N cycles (default 2; "
                        "the fade-in is the settling before the measured cycles); multisine: "
                        "over N cycles of its lowest line (default 1)")


def apply_tuning_band(args) -> None:
    """--tuning-band: its frequencies as --freqs-hz (the two together refused)."""
    # the command's work, imported when it runs: --help imports every command module
    from ..acquire.sweep import tuning_freqs_hz

    if args.tuning_band:
        if args.freqs_hz:
            raise InputError("--tuning-band and --freqs-hz both give the frequencies: give one")
        args.freqs_hz = tuning_freqs_hz(args.axis).tolist()


def sweep_plan(args, on_board: bool = False):
    """The sweep's plan from the options of :func:`add_design_arguments`: fixed or
    sequential dwell, fixed or designed amplitudes (``on_board``: a fixed dwell, 8 cycles
    unless --cycles, and fixed amplitudes, a mixer's the design's first), and what a rate
    or angle sweep measures (--response, checked with the rig's options)."""
    plan = _plan(args, on_board)
    plan.response = getattr(args, "response", None)
    return plan


def _plan(args, on_board: bool):
    # the command's work, imported when it runs: --help imports every command module
    from ..acquire.sweep import MEASURED_CYCLES, default_plan

    target_sigma, max_cycles, swing_deg = (getattr(args, name, None) for name in
                                           ("target_sigma", "max_cycles", "swing_deg"))
    apply_tuning_band(args)
    if swing_deg is not None and (args.amplitude is not None or args.inject != "mixer"):
        raise InputError("--swing-deg designs mixer amplitudes; it does not go with "
                         "--amplitude or angle or rate injection")
    amp = None if args.amplitude is None else firmware_amplitude(args.inject, args.amplitude)
    if getattr(args, "linearity", None) and args.signal != "multisine":
        raise InputError("--linearity is a campaign of multisines: add --signal multisine")
    if getattr(args, "redesign", False) and args.signal != "multisine":
        raise InputError("--redesign redesigns a multisine's lines: add --signal multisine")
    if args.signal == "multisine":
        return _multisine_plan(args, amp, (target_sigma, max_cycles, swing_deg))
    if args.signal == "chirp":
        return _chirp_plan(args, amp, (target_sigma, max_cycles, swing_deg))
    if args.lines is not None or args.rig_time is not None or args.base_period is not None:
        raise InputError("--lines, --rig-time and --base-period shape a multisine: add "
                         "--signal multisine")
    if args.cycles is not None and (target_sigma or max_cycles):
        raise InputError("--cycles fixes the dwell; --target-sigma and --max-cycles are for "
                         "the sequential dwell: give one or the other")
    if on_board:
        if amp is None and args.inject == "mixer":
            amp = design.AmplitudeDesign(amplitude_bound("mixer")).first()
        return default_plan(args.axis, args.inject, args.freqs_hz, amp,
                            args.cycles or MEASURED_CYCLES, fade_cycles=args.fade_cycles)
    dwell = None
    if args.cycles is None:
        dwell = design.Dwell()
        dwell.target_sigma = target_sigma or dwell.target_sigma
        dwell.max_cycles = max_cycles or dwell.max_cycles
    return default_plan(args.axis, args.inject, args.freqs_hz, amp, args.cycles, dwell,
                        swing_deg, args.fade_cycles)


def _band_edges(args, signal: str):
    """--freqs-hz as a band's two edges (its lowest and highest), or None without it."""
    if args.freqs_hz is None:
        return None
    if len(args.freqs_hz) < 2 or min(args.freqs_hz) == max(args.freqs_hz):
        raise InputError(f"--freqs-hz with --signal {signal}: the band's two edges "
                         "(lowest and highest)")
    return min(args.freqs_hz), max(args.freqs_hz)


def _chirp_plan(args, amp, dwell_options):
    """A chirp's plan: over the axis's band, or from the lowest to the highest of
    --freqs-hz, sweeping --rig-time seconds; --amplitude is its amplitude."""
    # the command's work, imported when it runs: --help imports every command module
    from ..acquire.sweep import chirp_plan

    given = [o for o, v in zip(("--cycles", "--target-sigma", "--max-cycles", "--swing-deg",
                                "--lines", "--base-period", "--fade-cycles"),
                               (args.cycles, *dwell_options, args.lines, args.base_period,
                                args.fade_cycles))
             if v is not None]
    if given:
        raise InputError(f"{' and '.join(given)} do not shape a chirp: its length is "
                         "--rig-time, its band the axis's or --freqs-hz's edges, its fades "
                         "whole cycles at its ends")
    return chirp_plan(args.axis, args.inject, amp, args.rig_time, _band_edges(args, "chirp"),
                      args.chirp)


def _multisine_plan(args, amp, dwell_options):
    """A multisine's plan: over the axis's band, or from the lowest to the highest of
    --freqs-hz; --amplitude is its peak; with --target-sigma it is sequential (whole base
    periods until every line is known that well, or --rig-time, default 180 s)."""
    # the command's work, imported when it runs: --help imports every command module
    from ..acquire.sweep import multisine_plan

    target_sigma = dwell_options[0]
    given = [o for o, v in zip(("--cycles", "--max-cycles", "--swing-deg"),
                               (args.cycles, *dwell_options[1:])) if v is not None]
    if given:
        raise InputError(f"{' and '.join(given)} shape a dwell; a multisine's length is "
                         "--rig-time (and with --target-sigma, the periods its lines need)")
    if getattr(args, "linearity", None):
        return _linearity_plan(args, amp, target_sigma)
    sequential = None if target_sigma is None else design.SequentialMultisine(target_sigma)
    redesign = bool(getattr(args, "redesign", False))
    if redesign and sequential is None:
        raise InputError("--redesign judges a first pass against the target: add --target-sigma")
    return multisine_plan(args.axis, args.inject, amp, args.lines, args.rig_time,
                          _band_edges(args, "multisine"), sequential=sequential,
                          base_period_s=args.base_period, fade_cycles=args.fade_cycles,
                          redesign=redesign)


def _linearity_plan(args, amp, target_sigma):
    """A linearity campaign's plan (--linearity M): its realisations' phases from --seed."""
    # the command's work, imported when it runs: --help imports every command module
    from ..acquire.sweep import linearity_plan

    given = [o for o, v in (("--target-sigma", target_sigma), ("--rig-time", args.rig_time),
                            ("--base-period", args.base_period),
                            ("--fade-cycles", args.fade_cycles),
                            ("--redesign", args.redesign or None)) if v is not None]
    if given:
        raise InputError(f"{' and '.join(given)} with --linearity: its length is its "
                         f"realisations' ({LINEARITY_PERIODS} base periods each, at two "
                         "amplitudes)")
    return linearity_plan(args.axis, args.inject, amp, getattr(args, "seed", 0) or 0,
                          args.linearity, _band_edges(args, "multisine"), args.lines)
