"""The simulated rig as a board on a serial port (``heliquad board``)."""

from __future__ import annotations

import os

from ...sim.base import dialect as names
from ...sim.plant.vehicle import RIGS
from ...sim.rig.setup import PLANTS
from ...sim.base.errors import InputError, LinkLost
from ...sim.base.firmware_facts import LOOP_RATE_HZ, MAX_LOOP_RATE_HZ, MAX_PTY_BACKLOG_BYTES
from .run_options import add_load_params_argument, add_rc_script_argument
from .shared_options import (add_firmware_argument, firmware_link, add_param_store_argument,
                             add_sd_card_arguments, add_vehicle_arguments,
                             check_plant, finite, sd_card, vehicle_config, vehicle_rig,
                             int_in, number_in)

__all__ = ["add_parser", "run"]

HELP = """\
Run the simulated rig in real time as if it were a board on a serial port: the firmware
with a plant (a transfer function, or with --plant vehicle the 6-DoF vehicle on a rig, as
heliquad sil flies it), armed and hovering, stepping one loop per loop
period of wall-clock time. Its telemetry port appears at --telemetry; connect any MAVLink
tool to it as to a board's serial port (any baud rate is accepted and ignored); while it
runs, --port auto finds it by the USB identity it announces (docs/usb.md). Nothing reads the
telemetry for you: with no reader, the firmware drops and counts messages as a UART would.
Ground stations list and set its parameters (heliquad params, MAVProxy's param commands);
with --param-store they persist in a file across runs. Before it flies, the board is
given the geometry of a --params vehicle file (its CA_* parameters, as heliquad params
from-vehicle writes them) and the values of --load-params, in lockstep with the pilot
landed, as heliquad params load would set them; a value it refuses ends the run. With --sd-image it has an SD card:
it logs each arming there and serves the card's logs (heliquad logs, MAVProxy's log
commands) while disarmed. The firmware saves parameters only while
disarmed: on an orderly stop (Ctrl-C, SIGTERM, SIGHUP, the end of --duration-s) the
simulated pilot disarms first, as before a power-off, and the save completes before the
board stops; then it exits with 130, 143, 129 (or 0 for --duration-s).

example: heliquad board --axis roll --telemetry /tmp/rig &   then open /tmp/rig
"""



def add_parser(sub, fmt) -> None:
    p = sub.add_parser("board", help="run the simulated rig as if it were a board on a serial port",
                       description=HELP, formatter_class=fmt)
    p.add_argument("--plant", choices=PLANTS, default="tf",
                   help="tf: a transfer function from the axis's torque command to its body "
                        "rate (default); vehicle: the 6-DoF heterogeneous multirotor on a rig")
    add_vehicle_arguments(p, RIGS)
    p.add_argument("--axis", choices=tuple(names.AXES), default="roll")
    p.add_argument("--num", type=finite, nargs="+", metavar="B", default=[28.19])
    p.add_argument("--den", type=finite, nargs="+", metavar="A", default=[1.0, 5.13, 22.93])
    p.add_argument("--telemetry", default="heliquad-board", metavar="PATH",
                   help="where the telemetry serial port appears (default ./heliquad-board)")
    p.add_argument("--duration-s", type=number_in(0, 1e7, lo_open=True), metavar="S", help="stop after S seconds "
                   "(default: run until Ctrl-C)")
    p.add_argument("--collective", type=number_in(0, 1), default=0.4)
    p.add_argument("--disarmed", action="store_true",
                   help="the pilot leaves the arm switch and throttle low (default: armed, "
                        "hovering)")
    p.add_argument("--backlog-bytes", type=int_in(0, MAX_PTY_BACKLOG_BYTES), metavar="N",
                   help="the most telemetry that waits for a reader, the oldest dropped past "
                        "it, as a board's USB or UART buffer holds a few KiB (default "
                        f"{MAX_PTY_BACKLOG_BYTES}, the most the pty shows: a tool that opens the "
                        "port late reads about 0.2 s of the past, and one that stalls longer "
                        "loses samples); 0 keeps all of it, however late the reader")
    p.add_argument("--loop-hz", type=number_in(1, MAX_LOOP_RATE_HZ), default=LOOP_RATE_HZ)
    p.add_argument("--dmp-image", metavar="FILE")
    add_param_store_argument(p)
    add_sd_card_arguments(p)
    add_firmware_argument(p)
    add_rc_script_argument(p)
    add_load_params_argument(p)
    p.set_defaults(func=run)


