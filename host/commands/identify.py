"""Points, models and plots from a sweep folder or a board's log (``heliquad identify``)."""

from __future__ import annotations

import argparse
import math
import os
import sys

from ...sim.base.errors import InputError
from .fit import print_models

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
"""



def add_parser(sub, fmt) -> None:
    p = sub.add_parser("identify", help="points, models and plots from a sweep folder or a .BIN",
                       description=HELP, formatter_class=fmt)
    p.add_argument("dir", metavar="DIR", help="a sweep folder, a board's .BIN log, or a folder "
                                              "holding one")
    p.add_argument("--order", action="append", metavar="M/N",
                   help="an order to fit, again for more (M/Ni: one pole at the origin); "
                        "default: the paper's per axis (0/2 0/3 2/4, yaw 0/1 2/2 2/3) and 0/2i 1/3i "
                        "(and 1/2 1/3 2/3 1/4 on a band reaching over 3 times the paper's top)")
    p.add_argument("--delay", action=argparse.BooleanOptionalAction, default=True,
                   help="fit a pure time delay with each model (default: the loop's hold "
                        "and the sensor's latency are real delays); --no-delay fits none")
    p.add_argument("--estimate", choices=("excitation", "input"), default="excitation",
                   help="excitation (default): each point as (Y/R)/(U/R), output and input "
                        "against the logged excitation R, unbiased when the loop is closed "
                        "and the air is not still; input: Y regressed on the measured input U "
                        "(the direct estimate, right only for open-loop data)")
    p.add_argument("--mat", metavar="MODELS.mat",
                   help="also write the models for MATLAB to this file (a struct array, "
                        "docs/file-formats.md)")
    p.set_defaults(func=run)


def run(args) -> int:
    # the command's work, imported when it runs: --help imports every command module
    from ..present.plot_process import PlotProcess
    from ..records.bin_log import is_bin_name

    if not os.path.isdir(args.dir) and not is_bin_name(args.dir):
        raise InputError(f"{args.dir}: not a folder")
    with PlotProcess() as plots:        # first: its imports overlap all of ours (numpy's too)
        # the command's work, imported when it runs: --help imports every command module
        from ..campaign.identify import identify_dir
        from ..estimate.fit import parse_order

        orders = [parse_order(o) for o in args.order] if args.order else None
        r = identify_dir(args.dir, orders, delay=args.delay, estimate=args.estimate,
                         plots=plots)
    print(f"{r['axis']}: {len(r['points'])} points")
    print(f"{'f (Hz)':>8} {'omega':>8} {'|G|':>9} {'phase':>9} {'R':>9} {'I':>9} {'coh':>7}")
    for p in sorted(r["points"], key=lambda q: q.omega_rad_s):
        print(f"{p.freq_hz:8.4g} {p.omega_rad_s:8.4g} {p.magnitude:9.4g} "
              f"{math.degrees(p.phase_rad):9.2f} {p.gain.real:9.4g} {p.gain.imag:9.4g} {p.coherence:7.4f}")
    print_models(r["result"])
    print(f"wrote points.csv, points_table.csv, models.json, bode.png, responses.png in "
          f"{r['out_dir']}")
    if args.mat:
        # the command's work, imported when it runs: --help imports every command module
        from ..records.models import fitted_models, write_models_mat

        write_models_mat(args.mat, fitted_models(r["result"]))
        print(f"wrote {args.mat}")
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
    return 0
