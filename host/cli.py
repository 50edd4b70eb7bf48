"""The ``heliquad`` command line.

Every subcommand reports bad input as one line on stderr (``heliquad SUB: error: ...``) and
exits with code 2; no traceback reaches the user for an input problem.
"""

from __future__ import annotations

import argparse
import math
import sys

import numpy as np

from . import __version__
from .cli_args import MAX_CYCLES, MAX_SEED, add_firmware_argument, finite, int_in, number_in
from .errors import InputError
from .link import DEFAULT_BAUD

__all__ = ["main"]

EXIT_INPUT = 2

FSF_HELP = """\
Estimate one frequency-response point per sine experiment with the frequency sampling
filter (FSF) and least squares (the paper's step 2, docs/paper.md).

RUN.csv: a header row, then columns t_s,u,y (seconds, input, output; any order, other
columns ignored), uniformly sampled, one sine frequency per file.
POINTS.csv (written): omega_rad_s,magnitude,phase_rad,sigma,coherence, one row per run,
sorted by frequency; magnitude linear, phase in radians, sigma the standard deviation of
the complex gain, coherence the magnitude-squared coherence at that frequency.

example: heliquad fsf runs/*.csv --discard-periods 2 --out points.csv
"""

FIT_HELP = """\
Fit transfer functions of the given orders to frequency-response points: Levy's method,
Sanathanan-Koerner iterations, then an output-error refinement with stable poles
(docs/paper.md, step 3). Prints each model's metrics and the recommended one.

POINTS.csv: a header row, columns omega_rad_s,magnitude,phase_rad (rad/s, linear, rad;
omega strictly increasing) and optionally sigma,coherence.
MODELS.json (written): {"models": [{"order": [M, N], "num": [...], "den": [...],
"delay_s": 0.0, "stable": true, "metrics": {"rms", "J", "aicc", ...}, "poles", "zeros",
"dc_gain"}, ...], "recommended": INDEX, "reason": "..."}; coefficients in descending
powers of s, den monic.

example: heliquad fit points.csv --order 0/2 --order 0/3 --order 2/4 --json models.json --plot bode.png
"""

SIL_HELP = """\
Run one sine experiment with the firmware in the loop: the host build of the firmware is
driven in lockstep over a pty by the simulated rig (a transfer-function plant from the
axis's normalised torque command to its body rate, rad/s), armed and held at hover, and
excited over the telemetry link exactly as a real board would be.

Writes RUN.tlog (every telemetry message, stamped with simulated time; pymavlink reads it)
and RUN.csv (t_s,u,y over the full-amplitude cycles, for heliquad fsf). u and y follow the
injection point: mixer -> u torque command, y rate; rate -> u rate setpoint, y rate (rad/s);
angle -> u angle setpoint, y angle (rad).

example: heliquad sil --axis roll --inject mixer --freq-hz 1 --amplitude 0.05 --out run1
"""

BOARD_HELP = """\
Run the simulated rig in real time as if it were a board on a serial port: the host
firmware with a transfer-function plant, armed and hovering, stepping one loop per loop
period of wall-clock time. Its telemetry port appears at --telemetry; connect any MAVLink
tool to it as to a board's serial port (any baud rate is accepted and ignored). Nothing reads the
telemetry for you: with no reader, the firmware drops and counts messages as a UART would.

example: heliquad board --axis roll --telemetry /tmp/rig &   then open /tmp/rig
"""

SWEEP_HELP = """\
Run the paper's sine sweep for one axis: the band of its Table 1, 15 log-spaced frequencies
(or --freqs-hz), each faded in over 2 cycles (the settling), measured for --cycles cycles,
faded out. --sil flies the simulated rig in lockstep (the 6-DoF vehicle on the axis's rig by
default); --port talks to a board, or to a `heliquad board` pty, in real time. Writes
DIR/sweep.tlog (every message) and DIR/manifest.json (axis, frequencies requested and used,
windows, gains, firmware, start time), kept valid on Ctrl-C. An angle beyond 80 deg or a
rate beyond 400 deg/s stops the excitation and the sweep (exit 1).
Input and output for `heliquad identify`: mixer -> the axis's torque command and the rate
(the plant; default, the paper's rate-in rate-out model); rate -> rate setpoint and rate;
angle -> angle setpoint and angle.

example: heliquad sweep --axis roll --sil --out roll_sweep && heliquad identify roll_sweep
"""

IDENTIFY_HELP = """\
Turn a sweep folder (manifest.json + sweep.tlog) into frequency-response points (FSF), the
paper's table (points_table.csv), fitted models (models.json, the paper's orders for the axis
unless --order) and plots (bode.png; responses.png, input dashed, output solid).
"""

LOG_HELP = """\
Log every MAVLink message from a board's telemetry port to a .tlog (8-byte big-endian
timestamp in us, then the packet; pymavlink reads it). The file is flushed as it goes, so
Ctrl-C or a crash leaves a valid log. Lost samples are counted from the gaps in
HQ_SYSID_SAMPLE.seq; a summary is printed at the end, and a status line every 5 s.

example: heliquad board --telemetry /tmp/rig &  heliquad log --port /tmp/rig --out flight.tlog
"""

