"""``heliquad verify DIR``: tuned gains proven on the simulated rig or a board, the previous
ones restored otherwise (docs/verification.md)."""

from __future__ import annotations

import importlib
import sys

from ...sim.base import dialect as names
from ...sim.base.errors import InputError
from .shared_options import (add_baud_argument, add_param_store_argument, add_port_argument,
                             add_vehicle_arguments, check_plant, int_in, number_in,
                             vehicle_config)

__all__ = ["add_parser", "run"]

HELP = """\
Prove the gains `heliquad tune` designed (DIR holds its tune.json and tuned.params) on the
board, one axis per run (the rig frees one axis). It reads the parameters the axis's tuned
gains change and keeps them in DIR/previous.params, sets the tuned values and reads them
back, then flies a sweep at the rate setpoint (and for roll and pitch one at the angle
setpoint), each over the band from half the loop's lowest predicted crossover to 1.5 times
its highest, and measures the loops from them: the rate loop (broken at the plant input)
and for roll and pitch the angle loop (broken at the rate setpoint). The gains are accepted
when every measured margin lies within its prediction's uncertainty (tune.json's, never
tighter than 1 dB and 5 deg) and is not below the specification; otherwise the previous
gains go back on the board, read back, and each failed loop is said in one line (exit 1).
DIR/verify/AXIS/ keeps the sweeps (rate/, angle/, their session.tlog) and DIR/verify.json
predicted, measured (and on the simulated rig the simulator's truth) margins, the verdict
and what was restored. Ctrl-C restores the previous gains before it exits; a lost link is
said with the gains the board holds.

--sil: the whole verification on one simulated board on the axis's rig (its parameters
kept in --param-store FILE, so `heliquad board --param-store FILE` flies what verify left).

example: heliquad tune roll/models.json --out tuned && heliquad verify --sil --axis roll tuned
"""


def add_parser(sub, fmt) -> None:
    p = sub.add_parser("verify", help="prove tuned gains on the board, restore the old ones "
                       "otherwise", description=HELP, formatter_class=fmt)
    p.add_argument("dir", metavar="DIR", help="the folder of tune.json and tuned.params")
    p.add_argument("--axis", choices=tuple(names.AXES),
                   help="the axis to verify (default: tune.json's only axis)")
    where = p.add_mutually_exclusive_group(required=True)
    where.add_argument("--sil", action="store_true", help="the simulated rig, in lockstep")
    add_port_argument(where, required=False)
    add_baud_argument(p)
    p.add_argument("--signal", choices=("multisine", "dwell"), default="multisine",
                   help="the sweeps' signal (default multisine: the band at once)")
    p.add_argument("--lines", type=int_in(2, 60), metavar="N",
                   help="multisine: its lines (default the most the firmware takes); dwell: "
                        "its frequencies (default 8)")
    p.add_argument("--rig-time", type=number_in(1, 3600), metavar="S",
                   help="multisine: each sweep's length, s (default 20; a loop whose lowest "
                        "crossover needs longer gets the least that holds 3 periods of its "
                        "lowest line and its fades)")
    p.add_argument("--cycles", type=int_in(1, 1000), metavar="N",
                   help="dwell: N measured cycles per frequency (default: the sequential dwell)")
    p.add_argument("--rate-amplitude", type=number_in(0, 1e3, lo_open=True), metavar="DEG_S",
                   help="the rate setpoint sweep's peak, deg/s (default 20, less when the tuned "
                        "rate Kc would swing the axis's command past half its bound)")
    p.add_argument("--angle-amplitude", type=number_in(0, 90, lo_open=True), metavar="DEG",
                   help="the angle setpoint sweep's peak, deg (default 5)")
    add_vehicle_arguments(p)
    p.add_argument("--collective", type=number_in(0, 1), default=0.4,
                   help="--sil: the hover's throttle (default 0.4)")
    add_param_store_argument(p)
    p.set_defaults(func=run)


def run(args) -> int:
    # the command's work, imported when it runs: --help imports every command module
    from ..acquire.excitation import firmware_amplitude
    from ..campaign.verify import prepare_verification, run_verification

    # fsf (with scipy) and python-control now, not while the board flies: a Ctrl-C that
    # lands inside an import leaves Python to end by SIGINT after the tool has stopped.
    importlib.import_module("heliquad.host.estimate.fsf")
    importlib.import_module("control")
    if not args.sil and (args.param_store or args.turbulence or args.params):
        raise InputError("--param-store, --turbulence and --params need --sil (a board keeps "
                         "its parameters in its flash and flies in the air it has)")
    amplitudes = {k: firmware_amplitude(k, v) for k, v in
                  (("rate", args.rate_amplitude), ("angle", args.angle_amplitude))
                  if v is not None}
    plan = prepare_verification(args.dir, args.axis, signal=args.signal, lines=args.lines,
                                rig_time_s=args.rig_time, cycles=args.cycles,
                                amplitudes=amplitudes,
                                board="sil" if args.sil else f"port {args.port}")
    if args.sil:
        args.plant, args.num, args.den = "vehicle", None, None
        check_plant(args)
    code, lines = run_verification(plan, _opener(args))
    if code == 0:
        print(f"accepted: the tuned {plan.axis} gains are on the board ({args.dir}/verify.json)")
    for line in lines:
        sys.stderr.write(f"heliquad verify: {line}\n")
    return code


def _opener(args):
    """What opens the session verify flies: the simulated board on the axis's rig, or a
    board's port (a ``(session, manifest source)`` for the tlog path it is given)."""
    # the command's work, imported when it runs: --help imports every command module
    from ..acquire.ports import AUTO, auto_board
    from ..acquire.session import PortSession
    from ..campaign.verify import sil_session

    if args.sil:
        return lambda axis, tlog: sil_session(
            axis, tlog, **vehicle_config(args), collective=args.collective,
            param_store=args.param_store)

    def port_session(axis, tlog):
        board = auto_board() if args.port == AUTO else None
        port = args.port if board is None else board.device
        return PortSession(port, tlog, args.baud), {"kind": "port", "port": port,
                                                    "baud": args.baud}

    return port_session
