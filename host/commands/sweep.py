"""An axis's sweep (the paper's sine dwells, or one multisine) on the simulated rig or a
board (``heliquad sweep``)."""

from __future__ import annotations

import importlib
import math
import os
import sys

from ...sim.base import dialect as names
from ..acquire.link import INPUT_OUTPUT, ROTOR_INPUT_OUTPUT, check_response
from ...sim.base.errors import DiskFull, InputError, LinkLost
from ...sim.base.firmware_facts import ABORT_ANGLE_RAD, ABORT_RATE_RAD_S, MAX_ROTORS, MIN_ROTORS
from ...sim.rig.setup import PLANTS
from ..acquire.excitation import DEFAULT_SETPOINT
from ..acquire.multisine import MAX_LINES
from ..acquire.rotor_multisine import ROTOR_PEAK
from ..records.choices import RESPONSES
from ..process.signals import ABORTED_BY, EXIT_CODES
from .run_options import add_load_params_argument, add_rc_script_argument
from .shared_options import (add_baud_argument, add_fault_argument, add_firmware_argument,
                             firmware_link, add_vehicle_arguments, add_param_store_argument,
                             add_port_argument, add_sd_card_arguments, check_plant, faults,
                             finite, int_in, number_in, sd_card, vehicle_config)
from .sweep_options import add_design_arguments, apply_tuning_band, check_excitation, sweep_plan

__all__ = ["add_parser", "run", "checked_plan"]

HELP = f"""\
Run the paper's sine sweep for one axis: the band of its Table 1, 15 log-spaced frequencies
(or --freqs-hz), each faded in over 2 cycles (--fade-cycles; the settling), measured, out.
The dwell is sequential by default: at least 8 measured cycles (the paper's dwell), then
until the point's standard deviation is --target-sigma of its magnitude (estimated against
the excitation after every cycle) or --max-cycles (and at most 60 s) have run, when the
firmware finishes the cycle under way and fades out; --cycles N gives every frequency
exactly N. A mixer sweep's amplitude is designed per frequency for a rig swing of
--swing-deg (from what the previous frequency measured, within the firmware's bound);
--amplitude gives one for all. --sil flies the simulated rig in lockstep (the 6-DoF vehicle on the axis's rig by
default); --port talks to a board in real time: its serial port, a `heliquad board` pty, auto
(the one heliquad board attached or running), or a network link (udpin:HOST:PORT, udpout:, tcp:, tcpin:, as MAVProxy writes them). Writes
DIR/sweep.tlog (every message) and DIR/manifest.json (axis, frequencies requested and used,
windows, gains, firmware, start time), kept valid on Ctrl-C. An angle beyond {math.degrees(ABORT_ANGLE_RAD):g} deg or a
rate beyond {math.degrees(ABORT_RATE_RAD_S):g} deg/s stops the excitation and the sweep (exit 1).
Input and output for `heliquad identify`: mixer -> the axis's torque command and the rate
(the plant; default, the paper's rate-in rate-out model); rate -> rate setpoint and rate;
angle -> angle setpoint and angle.

--signal multisine excites the whole band at once instead: --lines log-spaced lines (default
15) on harmonics of one base period (chosen for the rig time, or --base-period), phases for a
low crest factor, faded in and out over a cycle of the lowest line (--fade-cycles), as many
whole base periods as fit --rig-time (default 60 s, at least 3 periods); --amplitude is its peak (default: {DEFAULT_SETPOINT['angle']:g} deg angle, {DEFAULT_SETPOINT['rate']:g} deg/s rate, the
firmware's bound at the mixer). identify estimates every line from the one record.

--signal chirp sweeps the band once instead, as ArduPilot's SystemID mode does: from its
bottom to its top (or the lowest and highest of --freqs-hz) over --rig-time seconds at full
amplitude (default 60), logarithmically (--chirp log, the default) or linearly, faded in over
whole cycles held at the bottom (as many as fit 12 s, at most 6) and out as long at the top;
--amplitude is its amplitude
(default: 0.25 at the mixer, the dwell's setpoints for angle and rate). identify estimates it
by the composite of overlapped windows of several lengths, with coherence per point.

--inject motors is the per-rotor run of `heliquad effectiveness` (docs/effectiveness.md): one
multisine in which every rotor has odd harmonics of its own (HQ_INJECTION_MOTORS: harmonic j
to rotor j mod --rotors), added to each rotor's thrust after the allocation while the cascade
flies the axis; {MAX_LINES} lines shared out (--lines fewer), the highest at the band's top (Table 1,
or the highest of --freqs-hz), the shortest base period that holds them, as many periods as fit
--rig-time; --amplitude is each rotor's peak, thrust fraction (default {ROTOR_PEAK:g}).
--inject motorN (motor1 the central rotor) is one rotor's run alone: every line its own.

example: heliquad sweep --axis roll --sil --out roll_sweep && heliquad identify roll_sweep
         heliquad sweep --axis roll --sil --signal multisine --out roll_ms
         heliquad sweep --axis roll --sil --signal chirp --out roll_chirp
         heliquad sweep --axis yaw --sil --inject motors --out yaw_rotors
"""



