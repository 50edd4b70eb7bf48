"""One sine experiment with the firmware in the loop (``heliquad sil``)."""

from __future__ import annotations

import os
import sys

from ...sim.base import dialect as names
from ..acquire.link import INPUT_OUTPUT
from ...sim.base.errors import DiskFull, InputError, LinkLost
from ...sim.base.firmware_facts import LOOP_RATE_HZ, MAX_LOOP_RATE_HZ
from ...sim.plant.vehicle import RIGS
from ...sim.rig.setup import PLANTS
from ..acquire.excitation import firmware_amplitude
from .run_options import add_load_params_argument, add_rc_script_argument
from .shared_options import (MAX_CYCLES, add_fault_argument, add_firmware_argument, firmware_link,
                             add_vehicle_arguments, vehicle_config, vehicle_rig,
                             add_param_store_argument, add_sd_card_arguments,
                             check_plant, faults, finite, int_in, number_in, sd_card)
from .sweep_options import check_excitation

__all__ = ["add_parser", "run"]

HELP = """\
Run one sine experiment with the firmware in the loop: the host build of the firmware is
driven in lockstep over a pty by the simulated rig (a transfer-function plant from the
axis's normalised torque command to its body rate, rad/s), armed and held at hover, and
excited over the telemetry link exactly as a real board would be.

Writes RUN.tlog (every telemetry message, stamped with the run's start on the wall clock
plus simulated time, so tools show when it ran; pymavlink reads it)
and RUN.csv (t_s,u,y over the full-amplitude cycles, for heliquad fsf). u and y follow the
injection point: mixer -> u torque command, y rate; rate -> u rate setpoint, y rate (rad/s);
angle -> u angle setpoint, y angle (rad).

example: heliquad sil --axis roll --inject mixer --freq-hz 1 --amplitude 0.05 --out run1
"""



def add_parser(sub, fmt) -> None:
    p = sub.add_parser("sil", help="one sine experiment with the firmware in the loop",
                       description=HELP, formatter_class=fmt)
    p.add_argument("--plant", choices=PLANTS, default="tf",
                   help="tf: a transfer function from the axis's torque command to its body "
                        "rate (default); vehicle: the 6-DoF heterogeneous multirotor on a rig")
    add_vehicle_arguments(p, RIGS)
    add_load_params_argument(p)
    p.add_argument("--axis", choices=tuple(names.AXES), default="roll")
    p.add_argument("--num", type=finite, nargs="+", metavar="B", default=[28.19],
                   help="numerator, descending powers of s (default: the paper's roll model)")
    p.add_argument("--den", type=finite, nargs="+", metavar="A", default=[1.0, 5.13, 22.93],
                   help="denominator, descending powers of s")
    p.add_argument("--inject", choices=tuple(INPUT_OUTPUT), default="mixer")
    p.add_argument("--freq-hz", type=number_in(0, 1e6, lo_open=True), required=True, metavar="F")
    p.add_argument("--amplitude", type=number_in(0, 1e6, lo_open=True), required=True, metavar="A",
                   help="deg for angle, deg/s for rate, normalised torque (-1..1) for mixer")
    p.add_argument("--cycles", type=int_in(1, MAX_CYCLES), default=10, help="full-amplitude cycles (default 10)")
    p.add_argument("--fade-cycles", type=int_in(1, MAX_CYCLES), default=2,
                   help="cycles of fade in and of fade out, also the settling (default 2; the "
                        "firmware needs at least 1)")
    p.add_argument("--collective", type=number_in(0, 1), default=0.4,
                   help="hover throttle as a fraction of stick travel (default 0.4)")
    p.add_argument("--loop-hz", type=number_in(1, MAX_LOOP_RATE_HZ), default=LOOP_RATE_HZ,
                   help=f"firmware loop rate (default {LOOP_RATE_HZ:g})")
    p.add_argument("--dmp-image", metavar="FILE",
                   help="MotionApps 2.0 DMP firmware file for the firmware, made with "
                        "heliquad dmp-image (default: raw FIFO path)")
    p.add_argument("--out", required=True, metavar="RUN",
                   help="writes RUN.tlog (all telemetry) and RUN.csv (t_s,u,y)")
    add_firmware_argument(p)
    add_param_store_argument(p)
    add_sd_card_arguments(p)
    add_fault_argument(p)
    add_rc_script_argument(p)
    p.set_defaults(func=run)


def run(args) -> int:
    # the command's work, imported when it runs: --help imports every command module
    from ...sim.rig.lockstep import FirmwareError
    from ...sim.rig.setup import SilConfig
    from ..acquire.experiment import run_sil

    check_plant(args)
    if args.inject == "angle" and args.axis == "yaw":
        raise InputError("yaw is rate-only: use --inject rate or mixer")
    amplitude = firmware_amplitude(args.inject, args.amplitude)
    check_excitation([args.freq_hz], args.cycles, args.fade_cycles, args.loop_hz, amplitude,
                      args.inject)
    folder = os.path.dirname(os.path.abspath(args.out))
    if not os.path.isdir(folder):
        raise InputError(f"--out: folder {folder} does not exist")
    rig = vehicle_rig(args)
    cfg = SilConfig(axis=args.axis, num=tuple(args.num), den=tuple(args.den), inject=args.inject,
                    freq_hz=args.freq_hz, amplitude=amplitude, cycles=args.cycles,
                    fade_cycles=args.fade_cycles, loop_hz=args.loop_hz,
                    collective=args.collective, dmp_image=args.dmp_image, plant=args.plant,
                    rig=rig, **vehicle_config(args),
                    param_store=args.param_store, load_params=args.load_params,
                    faults=faults(args), firmware=args.firmware,
                    firmware_link=firmware_link(args), rc_script=args.rc_script,
                    **sd_card(args))
    if (args.turbulence or args.hinge_friction is not None) and args.plant != "vehicle":
        raise InputError("--turbulence and --hinge-friction need --plant vehicle")
    try:
        r = run_sil(cfg, args.out)
    except FirmwareError as exc:         # the board is gone (exit 1), not the user's input
        raise LinkLost(str(exc)) from None
    except DiskFull as exc:
        raise exc.also("the run is stopped; the log up to here is kept")
    print(f"{r.frames} frames ({r.frames / args.loop_hz:.2f} s simulated) in {r.wall_s:.2f} s "
          f"wall ({r.frames / args.loop_hz / r.wall_s:.2g}x real time); firmware "
          f"{args.firmware}{' over ' + cfg.firmware_link if args.firmware == 'teensy35' else ''}"
          f"; imu path {r.imu_mode}")
    print(f"excitation at {r.actual_freq_hz:.6g} Hz; {r.samples} full-amplitude samples; "
          f"{r.seq_gaps} telemetry gaps")
    # the command's work, imported when it runs: --help imports every command module
    from ..acquire.measure import saturation_summary

    said = saturation_summary(r.saturation)
    if said:
        print(f"warning: measured samples: {said}; the record is not the linear response: "
              "lower --amplitude", file=sys.stderr)
    if args.firmware != "host" and r.firmware_summary:
        print(f"the board: {r.firmware_summary.removeprefix('heliquad-fw-pil: ')}")
    print(f"wrote {r.tlog_path} and {r.csv_path}")
    if r.stopped:
        print(f"heliquad sil: {r.stopped} (the log and the samples before it are kept)",
              file=sys.stderr)
        return 1
    return 0