VALIDATE_HELP = """\
Check an identified model in closed loop, as the paper does: its cascade (PID rate
loop on the model; for roll and pitch a PD angle loop around it) with the paper's gains or a
gains file ({"rate": {"roll": [Kc, tau_I, tau_D]}, "angle": {"roll": [Kc, tau_D]}}).
Reports gain and phase margins of each loop, the step response, 0.5 Hz sine tracking, and
rejection of Dryden turbulence; writes validation.json and validation.png. Exit code 1 if
the cascade is unstable.

example: heliquad validate models.json --axis roll
"""

DEFAULT_FIT_ORDERS = ("0/1", "0/2", "0/3", "2/2", "2/3", "2/4")


class _Parser(argparse.ArgumentParser):
    """argparse with a one-line error and exit code 2."""

    def error(self, message):
        sys.stderr.write(f"{self.prog}: error: {message} (see {self.prog} --help)\n")
        sys.exit(EXIT_INPUT)


def _build_parser() -> argparse.ArgumentParser:
    parser = _Parser(prog="heliquad",
                     description="Firmware-in-the-loop flight-controller emulator and "
                                 "frequency-domain system identification for heterogeneous "
                                 "multirotors.")
    parser.add_argument("--version", action="version", version=f"heliquad {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", parser_class=_Parser)
    sub.required = True
    fmt = argparse.RawDescriptionHelpFormatter

    p = sub.add_parser("fsf", help="frequency-response points from sine runs",
                       description=FSF_HELP, formatter_class=fmt)
    p.add_argument("runs", nargs="+", metavar="RUN.csv", help="one sine experiment per file")
    p.add_argument("--freq-hz", type=number_in(0, 1e6, lo_open=True), action="append", metavar="F",
                   help="excitation frequency: once for all runs or once per run "
                        "(default: found from the input signal)")
    p.add_argument("--harmonics", type=int, default=3, metavar="L",
                   help="harmonics -L..L in the FSF model (default 3, as in the paper)")
    p.add_argument("--discard-periods", type=int, default=1, metavar="K",
                   help="settling periods dropped at the start of each run (default 1)")
    p.add_argument("--no-offset", action="store_true",
                   help="do not estimate a constant output offset")
    p.add_argument("--out", required=True, metavar="POINTS.csv", help="points file to write")
    p.set_defaults(func=_cmd_fsf)

    p = sub.add_parser("fit", help="transfer functions from frequency-response points",
                       description=FIT_HELP, formatter_class=fmt)
    p.add_argument("points", metavar="POINTS.csv")
    p.add_argument("--order", action="append", metavar="M/N",
                   help="numerator/denominator degree; repeat for several "
                        f"(default: {' '.join(DEFAULT_FIT_ORDERS)}, those the points support)")
    p.add_argument("--delay", action="store_true", help="fit a pure time delay with each model")
    p.add_argument("--weights", choices=("auto", "sigma", "coherence", "none"), default="auto",
                   help="point weights: 1/sigma, CIFER coherence weight, or equal relative "
                        "weight (default auto: sigma, else coherence, else none)")
    p.add_argument("--allow-unstable", action="store_true",
                   help="do not constrain poles to the left half plane (unstable results "
                        "are flagged)")
    p.add_argument("--json", required=True, metavar="MODELS.json", help="models file to write")
    p.add_argument("--plot", metavar="BODE.png", help="write a Bode plot of points and models")
    p.add_argument("--mat", metavar="MODELS.mat", help="also write the models for MATLAB")
    p.set_defaults(func=_cmd_fit)

    p = sub.add_parser("sil", help="one sine experiment with the firmware in the loop",
                       description=SIL_HELP, formatter_class=fmt)
    p.add_argument("--plant", choices=("tf", "vehicle"), default="tf",
                   help="tf: a transfer function from the axis's torque command to its body "
                        "rate (default); vehicle: the 6-DoF heterogeneous multirotor on a rig")
    p.add_argument("--rig", choices=("roll", "pitch", "yaw", "free"), default=None,
                   help="vehicle plant: the test rig (default: the --axis one)")
    p.add_argument("--params", metavar="FILE",
                   help="vehicle plant: parameter file (default: the shipped vehicle.toml)")
    p.add_argument("--turbulence", choices=("light", "moderate", "severe"),
                   help="vehicle plant: Dryden turbulence (MIL-F-8785C) at this level")
    p.add_argument("--seed", type=int_in(0, MAX_SEED), default=0, help="turbulence and sensor-noise seed (default 0)")
    p.add_argument("--ideal-sensor", action="store_true",
                   help="vehicle plant: no IMU noise, bias or DMP latency")
    p.add_argument("--axis", choices=("roll", "pitch", "yaw"), default="roll")
    p.add_argument("--num", type=finite, nargs="+", metavar="B", default=[28.19],
                   help="numerator, descending powers of s (default: the paper's roll model)")
    p.add_argument("--den", type=finite, nargs="+", metavar="A", default=[1.0, 5.13, 22.93],
                   help="denominator, descending powers of s")
    p.add_argument("--inject", choices=("mixer", "rate", "angle"), default="mixer")
    p.add_argument("--freq-hz", type=number_in(0, 1e6, lo_open=True), required=True, metavar="F")
    p.add_argument("--amplitude", type=number_in(0, 1e6, lo_open=True), required=True, metavar="A",
                   help="deg for angle, deg/s for rate, normalised torque (-1..1) for mixer")
    p.add_argument("--cycles", type=int_in(1, MAX_CYCLES), default=10, help="full-amplitude cycles (default 10)")
    p.add_argument("--fade-cycles", type=int_in(1, MAX_CYCLES), default=2,
                   help="cycles of fade in and of fade out, also the settling (default 2; the "
                        "firmware needs at least 1)")
    p.add_argument("--collective", type=number_in(0, 1), default=0.4,
                   help="hover throttle as a fraction of stick travel (default 0.4)")
    p.add_argument("--loop-hz", type=number_in(1, 2000), default=200.0, help="firmware loop rate (default 200)")
    p.add_argument("--dmp-image", metavar="FILE",
                   help="MotionApps 2.0 DMP firmware file for the firmware, made with "
                        "heliquad dmp-image (default: raw FIFO path)")
    p.add_argument("--out", required=True, metavar="RUN",
                   help="writes RUN.tlog (all telemetry) and RUN.csv (t_s,u,y)")
    add_firmware_argument(p)
    _add_fault_argument(p)
    p.set_defaults(func=_cmd_sil)

    p = sub.add_parser("board", help="run the simulated rig as if it were a board on a serial port",
                       description=BOARD_HELP, formatter_class=fmt)
    p.add_argument("--plant", choices=("tf",), default="tf")
    p.add_argument("--axis", choices=("roll", "pitch", "yaw"), default="roll")
    p.add_argument("--num", type=finite, nargs="+", metavar="B", default=[28.19])
    p.add_argument("--den", type=finite, nargs="+", metavar="A", default=[1.0, 5.13, 22.93])
    p.add_argument("--telemetry", default="heliquad-board", metavar="PATH",
                   help="where the telemetry serial port appears (default ./heliquad-board)")
    p.add_argument("--duration-s", type=number_in(0, 1e7, lo_open=True), metavar="S", help="stop after S seconds "
                   "(default: run until Ctrl-C)")
    p.add_argument("--collective", type=number_in(0, 1), default=0.4)
    p.add_argument("--loop-hz", type=number_in(1, 2000), default=200.0)
    p.add_argument("--dmp-image", metavar="FILE")
    add_firmware_argument(p)
    p.set_defaults(func=_cmd_board)

    p = sub.add_parser("validate", help="closed-loop validation of an identified model",
                       description=VALIDATE_HELP, formatter_class=fmt)
    p.add_argument("models", metavar="MODELS.json")
    p.add_argument("--model", type=int_in(0, 10_000), metavar="INDEX",
                   help="which model (default: the recommended one)")
    p.add_argument("--axis", choices=("roll", "pitch", "yaw"),
                   help="axis of the model (default: the file's \"axis\" entry)")
    p.add_argument("--gains", metavar="FILE", help="gains file (default: the paper's gains)")
    p.add_argument("--turbulence", choices=("none", "light", "moderate", "severe"),
                   default="moderate", help="Dryden level for disturbance rejection (default moderate)")
    p.add_argument("--seed", type=int_in(0, MAX_SEED), default=0)
    p.add_argument("--out", metavar="DIR", help="where validation.json and validation.png go "
                   "(default: beside MODELS.json)")
    p.set_defaults(func=_cmd_validate)

    p = sub.add_parser("log", help="log a board's (or a SIL's) telemetry to a .tlog",
                       description=LOG_HELP, formatter_class=fmt)
    p.add_argument("--port", required=True, metavar="DEVICE",
                   help="serial device: /dev/ttyACM0 for a Teensy, or a heliquad board pty")
    p.add_argument("--out", required=True, metavar="FILE.tlog")
    p.add_argument("--baud", type=int_in(50, 12_000_000), default=DEFAULT_BAUD,
                   help=f"serial rate (default {DEFAULT_BAUD}, the Teensy's UART0; ignored by USB and ptys)")
    p.add_argument("--duration-s", type=number_in(0, 1e7, lo_open=True), metavar="S", help="stop after S seconds "
                   "(default: until Ctrl-C)")
    p.set_defaults(func=_cmd_log)

    p = sub.add_parser("tlog", help="summarise a .tlog: messages, time span, lost samples",
                       description="Summarise a .tlog written by heliquad (or any MAVLink 2 "
                                   "log of this dialect). A damaged or truncated file is read "
                                   "up to the damage, with a warning.", formatter_class=fmt)
    p.add_argument("path", metavar="FILE.tlog")
    p.set_defaults(func=_cmd_tlog)

    p = sub.add_parser("sweep", help="run an axis's sine sweep (SIL or a board) and log it",
                       description=SWEEP_HELP, formatter_class=fmt)
    p.add_argument("--axis", choices=("roll", "pitch", "yaw"), required=True)
    p.add_argument("--inject", choices=("mixer", "rate", "angle"), default="mixer")
    where = p.add_mutually_exclusive_group(required=True)
    where.add_argument("--sil", action="store_true", help="the simulated rig, in lockstep")
    where.add_argument("--port", metavar="DEVICE", help="a board's telemetry port (or a heliquad board pty)")
    p.add_argument("--baud", type=int_in(50, 12_000_000), default=DEFAULT_BAUD,
                   help=f"serial rate (default {DEFAULT_BAUD}, the Teensy's UART0; ignored by USB and ptys)")
    p.add_argument("--plant", choices=("tf", "vehicle"), default="vehicle",
                   help="--sil: the 6-DoF vehicle (default) or a transfer function")
    p.add_argument("--num", type=finite, nargs="+", metavar="B",
                   help="--plant tf: numerator (default: the paper's chosen model of the axis)")
    p.add_argument("--den", type=finite, nargs="+", metavar="A", help="--plant tf: denominator")
    p.add_argument("--params", metavar="FILE", help="--plant vehicle: parameter file")
    p.add_argument("--turbulence", choices=("light", "moderate", "severe"))
    p.add_argument("--seed", type=int_in(0, MAX_SEED), default=0)
    p.add_argument("--ideal-sensor", action="store_true")
    p.add_argument("--collective", type=number_in(0, 1), default=0.4)
    p.add_argument("--dmp-image", metavar="FILE")
    p.add_argument("--freqs-hz", type=number_in(0, 1e6, lo_open=True), nargs="+", metavar="F",
                   help="frequencies (default: 15 log-spaced over the paper's band for the axis)")
    p.add_argument("--amplitude", type=number_in(0, 1e6, lo_open=True), metavar="A", help="one amplitude for all "
                   "frequencies: deg (angle), deg/s (rate), normalised (mixer); default: per frequency")
    p.add_argument("--cycles", type=int_in(1, MAX_CYCLES), default=8, help="measured cycles per frequency (default 8)")
    p.add_argument("--out", required=True, metavar="DIR")
    add_firmware_argument(p)
    _add_fault_argument(p, "--sil: ")
    p.set_defaults(func=_cmd_sweep)

    p = sub.add_parser("identify", help="points, models and plots from a sweep folder",
                       description=IDENTIFY_HELP, formatter_class=fmt)
    p.add_argument("dir", metavar="DIR")
    p.add_argument("--order", action="append", metavar="M/N",
                   help="orders to fit (default: the paper's per axis: 0/2 0/3 2/4, yaw 0/1 2/2 2/3)")
    p.add_argument("--delay", action="store_true", help="fit a pure time delay with each model "
                   "(the loop's hold and the sensor's latency are real delays)")
    p.set_defaults(func=_cmd_identify)

    p = sub.add_parser("report", help="one self-contained HTML page of a session",
                       description="Write DIR/report.html: every table, model, metric and plot "
                                   "of a sweep folder (or of a folder of them, one per axis), "
                                   "with the quality flags (low coherence, unstable fits, "
                                   "aborted frequencies).", formatter_class=fmt)
    p.add_argument("dir", metavar="DIR")
    p.add_argument("--out", metavar="FILE.html")
    p.set_defaults(func=_cmd_report)

    from .demo import add_demo_parser
    from .dmp_image import add_dmp_image_parser
    from .flash import add_flash_parser

    add_demo_parser(sub, fmt)
    add_dmp_image_parser(sub, fmt)
    add_flash_parser(sub, fmt)
    return parser