def add_parser(sub, fmt) -> None:
    p = sub.add_parser("sweep", help="run an axis's sine sweep (SIL or a board) and log it",
                       description=HELP, formatter_class=fmt)
    p.add_argument("--axis", choices=tuple(names.AXES), required=True)
    p.add_argument("--inject", choices=(*INPUT_OUTPUT, *ROTOR_INPUT_OUTPUT), default="mixer",
                   help="the axis's injection point (default mixer), or motors: the per-rotor "
                        "run, motorN: rotor N's alone (below)")
    p.add_argument("--response", choices=RESPONSES,
                   help="rate or angle injection: what the sweep measures and identify "
                        "fits; loop (default): the setpoint to the rate or angle; plant: "
                        "the mixer's input to the rate, against the excitation at the "
                        "setpoint, as a mixer sweep measures it (under strong turbulence "
                        "the better way to the plant at low frequencies, where the loop "
                        "cancels a mixer injection but follows a setpoint's: "
                        "docs/method.md)")
    p.add_argument("--rotors", type=int_in(MIN_ROTORS, MAX_ROTORS), metavar="N",
                   help="--inject motors or motorN: the rotors the board flies (its CA_ROTOR_COUNT; "
                        "default: the --params vehicle's with --sil, else the firmware's "
                        "default geometry's)")
    where = p.add_mutually_exclusive_group(required=True)
    where.add_argument("--sil", action="store_true", help="the simulated rig, in lockstep")
    add_port_argument(where, required=False)
    add_baud_argument(p)
    p.add_argument("--plant", choices=PLANTS, default="vehicle",
                   help="--sil: the 6-DoF vehicle (default) or a transfer function")
    p.add_argument("--num", type=finite, nargs="+", metavar="B",
                   help="--plant tf: numerator (default: the paper's chosen model of the axis)")
    p.add_argument("--den", type=finite, nargs="+", metavar="A", help="--plant tf: denominator")
    add_vehicle_arguments(p)
    add_load_params_argument(p)
    p.add_argument("--collective", type=number_in(0, 1), default=0.4)
    p.add_argument("--dmp-image", metavar="FILE")
    add_design_arguments(p)
    p.add_argument("--out", required=True, metavar="DIR")
    add_firmware_argument(p)
    add_param_store_argument(p)
    add_sd_card_arguments(p, "--sil: ")
    add_fault_argument(p, "--sil: ")
    add_rc_script_argument(p)
    p.set_defaults(func=run)


def run(args) -> int:
    # the command's work, imported when it runs: --help imports every command module
    from ..acquire.sweep import SWEEP_TLOG, run_sweep
    from ..records.output import new_output_folder

    # fsf (with scipy) is imported now, not by the first dwell check or amplitude design
    # while the sweep runs: a Ctrl-C that lands inside an import leaves Python to end by
    # SIGINT after the tool has stopped in order.
    importlib.import_module("heliquad.host.estimate.fsf")
    plan = checked_plan(args)
    created = new_output_folder(args.out, "a sweep")
    try:
        session, source, found = _sweep_session(args, os.path.join(args.out, SWEEP_TLOG))
    except BaseException:
        if created and not os.listdir(args.out):     # nothing recorded: leave nothing behind
            os.rmdir(args.out)
        raise
    try:
        print(f"sweep: {args.axis}, {args.inject} injection, {_what(plan)} -> {args.out}",
              flush=True)
        if found is not None:             # a simulated board never passes for the rig unseen
            print(f"port auto found: {_found_text(found)}", flush=True)
        manifest = run_sweep(session, plan, args.out, source, port_found=found)
    except Exception as exc:          # a full disk, the firmware died, the port went away
        return _ended(exc, args.out)
    finally:
        session.close()
    done = sum(1 for f in manifest["frequencies"] if f["status"] == "ok")
    if manifest["complete"]:
        then = "effectiveness" if args.inject in ROTOR_INPUT_OUTPUT else "identify"
        print(f"{done} of {len(plan.freqs_hz)} frequencies measured; complete; "
              f"next: heliquad {then} {args.out}")
        return 0
    sys.stderr.write(f"heliquad sweep: {manifest['aborted']} ({done} of "
                     f"{len(plan.freqs_hz)} frequencies measured; the log and manifest are kept "
                     f"in {args.out})\n")
    # Stopped by a signal: its code (130, 143, 129), after the same orderly stop; else 1.
    return next((EXIT_CODES[s] for s, how in ABORTED_BY.items() if manifest["aborted"] == how), 1)


