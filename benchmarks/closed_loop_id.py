"""Benchmark: identification in closed loop under turbulence, against the simulator's truth.

For each axis, turbulence level and seed: a default `heliquad sweep --sil` of the 6-DoF
vehicle on the axis's rig, then `heliquad identify`, and the figures identify records in
models.json (`sil_truth`): the worst point error across the band (dB, deg), the RMS of
point error / reported sigma, the recommended model (its order) and its worst error, and
the session's simulated time (the log's span: the rig time the sweep cost).

`--before` runs the earlier design for comparison: a fixed dwell of 8 cycles at the earlier
default mixer amplitude (0.05 on roll and pitch; 0.3 on yaw, which then had 1.0 below
0.4 Hz) with points regressed on the measured input.

    python benchmarks/closed_loop_id.py [--axes roll pitch yaw] [--levels none light
        moderate severe] [--seeds 1 2 3] [--before] [--no-delay] [--keep DIR]
"""

import argparse
import json
import os
import subprocess
import sys
import tempfile

LEVELS = ("none", "light", "moderate", "severe")


def heliquad(*args):
    res = subprocess.run([sys.executable, "-m", "heliquad.host.cli.parser", *map(str, args)],
                         capture_output=True, text=True)
    if res.returncode:
        raise SystemExit(f"heliquad {' '.join(map(str, args))}: {res.stderr.strip()}")
    return res


def before_options(axis):
    """The earlier design's sweep options: fixed dwell, fixed small amplitude."""
    return ["--cycles", 8, "--amplitude", 0.05 if axis != "yaw" else 0.3]


def one(folder, axis, level, seed, before, delay):
    """Sweep and identify; the figures of one run."""
    from heliquad.host.acquire.log_session import summarise_tlog

    sweep = ["sweep", "--sil", "--axis", axis, "--seed", seed, "--out", folder]
    if level != "none":
        sweep += ["--turbulence", level]
    if before:
        sweep += before_options(axis)
    heliquad(*sweep)
    identify = ["identify", folder] + (["--estimate", "input"] if before else [])
    heliquad(*identify, "--delay" if delay else "--no-delay")
    doc = json.loads(open(os.path.join(folder, "models.json")).read())
    truth = doc["sil_truth"]
    span = summarise_tlog(os.path.join(folder, "sweep.tlog"))["span_s"]
    from heliquad.host.estimate.fit import order_name

    rec = doc.get("recommended")
    pick = "none"
    if rec is not None:
        m = doc["models"][rec]
        pick = order_name((*m["order"], int(bool(m.get("integrator")))), bool(m.get("delay_s")))
    return {"pick": pick, "db": truth["points_worst_db"], "deg": truth["points_worst_deg"],
            "z": truth["points_rms_error_over_sigma"], "model_db": truth.get("model_worst_db"),
            "model_deg": truth.get("model_worst_deg"), "rig_s": span}


def main():
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    from heliquad.sim.base import dialect

    parser.add_argument("--axes", nargs="+", choices=tuple(dialect.AXES),
                        default=list(dialect.AXES))
    parser.add_argument("--levels", nargs="+", choices=LEVELS, default=list(LEVELS))
    parser.add_argument("--seeds", nargs="+", type=int, default=[1, 2, 3])
    parser.add_argument("--before", action="store_true", help="the earlier design")
    parser.add_argument("--delay", action=argparse.BooleanOptionalAction, default=True,
                        help="identify's --delay (its default) or --no-delay")
    parser.add_argument("--keep", metavar="DIR", help="keep the sweep folders here")
    args = parser.parse_args()
    base = args.keep or tempfile.mkdtemp(prefix="closed_loop_id-")
    print(f"{'axis':>5} {'level':>8} {'seed':>4} {'points dB':>9} {'deg':>6} {'err/sig':>7} "
          f"{'model':>6} {'model dB':>8} {'deg':>6} {'rig s':>6}", flush=True)
    for axis in args.axes:
        for level in args.levels:
            for seed in (args.seeds if level != "none" else args.seeds[:1]):
                folder = os.path.join(base, f"{axis}-{level}-{seed}{'-before' if args.before else ''}")
                r = one(folder, axis, level, seed, args.before, args.delay)
                model = (f"{r['model_db']:8.2f} {r['model_deg']:6.1f}"
                         if r["model_db"] is not None else f"{'none':>8} {'':>6}")
                z = f"{r['z']:7.2f}" if r["z"] is not None else f"{'-':>7}"
                print(f"{axis:>5} {level:>8} {seed:>4} {r['db']:9.2f} {r['deg']:6.1f} {z} "
                      f"{r['pick']:>6} {model} {r['rig_s']:6.0f}", flush=True)
    if not args.keep:
        import shutil

        shutil.rmtree(base)


if __name__ == "__main__":
    main()