def _add_fault_argument(p, prefix="") -> None:
    p.add_argument("--fault", action="append", default=[], metavar="KIND@T[:D]",
                   help=prefix + "inject a fault at T seconds of simulated time (repeatable): "
                        "silent, nack (for D seconds, or to the end), reset, overflow (the "
                        "MPU6050), link (the host closes its telemetry link); e.g. silent@3:0.5")


def _faults(args) -> tuple:
    from ..sim.faults import parse_fault

    return tuple(parse_fault(text) for text in args.fault)


def _cmd_fsf(args) -> int:
    from .files import read_run_csv, write_points_csv
    from .fsf import estimate_fsf

    freqs = args.freq_hz or [None]
    if len(freqs) not in (1, len(args.runs)):
        raise InputError(f"--freq-hz given {len(freqs)} times for {len(args.runs)} runs; "
                         "give it once for all runs or once per run")
    if len(freqs) == 1:
        freqs = freqs * len(args.runs)
    points, origin = [], {}
    for i, (path, freq) in enumerate(zip(args.runs, freqs), 1):
        fs_hz, u, y = read_run_csv(path)
        try:
            point = estimate_fsf(u, y, fs_hz, freq_hz=freq, harmonics=args.harmonics,
                                 discard_periods=args.discard_periods, offset=not args.no_offset)
        except InputError as exc:
            raise InputError(f"{path}: {exc}") from None
        key = round(point.omega_rad_s, 9)
        if key in origin:
            raise InputError(f"{path} and {origin[key]} are both at {point.freq_hz:.6g} Hz; "
                             "one point per frequency")
        origin[key] = path
        points.append(point)
        print(f"[{i}/{len(args.runs)}] {path}: {_describe_point(point)}", flush=True)
        if point.coherence < 0.6:
            print(f"warning: {path}: low coherence {point.coherence:.2f}; the point is "
                  "unreliable", file=sys.stderr)
    write_points_csv(args.out, points)
    print(f"wrote {len(points)} point(s) to {args.out}")
    return 0