def checked_plan(args):
    """The sweep's plan from its options, refused (InputError) as the firmware would refuse
    it, and the simulated rig's options checked: all before anything is made or flies (also
    what ``heliquad study`` checks of every run before any starts)."""
    plan = rotor_plan(args) if args.inject in ROTOR_INPUT_OUTPUT else sweep_plan(args)
    if args.sil:       # a board applies the limits it was flashed with (and says why it refuses)
        # the command's work, imported when it runs: --help imports every command module
        from ...sim.rig.setup import SilConfig

        if plan.chirp is not None:           # checked by its design (acquire/chirp.py)
            pass
        elif plan.multisine is not None:     # its lines in the band, its peak in bounds
            check_excitation(plan.multisine.freqs_hz[[0, -1]], 1, 1, SilConfig.loop_hz,
                             plan.multisine.peak, args.inject)
        else:
            for f, a in zip(plan.freqs_hz, plan.amplitudes):
                check_excitation([f], plan.cycles_for(f), plan.fade_cycles, SilConfig.loop_hz,
                                 a, args.inject)
    _check_rig_options(args)
    return plan


def rotor_plan(args):
    """The per-rotor run's plan (``--inject motors``): one multisine whose lines are shared
    out among the rotors (:func:`~heliquad.host.acquire.rotor_multisine.rotor_design`)."""
    # the command's work, imported when it runs: --help imports every command module
    from ..acquire.excitation import amplitude_bound
    from ..acquire.rotor_multisine import rotor_design
    from ..acquire.sweep import SweepPlan
    from ..records import paper

    given = [o for o, v in (("--cycles", args.cycles), ("--target-sigma", args.target_sigma),
                            ("--max-cycles", args.max_cycles), ("--swing-deg", args.swing_deg))
             if v is not None]
    if given:
        raise InputError(f"{' and '.join(given)} shape a dwell; the per-rotor run is one "
                         "multisine, its length --rig-time")
    given = [o for o, v in (("--fade-cycles", args.fade_cycles),
                            ("--base-period", args.base_period),
                            ("--redesign", args.redesign or None)) if v is not None]
    if given:
        raise InputError(f"{' and '.join(given)} do not shape the per-rotor run: its lines, "
                         "base period and fades are its own design's, its length --rig-time")
    peak = ROTOR_PEAK if args.amplitude is None else args.amplitude
    if peak > amplitude_bound("motors"):
        raise InputError(f"--amplitude {peak:g} is above the firmware's bound for a rotor's "
                         f"injection ({amplitude_bound('motors'):g}, EXC_MAX_MOT)")
    apply_tuning_band(args)
    top = max(args.freqs_hz) if args.freqs_hz else paper.BANDS_HZ[args.axis][1]
    rotors = _rotors(args)
    only = None if args.inject == "motors" else int(args.inject[len("motor"):]) - 1
    if only is not None and only >= rotors:
        raise InputError(f"--inject {args.inject}: the board flies {rotors} rotors "
                         f"(motor1 to motor{rotors})")
    ms = rotor_design(top, rotors, peak, args.lines or MAX_LINES,
                      *([args.rig_time] if args.rig_time else []), only=only)
    return SweepPlan.of_multisine(args.axis, args.inject, ms)


def _rotors(args) -> int:
    """The rotors a per-rotor run shares its lines among: --rotors, else the simulated
    vehicle's, else the firmware's default geometry's."""
    if args.rotors is not None:
        return args.rotors
    if args.sil:
        # the vehicle file's reader, imported when it runs: --help imports every command module
        from ...sim.plant.vehicle_params import load_params
        return len(load_params(args.params).rotors)
    # the firmware's bindings, imported when it runs: --help imports every command module
    from heliquad import _firmware
    return int(_firmware.params_geometry().count)


def _check_rig_options(args) -> None:
    """The simulated rig's options: refused without --sil, their combinations checked with it
    (before the sweep's folder is made)."""
    if not args.sil and args.fault:
        raise InputError("--fault needs --sil (a board's faults are real)")
    if not args.sil and args.firmware != "host":
        raise InputError("--firmware needs --sil (a board runs what is flashed on it)")
    if not args.sil and args.rc_script is not None:
        raise InputError("--rc-script needs --sil (a board's pilot is a person with a radio)")
    if not args.sil and args.param_store:
        raise InputError("--param-store needs --sil (a board keeps its parameters in its flash; "
                         "set them with heliquad params)")
    if not args.sil and args.load_params:
        raise InputError("--load-params needs --sil (on a board: heliquad params load, then "
                         "the sweep)")
    if not args.sil and (args.sd_image is not None or args.sd_faults):
        raise InputError("--sd-image and --sd-faults need --sil (a board's card is in its "
                         "socket; read its logs with heliquad logs)")
    if args.rotors is not None and args.inject not in ROTOR_INPUT_OUTPUT:
        raise InputError("--rotors is for --inject motors (the per-rotor run)")
    check_response(args.inject, args.response)
    if args.sil:
        sd_card(args)


