"""``heliquad verify DIR``: tuned gains proven on the simulated rig or a board, the previous
ones restored otherwise (docs/verification.md)."""

from __future__ import annotations

import importlib
import os
import sys

from ...sim.base import dialect as names
from ...sim.base.errors import InputError
from .shared_options import (add_baud_argument, add_param_store_argument, add_port_argument,
                             add_vehicle_arguments, check_plant, int_in, number_in)

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
    from ..campaign.verify import SESSION_TLOG, VerifyPlan, verify_axis
    from ..acquire.excitation import firmware_amplitude

    # fsf (with scipy) and python-control now, not while the board flies: a Ctrl-C that
    # lands inside an import leaves Python to end by SIGINT after the tool has stopped.
    importlib.import_module("heliquad.host.estimate.fsf")
    importlib.import_module("control")
    tune, axis, entries = _read_dir(args)
    if not args.sil and (args.param_store or args.turbulence or args.params):
        raise InputError("--param-store, --turbulence and --params need --sil (a board keeps "
                         "its parameters in its flash and flies in the air it has)")
    amplitudes = {k: firmware_amplitude(k, v) for k, v in
                  (("rate", args.rate_amplitude), ("angle", args.angle_amplitude))
                  if v is not None}
    plan = VerifyPlan(axis=axis, dir=args.dir, tune=tune, entries=entries, signal=args.signal,
                      lines=args.lines, rig_time_s=args.rig_time, cycles=args.cycles,
                      amplitudes=amplitudes, board="sil" if args.sil else f"port {args.port}")
    for loop in plan.loops:             # a band or amplitude the firmware refuses: said now
        plan.sweep_plan(loop)
    axis_dir = os.path.join(args.dir, "verify", axis)
    if os.path.lexists(axis_dir):
        raise InputError(f"{axis_dir} holds an earlier verification of {axis}: move it away "
                         "first (verify.json keeps what it found)")
    os.makedirs(axis_dir)
    session, source = _session(args, axis, os.path.join(axis_dir, SESSION_TLOG))
    try:
        print(f"verify: {axis} on {plan.board} -> {axis_dir}", flush=True)
        code, lines = verify_axis(session, source, plan)
    finally:
        _close(session, args.sil)
    if code == 0:
        print(f"accepted: the tuned {axis} gains are on the board ({args.dir}/verify.json)")
    for line in lines:
        sys.stderr.write(f"heliquad verify: {line}\n")
    return code


def _read_dir(args) -> tuple:
    """``(tune.json's TuneFile, the axis, the tuned values it loads)`` of DIR: tune.json
    and tuned.params there, the axis tuned, tuned.params holding tune.json's values."""
    # the command's work, imported when it runs: --help imports every command module
    from ..acquire.param_protocol import same_value
    from ..records.params_file import read_params_file
    from ..records.tune import read_tune

    if not os.path.isdir(args.dir):
        raise InputError(f"{args.dir} is not a folder (heliquad tune --out DIR writes one)")
    paths = [os.path.join(args.dir, n) for n in ("tune.json", "tuned.params")]
    for path in paths:
        if not os.path.isfile(path):
            raise InputError(f"{args.dir} has no {os.path.basename(path)} (heliquad tune "
                             "--out DIR writes tune.json and tuned.params)")
    tune = read_tune(paths[0])
    tuned = {p.name: p.value for p in read_params_file(paths[1])}
    axis = args.axis
    if axis is None:
        if len(tune.axes) > 1:
            raise InputError(f"{paths[0]} tunes {', '.join(tune.axes)}: give --axis (the rig "
                             "frees one axis; verify one per run)")
        axis = next(iter(tune.axes))
    if axis not in tune.axes:
        raise InputError(f"--axis {axis}: {paths[0]} tunes {', '.join(tune.axes)} only")
    entries = []
    for name, value in tune.axes[axis]["params"].items():
        if name not in tuned or not same_value(tuned[name], value):
            raise InputError(f"{paths[1]}: {name} is "
                             f"{'missing' if name not in tuned else tuned[name]}, tune.json "
                             f"says {value:g} (tuned.params and tune.json are not of one run)")
        entries.append((name, tuned[name]))
    return tune, axis, entries


def _session(args, axis: str, tlog: str) -> tuple:
    """The session verify flies (the simulated board on the axis's rig, or a board's port)
    and the sweeps' manifest source."""
    # the command's work, imported when it runs: --help imports every command module
    from ..acquire.ports import AUTO, auto_board
    from ..acquire.session import PortSession, SilSession
    from ..acquire.sweep import sil_source
    from ...sim.rig.lockstep import FirmwareError
    from ...sim.rig.setup import SilConfig

    if not args.sil:
        board = auto_board() if args.port == AUTO else None
        port = args.port if board is None else board.device
        return PortSession(port, tlog, args.baud), {"kind": "port", "port": port,
                                                    "baud": args.baud}
    args.plant, args.num, args.den = "vehicle", None, None
    check_plant(args)
    cfg = SilConfig(axis=axis, rig=axis, inject="rate", plant="vehicle", params=args.params,
                    turbulence=args.turbulence, seed=args.seed, ideal_sensor=args.ideal_sensor,
                    collective=args.collective, param_store=args.param_store)
    source = sil_source(cfg)
    try:
        session = SilSession(cfg, tlog)
    except FirmwareError as exc:
        raise InputError(str(exc)) from None
    source["firmware"] = session.fw.record()
    return session, source


def _close(session, sil: bool) -> None:
    """The session closed; the simulated board lands first, so that the firmware saves the
    parameters changed while it flew (--param-store)."""
    try:
        if sil:
            session.land()
    finally:
        session.close()