def _check_excitation(freqs_hz, cycles, fade_cycles, loop_hz, amplitude=None, inject=None):
    """Refuse, before anything starts, an excitation the firmware would refuse: the limits
    are the firmware's own defaults (heliquad._firmware.SafetyLimits, the same C++ the
    firmware compiles)."""
    from heliquad import _firmware

    from .link import INJECTIONS

    import numpy as np

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


def _cmd_sil(args) -> int:
    import os

    from ..sim.lockstep import FirmwareError
    from ..sim.sil import SilConfig, run_sil

    _check_plant(args)
    if args.inject == "angle" and args.axis == "yaw":
        raise InputError("yaw is rate-only: use --inject rate or mixer")
    amplitude = math.radians(args.amplitude) if args.inject in ("angle", "rate") else args.amplitude
    _check_excitation([args.freq_hz], args.cycles, args.fade_cycles, args.loop_hz, amplitude,
                      args.inject)
    folder = os.path.dirname(os.path.abspath(args.out))
    if not os.path.isdir(folder):
        raise InputError(f"--out: folder {folder} does not exist")
    rig = args.rig or args.axis
    if args.plant == "vehicle" and rig not in (args.axis, "free"):
        raise InputError(f"on the {rig} rig only {rig} is free: use --axis {rig}")
    cfg = SilConfig(axis=args.axis, num=tuple(args.num), den=tuple(args.den), inject=args.inject,
                    freq_hz=args.freq_hz, amplitude=amplitude, cycles=args.cycles,
                    fade_cycles=args.fade_cycles, loop_hz=args.loop_hz,
                    collective=args.collective, dmp_image=args.dmp_image, plant=args.plant,
                    rig=rig, params=args.params, turbulence=args.turbulence, seed=args.seed,
                    ideal_sensor=args.ideal_sensor, faults=_faults(args), firmware=args.firmware)
    if args.turbulence and args.plant != "vehicle":
        raise InputError("--turbulence needs --plant vehicle")
    try:
        r = run_sil(cfg, args.out)
    except FirmwareError as exc:
        raise InputError(str(exc)) from None
    print(f"{r.frames} frames ({r.frames / args.loop_hz:.2f} s simulated) in {r.wall_s:.2f} s "
          f"wall ({r.frames / args.loop_hz / r.wall_s:.2g}x real time); firmware "
          f"{args.firmware}; imu path {r.imu_mode}")
    print(f"excitation at {r.actual_freq_hz:.6g} Hz; {r.samples} full-amplitude samples; "
          f"{r.seq_gaps} telemetry gaps")
    if r.saturated_samples:
        print(f"warning: {r.saturated_samples} samples saturated the mixer; lower --amplitude",
              file=sys.stderr)
    if args.firmware != "host" and r.firmware_summary:
        print(f"the board: {r.firmware_summary.removeprefix('heliquad-fw-pil: ')}")
    print(f"wrote {r.tlog_path} and {r.csv_path}")
    if r.stopped:
        print(f"heliquad sil: {r.stopped} (the log and the samples before it are kept)",
              file=sys.stderr)
        return 1
    return 0