def _ended(exc, out) -> int:
    """A sweep ended by an error: the board went away (exit 1, as a silent one), or the one
    line the command line gives ``exc``, saying that the records are kept."""
    # the command's work, imported when it runs: --help imports every command module
    from ...sim.rig.lockstep import FirmwareError

    kept = f"the log and manifest so far are kept in {out}"
    if isinstance(exc, DiskFull):
        raise exc.also(kept)
    if isinstance(exc, (LinkLost, FirmwareError)):      # the board (or the SIL's firmware) is gone
        sys.stderr.write(f"heliquad sweep: the board went away: {exc} ({kept})\n")
        return 1
    # OSError: a write to the log failed (not for want of room)
    if isinstance(exc, (InputError, OSError)):
        raise InputError(f"{exc} ({kept})") from None
    raise exc


def _what(plan) -> str:
    if plan.chirp is not None:
        c = plan.chirp
        return (f"chirp ({c.law}) {c.start_hz:.3g}-{c.stop_hz:.3g} Hz in {c.sweep_s:g} s, "
                f"{c.duration_s:.0f} s with its fades, amplitude {c.amplitude:.3g}")
    if plan.multisine is None:
        return (f"{len(plan.freqs_hz)} frequencies {plan.freqs_hz[0]:.3g}-"
                f"{plan.freqs_hz[-1]:.3g} Hz")
    ms = plan.multisine
    return (f"multisine: {len(ms.orders)} lines {ms.freqs_hz[0]:.3g}-{ms.freqs_hz[-1]:.3g} Hz "
            f"on a {ms.period_samples / ms.fs_hz:.3g} s period, {ms.periods} periods, "
            f"{ms.duration_s:.0f} s, peak {ms.peak:.3g} (crest factor {ms.crest_factor:.2f})")


def _found_text(found: dict) -> str:
    """What ``--port auto`` found (the manifest's ``port_found``), for the sweep's first lines."""
    serial = found["serial_number"] or "none"
    if found["source"] == "usb":
        return f"a USB device, serial {serial}"
    return (f"a board emulated by {found['source']} (serial {serial}, firmware "
            f"{found.get('firmware', 'not said')}), not a real one")


def _sweep_session(args, tlog):
    """The session a sweep drives (the firmware in the loop, or a board's port), the
    manifest's record of its source, and what ``--port auto`` found (None: not auto)."""
    # the command's work, imported when it runs: --help imports every command module
    from ..acquire.ports import AUTO, auto_board, found_record
    from ..acquire.session import PortSession
    from ..records import paper

    if not args.sil:
        board = auto_board() if args.port == AUTO else None
        port = args.port if board is None else board.device
        found = None if board is None else found_record(board)
        return (PortSession(port, tlog, args.baud),
                {"kind": "port", "port": port, "baud": args.baud}, found)
    # the command's work, imported when it runs: --help imports every command module
    from ...sim.rig.lockstep import FirmwareError
    from ...sim.rig.setup import SilConfig
    from ..acquire.session import SilSession
    from ..acquire.sweep import sil_source

    num, den = paper.MODELS[args.axis][paper.CHOSEN_ORDER[args.axis]]
    args.num, args.den = args.num or num, args.den or den
    check_plant(args)
    cfg = SilConfig(axis=args.axis, num=tuple(args.num), den=tuple(args.den),
                    inject=args.inject, collective=args.collective, dmp_image=args.dmp_image,
                    plant=args.plant, rig=args.axis, **vehicle_config(args),
                    load_params=args.load_params, faults=faults(args), firmware=args.firmware, param_store=args.param_store,
                    firmware_link=firmware_link(args), rc_script=args.rc_script,
                    **sd_card(args))
    source = sil_source(cfg)
    try:
        session = SilSession(cfg, tlog)
    except FirmwareError as exc:
        raise InputError(str(exc)) from None
    try:
        source["firmware"] = session.fw.record()
    except BaseException:                # Ctrl-C, or the image went away: nothing left running
        session.close()
        raise
    if args.fault:
        source["faults"] = list(args.fault)
    if args.rc_script is not None:
        source["rc_script"] = [[t, {str(i + 1): us for i, us in sets}]
                               for t, sets in args.rc_script.changes]
    return session, source, None
