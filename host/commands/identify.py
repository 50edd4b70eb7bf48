"""Points, models and plots from a sweep folder or a board's log (``heliquad identify``)."""

from __future__ import annotations

import argparse
import math
import os
import sys

from ...sim.base.dialect import AXES
from ...sim.base.errors import InputError
from ..records.choices import RECORD_FIELDS, RESPONSES
from .fit import add_cost_option, print_models

__all__ = ["add_parser", "run"]

HELP = """\
Turn a sweep folder (manifest.json + sweep.tlog) into frequency-response points (FSF), the
paper's table (points_table.csv), fitted models (models.json: the paper's orders for the axis
and the integrator structures 0/2i and 1/3i, and on a band reaching over 3 times the top of
the paper's (as sweep --tuning-band does) 1/2 1/3 2/3 1/4 too, unless --order; each with a
fitted delay
unless --no-delay) and plots (bode.png; responses.png: each record's input and output,
with the recommended model's replay of the output dashed). The recommended model is the
lowest AICc among the stable models of acceptable fit, unless another fits visibly better;
its quality (good, acceptable, poor) is said and recorded.
When the loop closes around the excitation (mixer injection), the loop broken there is
measured too, L = R/U - 1, with its margins where the sweep reaches its crossovers.
DIR may also be a board's on-board log, a .BIN (heliquad logs download, or LOGS/ on its SD
card), or a folder holding one and no manifest: the sweep is read from the log itself (each
excitation's set-up from SIDS, its samples from HQSD; a multisine's lines from its logged
excitation), and the outputs go into the folder that holds the .BIN.
DIR may also be an ArduPilot DataFlash log of ArduCopter's SystemID mode: each run of its
chirp (SIDS, then SIDD, RATE and ATT every loop) is identified as a chirp of heliquad's,
against its excitation (SID_AXIS 10-12: the mixer's input ROut/POut/YOut to the rate; 7-9
and 1-3: the rate and angle targets), each into a folder beside the log, LOG-sidK-AXIS.
--from-record reads the log (a sweep folder's, or a .tlog such as heliquad log writes) as one
record without a designed periodic excitation: a chirp, a pilot's inputs, turbulence. Its
longest armed stretch is cut into overlapped, tapered windows of five lengths, whose
estimates are combined into one composite response at 20 frequencies over the band
(--band, else the sweep's, else the paper's for the axis), each point with its coherence and
random error; points of coherence below 0.6 are left out. Against the record's excitation
when it carries one; otherwise the direct estimate of --output over --input, right only
where the input is not fed back from the output's noise (a pilot's inputs that outweigh the
turbulence: under a closed loop, turbulence alone gives the controller, not the plant).
"""



def add_parser(sub, fmt) -> None:
    p = sub.add_parser("identify", help="points, models and plots from a sweep folder or a .BIN",
                       description=HELP, formatter_class=fmt)
    p.add_argument("dir", metavar="DIR", help="a sweep folder, a board's .BIN log (or an "
                                              "ArduPilot SystemID log), or a folder holding one")
    p.add_argument("--order", action="append", metavar="M/N",
                   help="an order to fit, again for more (M/Ni: one pole at the origin); "
                        "default: the paper's per axis (0/2 0/3 2/4, yaw 0/1 2/2 2/3) and 0/2i 1/3i "
                        "(and 1/2 1/3 2/3 1/4 on a band reaching over 3 times the paper's top)")
    p.add_argument("--delay", action=argparse.BooleanOptionalAction, default=True,
                   help="fit a pure time delay with each model (default: the loop's hold "
                        "and the sensor's latency are real delays); --no-delay fits none")
    add_cost_option(p)
    p.add_argument("--from-record", action="store_true",
                   help="read the log as one record (windows of several lengths combined), "
                        "not as its designed excitations")
    p.add_argument("--input", choices=RECORD_FIELDS, metavar="FIELD",
                   help="with --from-record: the record's input, a field of HQ_SYSID_SAMPLE "
                        f"({', '.join(RECORD_FIELDS)}; default: the sweep's injection's, "
                        "else axis_cmd)")
    p.add_argument("--output", choices=RECORD_FIELDS, metavar="FIELD",
                   help="with --from-record: the record's output (default: the sweep's "
                        "injection's, else rate)")
    p.add_argument("--response", choices=RESPONSES,
                   help="a rate or angle sweep (or a .BIN's, or an ArduPilot log's rate or "
                        "angle target segments): loop, the setpoint to the rate or angle; "
                        "plant, the mixer's input to the rate, both against the excitation "
                        "(default: what the sweep measured, its --response)")
    p.add_argument("--axis", choices=tuple(AXES),
                   help="with --from-record on a .tlog: the axis (default: the one its "
                        "samples name most)")
    p.add_argument("--band", nargs=2, type=float, metavar=("LO_HZ", "HI_HZ"),
                   help="with --from-record: the band of the points (default: the sweep's "
                        "frequencies, else the paper's band for the axis)")
    p.add_argument("--estimate", choices=("excitation", "input"), default="excitation",
                   help="excitation (default): each point as (Y/R)/(U/R), output and input "
                        "against the logged excitation R, unbiased when the loop is closed "
                        "and the air is not still; input: Y regressed on the measured input U "
                        "(the direct estimate, right only for open-loop data)")
    p.add_argument("--mat", metavar="MODELS.mat",
                   help="also write the models for MATLAB to this file (a struct array, "
                        "docs/file-formats.md)")
    p.set_defaults(func=run)