def _cmd_validate(args) -> int:
    import json
    import os

    from .validate import load_gains, save_validation, validate_model

    try:
        with open(args.models) as fh:
            doc = json.load(fh)
        models = doc["models"]
    except OSError as exc:
        raise InputError(f"{args.models}: {exc.strerror}") from None
    except (ValueError, KeyError, TypeError):
        raise InputError(f"{args.models}: not a MODELS.json (needs a \"models\" list)") from None
    index = args.model if args.model is not None else doc.get("recommended")
    if index is None or not 0 <= index < len(models):
        raise InputError(f"{args.models}: no model {index!r} (the file has {len(models)}; "
                         "give --model INDEX)")
    axis = args.axis or doc.get("axis")
    if axis not in ("roll", "pitch", "yaw"):
        raise InputError(f"{args.models} does not say which axis: give --axis roll|pitch|yaw")
    m = models[index]
    try:
        num, den, delay = m["num"], m["den"], float(m.get("delay_s", 0.0))
    except (KeyError, TypeError):
        raise InputError(f"{args.models}: model {index} has no num/den") from None
    gains = load_gains(axis, args.gains)
    turbulence = None if args.turbulence == "none" else args.turbulence
    report, traces = validate_model(num, den, delay, axis, gains, turbulence, args.seed)
    out = args.out or os.path.dirname(os.path.abspath(args.models))
    _print_validation(report)
    written = save_validation(out, report, traces, num, den, delay, axis, gains)
    print(f"wrote {' and '.join(os.path.join(out, name) for name in written)}")
    return 0 if report["stable"] else 1


