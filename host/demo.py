"""``heliquad demo``: the whole identification campaign on the simulated vehicle.

For each axis: the firmware in the loop flies the 6-DoF vehicle on that axis's test rig
(the paper's vehicle, docs/paper.md, and its IMU with noise, bias and latency); a sweep
over the axis's Table 1 band (15 frequencies, mixer injection: the plant); identification
with the paper's orders and two integrator structures, each with a fitted delay (the loop's
hold and the DMP's latency are real delays); closed-loop validation with the paper's gains
in the firmware's discrete loops; and one HTML report for all three axes. It prints each
axis's recommended model against the simulator's own truth, with the worst error across
the band.
"""

from __future__ import annotations

import os
import time

from . import paper
from .cli_args import MAX_SEED, add_firmware_argument, int_in
from .errors import InputError

__all__ = ["add_parser", "run_demo"]


def add_parser(sub, fmt) -> None:
    p = sub.add_parser("demo", help="the whole campaign on the simulated vehicle, all three axes",
                       description=__doc__, formatter_class=fmt)
    p.add_argument("--out", default="heliquad-demo", metavar="DIR",
                   help="output directory (default ./heliquad-demo)")
    p.add_argument("--axes", nargs="+", choices=tuple(paper.BANDS_HZ), default=list(paper.BANDS_HZ))
    p.add_argument("--ideal-sensor", action="store_true", help="no IMU noise, bias or latency")
    p.add_argument("--turbulence", choices=("light", "moderate", "severe"),
                   help="Dryden turbulence on the rigs during the sweeps (default: still air)")
    p.add_argument("--seed", type=int_in(0, MAX_SEED), default=1,
                   help="sensor-noise and turbulence seed (default 1)")
    add_firmware_argument(p)
    p.set_defaults(func=run_demo)


def run_demo(args) -> int:
    from .files import new_output_folder, read_models_json

    new_output_folder(args.out, "the demo")                 # before the slow imports below
    from ..sim.sil import SilConfig
    from .session import SilSession
    from .identify_session import identify_dir
    from .report import write_report
    from .sweep import SWEEP_TLOG, default_plan, run_sweep, sil_source
    from .validate import model_gains, save_validation, sweep_inputs, validate_model

    t0, sim_s, summary = time.monotonic(), 0.0, []
    for axis in args.axes:
        folder = os.path.join(args.out, axis)
        os.makedirs(folder, exist_ok=True)
        print(f"== {axis}: sweep on the {axis} rig, {args.firmware} firmware in the loop",
              flush=True)
        cfg = SilConfig(axis=axis, inject="mixer", plant="vehicle", rig=axis,
                        ideal_sensor=args.ideal_sensor, seed=args.seed, firmware=args.firmware,
                        turbulence=args.turbulence)
        with SilSession(cfg, os.path.join(folder, SWEEP_TLOG)) as session:
            run_sweep(session, default_plan(axis), folder,
                      {**sil_source(cfg), "firmware": session.fw.record()})
            sim_s += session.time_us * 1e-6
        print(f"== {axis}: identify", flush=True)
        try:
            identified = identify_dir(folder, progress=print)
        except InputError as exc:                 # a failed sweep: say so, go on
            print(f"== {axis}: not identified: {exc}")
            summary.append((axis, None, str(exc), float("nan"), float("nan")))
            continue
        result = identified["result"]
        model = result.models[result.recommended] if result.recommended is not None else None
        if model is not None:
            models_path = os.path.join(folder, "models.json")
            doc = read_models_json(models_path)
            report, traces = validate_model(
                model.num, model.den, model.delay_s, axis, model_gains(doc, axis)[0], "moderate",
                args.seed, **sweep_inputs(models_path, doc))
            save_validation(folder, report, traces)
        summary.append(_compare(axis, model, result.reason, identified["truth"]))
    report_path = write_report(args.out)
    wall = time.monotonic() - t0
    _print_summary(summary, report_path, wall, sim_s)
    return 0


def _compare(axis, model, reason, truth):
    """Worst error of the recommended model against the simulator's sampled-data truth
    across the band (identify's record of it, :mod:`.truth`)."""
    from .fit import format_tf

    if model is None or not truth:
        return (axis, None, reason, float("nan"), float("nan"))
    return (axis, format_tf(model), reason, truth["model_worst_db"], truth["model_worst_deg"])


def _print_summary(summary, report_path, wall, sim_s) -> None:
    print("\n== identified versus the simulator's truth (worst error across each axis's band)")
    for axis, text, reason, db, deg in summary:
        print(f"{axis:>6}: {text}\n        error {db:.2f} dB, {deg:.1f} deg; {reason}")
    print(f"\n{sim_s:.0f} s simulated in {wall:.0f} s ({sim_s / wall:.1f}x real time)")
    print(f"report: {os.path.abspath(report_path)}")