#: Which estimator made a point (FrequencyPoint.method), in the table's words.
ESTIMATORS = {"fsf": "FSF", "sinefit": "sine fit", "composite": "composite of windows",
              "bla": "BLA of random-phase realisations"}


def _estimate_text(point) -> str:
    """Which estimate a point came from: the estimator, and against what."""
    against = "the excitation" if point.estimate == "excitation" else "the input"
    return f"{ESTIMATORS.get(point.method, point.method or 'file')} against {against}"


def _record_options(args) -> dict | None:
    """--from-record's options for identify_dir, None without it; its options without it
    are refused."""
    given = [name for name in ("input", "output", "axis", "band") if getattr(args, name)]
    if not args.from_record:
        if given:
            raise InputError(f"--{given[0]} is an option of --from-record")
        return None
    if args.response:
        raise InputError("--response is for designed excitations; with --from-record, "
                         "--input and --output name the record's fields")
    if bool(args.input) != bool(args.output):
        raise InputError("--input and --output go together (or neither: the injection's)")
    if args.band and not 0 < args.band[0] < args.band[1]:
        raise InputError(f"--band {args.band[0]:g} {args.band[1]:g}: give LO_HZ < HI_HZ, "
                         "both positive")
    return {"axis": args.axis, "fields": (args.input, args.output) if args.input else None,
            "band_hz": tuple(args.band) if args.band else None}


def run(args) -> int:
    # the command's work, imported when it runs: --help imports every command module
    from ..present.plot_process import command_plots
    from ..records.bin_log import is_bin_name

    record = _record_options(args)
    if not os.path.isdir(args.dir) and not is_bin_name(args.dir) and \
            not (record is not None and args.dir.endswith(".tlog")):
        raise InputError(f"{args.dir}: not a folder" + (" or a .tlog" if record is not None
                                                         else ""))
    with command_plots() as plots:        # first: its imports overlap all of ours (numpy's too)
        # the command's work, imported when it runs: --help imports every command module
        from ..campaign.identify import identify_path
        from ..estimate.fit import parse_order

        orders = [parse_order(o) for o in args.order] if args.order else None
        results = identify_path(args.dir, orders, delay=args.delay, estimate=args.estimate,
                                plots=plots, cost=args.cost, from_record=record,
                                response=args.response)
    for r in results:
        _print_result(r, args.mat if len(results) == 1 else None)
    if args.mat and len(results) > 1:
        sys.stderr.write(f"heliquad identify: warning: {args.mat} not written: the log held "
                         f"{len(results)} segments; each folder's models.json has its models\n")
    return 0


def _print_result(r, mat) -> None:
    """One sweep's points and models, what was written, and its warnings (``mat``: the
    MATLAB file to write its models into, or None)."""
    print(f"{r['axis']}: {len(r['points'])} points")
    print(f"{'f (Hz)':>8} {'omega':>8} {'|G|':>9} {'phase':>9} {'R':>9} {'I':>9} {'coh':>7}"
          f"  estimate")
    for p in sorted(r["points"], key=lambda q: q.omega_rad_s):
        print(f"{p.freq_hz:8.4g} {p.omega_rad_s:8.4g} {p.magnitude:9.4g} "
              f"{math.degrees(p.phase_rad):9.2f} {p.gain.real:9.4g} {p.gain.imag:9.4g} "
              f"{p.coherence:7.4f}  {_estimate_text(p)}")
    print_models(r["result"])
    print(f"wrote points.csv, points_table.csv, models.json, bode.png, responses.png in "
          f"{r['out_dir']}")
    if mat:
        # the command's work, imported when it runs: --help imports every command module
        from ..records.models import fitted_models, write_models_mat

        write_models_mat(mat, fitted_models(r["result"]))
        print(f"wrote {mat}")
    if r["skipped"] or r["damage"]:
        n = len(r["points"]) + len(r["skipped"])
        sys.stderr.write(f"heliquad identify: warning: {len(r['skipped'])} of {n} measured "
                         "frequencies not used"
                         + (f"; the log is damaged: {r['damage'].summary()}" if r["damage"] else "")
                         + " (heliquad report flags it)\n")
    if r["saturated"]:
        sys.stderr.write(f"heliquad identify: warning: something saturated at "
                         f"{len(r['saturated'])} frequency(ies): {'; '.join(r['saturated'])} "
                         "(heliquad report flags it)\n")