def _print_validation(r) -> None:
    coeffs = lambda c: "[" + ", ".join(f"{v:.5g}" for v in c) + "]"  # noqa: E731
    print(f"{r['axis']}: G(s) = {coeffs(r['num'])} / {coeffs(r['den'])}"
          + (f" * exp(-{r['delay_s'] * 1e3:.3g} ms s)" if r["delay_s"] else ""))
    for name, lp in r["loops"].items():
        gm = "inf" if lp["gain_margin_db"] is None else f"{lp['gain_margin_db']:.1f} dB"
        pm = "none" if lp["phase_margin_deg"] is None else f"{lp['phase_margin_deg']:.1f} deg"
        wc = "-" if lp["gain_crossover_rad_s"] is None else f"{lp['gain_crossover_rad_s']:.2f} rad/s"
        print(f"  {name:5s} loop: gain margin {gm}, phase margin {pm} at {wc}; closed loop "
              f"{'stable' if lp['closed_loop_stable'] else 'UNSTABLE'}")
    if not r["stable"]:
        from .validate import instability_text

        print(f"  {instability_text(r)}; no time responses")
        return
    st, sn = r["step"], r["sine"]
    print(f"  step {st['size']:g} {st['unit']}: rise {st['rise_time_s']:.2f} s, overshoot "
          f"{st['overshoot_pct']:.1f} %, settling {st['settling_time_s']:.2f} s")
    print(f"  sine {sn['freq_hz']:g} Hz: tracking RMS {sn['tracking_rms']:.3g} {st['unit']} "
          f"({sn['tracking_rms_pct']:.1f} % of the reference RMS)")
    if "turbulence" in r:
        tb = r["turbulence"]
        extra = f", angle RMS {tb['angle_rms_deg']:.2f} deg (max {tb['angle_max_deg']:.2f})" \
            if "angle_rms_deg" in tb else ""
        print(f"  {tb['level']} turbulence: gust rate RMS {tb['gust_rate_rms_deg_s']:.1f} deg/s -> "
              f"rate RMS {tb['rate_rms_deg_s']:.2f} deg/s{extra}")


def _cmd_sweep(args) -> int:
    import os

    from .files import new_output_folder
    from .sweep import SWEEP_TLOG, default_plan, run_sweep

    amp = None
    if args.amplitude is not None:
        amp = math.radians(args.amplitude) if args.inject in ("angle", "rate") else args.amplitude
    plan = default_plan(args.axis, args.inject, args.freqs_hz, amp, args.cycles)
    if args.sil:       # a board applies the limits it was flashed with (and says why it refuses)
        from ..sim.sil import SilConfig

        for f, a in zip(plan.freqs_hz, plan.amplitudes):
            _check_excitation([f], plan.cycles, plan.fade_cycles, SilConfig.loop_hz, a,
                              args.inject)
    if not args.sil and args.fault:
        raise InputError("--fault needs --sil (a board's faults are real)")
    if not args.sil and args.firmware != "host":
        raise InputError("--firmware needs --sil (a board runs what is flashed on it)")
    created = new_output_folder(args.out, "a sweep")
    try:
        session, source = _sweep_session(args, os.path.join(args.out, SWEEP_TLOG))
    except BaseException:
        if created and not os.listdir(args.out):     # nothing recorded: leave nothing behind
            os.rmdir(args.out)
        raise
    print(f"sweep: {args.axis}, {args.inject} injection, {len(plan.freqs_hz)} frequencies "
          f"{plan.freqs_hz[0]:.3g}-{plan.freqs_hz[-1]:.3g} Hz -> {args.out}", flush=True)
    try:
        manifest = run_sweep(session, plan, args.out, source)
    except Exception as exc:                      # the firmware died, the port went away
        from ..sim.lockstep import FirmwareError

        if isinstance(exc, (FirmwareError, InputError)):
            raise InputError(f"{exc} (the log and manifest so far are kept in {args.out})") from None
        raise
    finally:
        session.close()
    done = sum(1 for f in manifest["frequencies"] if f["status"] == "ok")
    if manifest["complete"]:
        print(f"{done} of {len(plan.freqs_hz)} frequencies measured; complete; "
              f"next: heliquad identify {args.out}")
        return 0
    sys.stderr.write(f"heliquad sweep: {manifest['aborted']} ({done} of "
                     f"{len(plan.freqs_hz)} frequencies measured; the log and manifest are kept "
                     f"in {args.out})\n")
    return 1