def run(args) -> int:
    # the command's work, imported when it runs: --help imports every command module
    from ...sim.rig.board import run_board
    from ...sim.rig.lockstep import FirmwareError
    from ...sim.rig.setup import SilConfig, make_plant

    check_plant(args)
    rig = vehicle_rig(args)
    if args.plant != "vehicle" and (args.turbulence or args.params or args.ideal_sensor or
                                    args.rig or args.hinge_friction is not None):
        raise InputError("--rig, --params, --turbulence, --ideal-sensor and --hinge-friction "
                         "need --plant vehicle")
    cfg = SilConfig(axis=args.axis, num=tuple(args.num), den=tuple(args.den), plant=args.plant,
                    rig=rig, **vehicle_config(args), collective=args.collective,
                    loop_hz=args.loop_hz)
    if args.rc_script is not None and args.disarmed:
        raise InputError("--rc-script is the pilot (it arms or not): leave out --disarmed")
    card = sd_card(args)
    if os.path.exists(args.telemetry) and not os.path.islink(args.telemetry):
        raise InputError(f"--telemetry: {args.telemetry} exists and is not a link; choose "
                         "another path")
    try:
        r = run_board(lambda dt_s: make_plant(cfg, dt_s), args.telemetry, loop_hz=args.loop_hz,
                      collective=args.collective, duration_s=args.duration_s,
                      dmp_image=args.dmp_image, firmware=args.firmware, params_file=args.param_store,
                      link=firmware_link(args),
                      armed=not args.disarmed, usb_serial=_usb_serial(args.firmware),
                      rc_script=args.rc_script, configure=_preflight(args),
                      **card,
                      **({} if args.backlog_bytes is None else {"backlog_bytes": args.backlog_bytes}))
    except FirmwareError as exc:
        raise LinkLost(str(exc)) from None
    print(f"stopped after {r['frames']} frames ({r['frames'] / args.loop_hz:.1f} s); "
          f"fell behind real time {r['resyncs']} time(s)"
          + ("" if r["landed"] else "; the board did not disarm, so nothing was saved"))
    if r["stopped_by"] is not None:              # said, and its code, by the command line
        raise r["stopped_by"]
    return 0


def _preflight(args):
    """What sets the board's parameters before it flies (a vehicle file's geometry,
    --load-params), or None when there is nothing to set."""
    # the command's work, imported when it runs: --help imports every command module
    from ..acquire.preflight import LandedRigLink, preflight_sets, set_on_board

    sets = preflight_sets(args.params if args.plant == "vehicle" else None, args.load_params)
    if not sets:
        return None

    def configure(rig) -> None:
        link = LandedRigLink(rig)
        try:
            set_on_board(link, sets)
        finally:
            link.close()

    return configure


def _usb_serial(firmware: str) -> str:
    """The USB serial number the board announces: the emulated chip's (from its unique
    identification, as the image's descriptor derives it), or the host build's."""
    # the command's work, imported when it runs: --help imports every command module
    from ...sim.base.firmware_facts import usb_serial_number
    from ...sim.rig.announce import HOST_BUILD_SERIAL

    if firmware == "host":
        return HOST_BUILD_SERIAL
    # the emulated chip (and unicorn under it) only for --firmware teensy35
    from ...sim.chip.clocks import Sim

    return usb_serial_number(Sim.UID[name] for name in ("UIDH", "UIDMH", "UIDML", "UIDL"))