def _sweep_session(args, tlog):
    """The session a sweep drives (the firmware in the loop, or a board's port) and the
    manifest's record of its source."""
    from . import paper
    from .sweep import PortSession

    if not args.sil:
        return PortSession(args.port, tlog, args.baud), \
            {"kind": "port", "port": args.port, "baud": args.baud}
    from ..sim.lockstep import FirmwareError
    from ..sim.sil import SilConfig, SilSession

    num, den = paper.MODELS[args.axis][paper.CHOSEN_ORDER[args.axis]]
    args.num, args.den = args.num or num, args.den or den
    _check_plant(args)
    cfg = SilConfig(axis=args.axis, num=tuple(args.num), den=tuple(args.den),
                    inject=args.inject, collective=args.collective, dmp_image=args.dmp_image,
                    plant=args.plant, rig=args.axis, params=args.params,
                    turbulence=args.turbulence, seed=args.seed, ideal_sensor=args.ideal_sensor,
                    faults=_faults(args), firmware=args.firmware)
    source = {"kind": "sil", "plant": args.plant, "num": list(args.num), "den": list(args.den),
              "params": args.params, "turbulence": args.turbulence, "seed": args.seed,
              "ideal_sensor": args.ideal_sensor}
    try:
        session = SilSession(cfg, tlog)
    except FirmwareError as exc:
        raise InputError(str(exc)) from None
    source["firmware"] = session.fw.record()
    if args.fault:
        source["faults"] = list(args.fault)
    return session, source


def _cmd_identify(args) -> int:
    import os

    from .fit import parse_order
    from .identify_session import identify_dir

    orders = [parse_order(o) for o in args.order] if args.order else None
    if not os.path.isdir(args.dir):
        raise InputError(f"{args.dir}: not a folder")
    r = identify_dir(args.dir, orders, delay=args.delay)
    print(f"{r['axis']}: {len(r['points'])} points")
    print(f"{'f (Hz)':>8} {'omega':>8} {'|G|':>9} {'phase':>9} {'R':>9} {'I':>9} {'coh':>7}")
    for p in sorted(r["points"], key=lambda q: q.omega_rad_s):
        print(f"{p.freq_hz:8.4g} {p.omega_rad_s:8.4g} {p.magnitude:9.4g} "
              f"{math.degrees(p.phase_rad):9.2f} {p.gain.real:9.4g} {p.gain.imag:9.4g} {p.coherence:7.4f}")
    _print_models(r["result"])
    print(f"wrote points.csv, points_table.csv, models.json, bode.png, responses.png in {args.dir}")
    if r["skipped"] or r["damage"]:
        n = len(r["points"]) + len(r["skipped"])
        sys.stderr.write(f"heliquad identify: warning: {len(r['skipped'])} of {n} measured "
                         "frequencies not used"
                         + (f"; the log is damaged: {r['damage'].summary()}" if r["damage"] else "")
                         + " (heliquad report flags it)\n")
    return 0


def _cmd_report(args) -> int:
    from .report import write_report

    print(f"wrote {write_report(args.dir, args.out)}")
    return 0


def _cmd_log(args) -> int:
    from .logsession import run_log

    if args.duration_s is not None and args.duration_s <= 0:
        raise InputError("--duration-s must be positive")
    print(f"logging {args.port} to {args.out} (Ctrl-C to stop)", flush=True)
    r = run_log(args.port, args.out, args.baud, args.duration_s)
    print(f"{r['seconds']:.1f} s: {r['messages']} messages, {r['samples']} samples"
          + (f" (seq {r['first_seq']}..{r['last_seq']})" if r["samples"] else "")
          + f", {r['lost']} lost; wrote {args.out}")
    return 0


def _cmd_tlog(args) -> int:
    from .logsession import summarise_tlog

    r = summarise_tlog(args.path)
    if not r["messages"] and r["damage"]:
        raise InputError(f"{args.path}: no MAVLink record in it (not a .tlog?)")
    if r["damage"]:
        print(f"warning: {r['damage']}", file=sys.stderr)
    print(f"{args.path}: {r['messages']} messages over {r['span_s']:.2f} s; {r['samples']} "
          f"samples, {r['lost']} lost")
    for name, count in r["types"].most_common():
        print(f"  {count:8d}  {name}")
    return 0


def _cmd_board(args) -> int:
    import os

    from ..sim.board import run_board
    from ..sim.lockstep import FirmwareError

    _check_plant(args)
    if os.path.exists(args.telemetry) and not os.path.islink(args.telemetry):
        raise InputError(f"--telemetry: {args.telemetry} exists and is not a link; choose "
                         "another path")
    try:
        r = run_board(args.axis, args.num, args.den, args.telemetry, loop_hz=args.loop_hz,
                      collective=args.collective, duration_s=args.duration_s,
                      dmp_image=args.dmp_image, firmware=args.firmware)
    except FirmwareError as exc:
        raise InputError(str(exc)) from None
    print(f"stopped after {r['frames']} frames ({r['frames'] / args.loop_hz:.1f} s); "
          f"fell behind real time {r['resyncs']} time(s)")
    return 0


def _check_plant(args) -> None:
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


def _describe_point(p) -> str:
    return (f"{p.freq_hz:.4g} Hz  |G| {p.magnitude:.5g} ({20 * math.log10(p.magnitude):+.2f} dB)"
            f"  phase {math.degrees(p.phase_rad):+.2f} deg  sigma {100 * p.sigma / p.magnitude:.2g} %"
            f"  coherence {p.coherence:.4f}  [{p.method}, {p.n_periods} periods of "
            f"{p.period_samples:.6g} samples]")


def _cmd_fit(args) -> int:
    from .files import read_points_csv, write_models_json, write_models_mat
    from .fit import n_parameters, parse_order
    from .identify import fit_orders

    points = read_points_csv(args.points)
    if args.order:
        orders = [parse_order(o) for o in args.order]
    else:
        n = points["omega"].size
        orders = [o for o in map(parse_order, DEFAULT_FIT_ORDERS)
                  if 2 * n >= n_parameters(o, args.delay) + 1]
        if not orders:
            raise InputError(f"{args.points}: {n} point(s) are too few for any default order")
    result = fit_orders(points, orders, weights=args.weights, delay=args.delay,
                        stable=not args.allow_unstable)
    _print_models(result)
    write_models_json(args.json, result.models, result.recommended, result.reason,
                      source=args.points, weights=result.weights)
    print(f"wrote {args.json}")
    if args.mat:
        write_models_mat(args.mat, result.models, result.recommended)
        print(f"wrote {args.mat}")
    if args.plot:
        from .plot import plot_bode

        sigma = points["sigma"]
        plot_bode(args.plot, points["omega"], points["F"], sigma=sigma, models=result.models,
                  recommended=result.recommended, title=str(args.points))
        print(f"wrote {args.plot}")
    return 0


def _print_models(result) -> None:
    print(f"weights: {result.weights}")
    print(f"{'order':>8} {'J':>9} {'rms %':>8} {'AICc':>10} {'max dB':>7} {'max deg':>8} "
          f"{'stable':>6}  model")
    for i, m in enumerate(result.models):
        k = m.metrics
        mark = "*" if i == result.recommended else " "
        order = f"{m.order[0]}/{m.order[1]}{'+d' if m.delay_fitted else ''}"
        print(f"{mark}{order:>7} {k['J']:9.3g} {100 * k['rms']:8.3g} {k['aicc']:10.4g} "
              f"{k['max_mag_err_db']:7.3f} {k['max_phase_err_deg']:8.2f} "
              f"{'yes' if m.stable else 'NO':>6}  {format_tf(m)}"
              + ("  [degenerate: a pole reached the edge of the allowed range; the points "
                 "do not support this order]" if m.degenerate else ""))
    print(f"recommended: {result.reason}")


def format_tf(model) -> str:
    """``(num) / (den)`` in descending powers of s, with the delay if any."""
    def poly(c):
        n = len(c) - 1
        terms = [f"{v:.5g}" + (f" s^{n - i}" if n - i > 1 else " s" if n - i == 1 else "")
                 for i, v in enumerate(c)]
        return " + ".join(terms).replace("+ -", "- ")
    text = f"({poly(model.num)}) / ({poly(model.den)})"
    if model.delay_fitted:
        text += f" * exp(-{model.delay_s * 1e3:.3g} ms s)"
    return text


def main(argv=None) -> int:
    """Entry point of the ``heliquad`` console script."""
    import signal

    from .errors import Terminated

    parser = _build_parser()
    args = parser.parse_args(argv)
    np.seterr(all="ignore")

    def on_sigterm(signum, frame):
        raise Terminated()
    signal.signal(signal.SIGTERM, on_sigterm)
    try:
        return args.func(args)
    except InputError as exc:
        sys.stderr.write(f"heliquad {args.command}: error: {exc}\n")
        return EXIT_INPUT
    except BrokenPipeError:              # e.g. piped into `head`: not an error
        sys.stderr.close()
        return 0
    except KeyboardInterrupt as exc:
        terminated = isinstance(exc, Terminated)
        sys.stderr.write(f"heliquad {args.command}: {'terminated' if terminated else 'interrupted'}\n")
        return 143 if terminated else 130
    except OSError as exc:
        sys.stderr.write(f"heliquad {args.command}: error: {exc.strerror or exc}: "
                         f"{exc.filename or ''}\n")
        return EXIT_INPUT


if __name__ == "__main__":
    sys.exit(main())
