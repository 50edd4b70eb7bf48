"""``heliquad demo``: the whole identification campaign on the simulated vehicle.

For each axis: the firmware in the loop flies the 6-DoF vehicle on that axis's test rig
(the paper's vehicle, docs/paper.md, and its IMU with noise, bias and latency); a sweep
over the axis's Table 1 band (15 frequencies, mixer injection: the plant); identification
with the paper's orders and two integrator structures, each with a fitted delay (the loop's
hold and the DMP's latency are real delays); closed-loop validation with the paper's gains
in the firmware's discrete loops; a tuning sweep (the same dwell from the band's bottom up to
45 Hz, into DIR/AXIS/tuning, identified there: a model that holds where every margin of
the loops is read); then the tuning sweeps' models tuned together (heliquad
tune's specification, into DIR/tune) and each axis's tuned gains proven on its simulated rig
(heliquad verify: loaded, measured through setpoint sweeps, kept or the previous ones
restored); and one HTML report for all three axes, the gains before and after in it. It
prints each axis's recommended model against the simulator's own truth, with the worst
error across the band, and each axis's verification verdict.

The axes run side by side, each in a process of its own (:mod:`.workers`), its progress
lines shown with its name in front. Ctrl-C, SIGTERM or SIGHUP stops every axis in order (each sweep
stops its excitation and keeps its log and manifest) and ends the demo without a report; an
axis that fails is said, the others go on, and the demo ends with exit code 1.
"""

from __future__ import annotations

import importlib
import json
import os
import signal
import sys
import time
import traceback

from ...sim.base.errors import DiskFull, InputError
from ..process.signals import WORDS, stop_exception, stopped_by
from ..records import paper
from .run_options import add_load_params_argument
from .shared_options import MAX_SEED, add_firmware_argument, firmware_link, int_in

#: The demo's exit code when an axis failed (the others' records and the report are kept).
EXIT_STOPPED = 1

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
    add_load_params_argument(p)
    p.set_defaults(func=run_demo)


def run_demo(args) -> int:
    # the command's work, imported when it runs: --help imports every command module
    from ..process.workers import run_children
    from ..records.output import new_output_folder

    new_output_folder(args.out, "the demo")
    t0 = time.monotonic()
    options = {"out": args.out, "ideal_sensor": args.ideal_sensor, "seed": args.seed,
               "firmware": args.firmware, "link": firmware_link(args),
               "turbulence": args.turbulence,
               "load_params": None if args.load_params is None
               else os.path.abspath(args.load_params)}
    # Each axis in a process of its own, side by side; Ctrl-C stops them all in order.
    children = run_children([(axis, [sys.executable, "-c", AXIS_COMMAND,
                                     json.dumps({**options, "axis": axis})])
                             for axis in args.axes])
    summary, sim_s, failed = [], 0.0, []
    for child in children:
        result = child.result or {"status": "failed",
                                  "error": f"it ended (exit code {child.returncode}) "
                                           "without a result"}
        if result["status"] == "done":
            summary.append(tuple(result["summary"]))
            sim_s += result["sim_s"]
        else:
            failed.append(child.name)
            print(f"== {child.name}: failed: {result['error']}")
            summary.append((child.name, None, f"failed: {result['error']}", float("nan"),
                            float("nan")))
    verdicts = _tune_and_verify(args.out, [c.name for c in children if c.name not in failed],
                                options)
    report_path = _report(args.out)
    _print_summary(summary, report_path, time.monotonic() - t0, sim_s)
    _print_verdicts(verdicts)
    stopped = any(v == "stopped" for v in verdicts.values())
    return EXIT_STOPPED if failed or stopped else 0


#: Where the demo's tuning goes (tune.json, tuned.params, tune.png, and the verification's
#: verify.json and verify/AXIS/).
TUNE_FOLDER = "tune"


#: A verification sweep's length in turbulence, s (verify's default, 20 s, in still air):
#: the gusts are noise on every line, and the angle loop's gain margin, read where the loop
#: gain is a few hundredths, comes out to +/- 2 dB from 20 s of moderate turbulence.
TURBULENT_VERIFY_S = 60.0


def _tune_and_verify(out: str, axes: list, options: dict) -> dict:
    """The demo's last step: the axes' tuning sweeps' models tuned together into out/tune
    (heliquad tune's defaults), then each tuned axis verified on its simulated rig in the
    same air as its sweep (its sweeps 60 s long in turbulence), one after the other
    (verify.json gathers them). Returns
    ``{axis: verdict}`` (``accepted``, ``rejected``, ``not tuned: why``, ``stopped``)."""
    # the command's work, imported when it runs: --help imports every command module
    from ..campaign.tune import axis_input, tune_models
    from ..campaign.verify import prepare_verification, run_verification, sil_session
    from ..validate.tuning import Spec

    inputs, verdicts = [], {}
    for axis in axes:
        try:
            inputs.append(axis_input(os.path.join(out, axis, TUNING_SWEEP, "models.json")))
        except InputError as exc:
            verdicts[axis] = f"not tuned: {exc}"
    if not inputs:
        return verdicts
    folder = os.path.join(out, TUNE_FOLDER)
    print(f"== tune {', '.join(i.axis for i in inputs)} -> {folder}")
    try:
        why = None if tune_models(inputs, Spec(), folder) == 0 else \
            "a band forbids the specification (above)"
    except InputError as exc:
        why = str(exc)
    if why is not None:
        return {**verdicts, **{i.axis: f"not tuned: {why}" for i in inputs}}
    session = lambda axis, tlog: sil_session(                          # noqa: E731
        axis, tlog, turbulence=options["turbulence"], seed=options["seed"],
        ideal_sensor=options["ideal_sensor"], load_params=options["load_params"])
    for inp in inputs:
        print(f"== verify {inp.axis} on the simulated rig")
        plan = prepare_verification(folder, inp.axis, board="sil",
                                    rig_time_s=TURBULENT_VERIFY_S if options["turbulence"]
                                    else None)
        code, lines = run_verification(plan, session)
        for line in lines:
            print(f"verify: {line}")
        verdicts[inp.axis] = {0: "accepted", 1: "rejected"}.get(code, "stopped")
        if verdicts[inp.axis] == "stopped":
            break
    return verdicts


def _print_verdicts(verdicts: dict) -> None:
    """Each axis's tuned gains as the verification judged them."""
    if verdicts:
        print("\n== tuned gains, verified on the simulated rig (tune/verify.json)")
        for axis, verdict in verdicts.items():
            print(f"{axis:>6}: {verdict}")


def _report(out: str) -> str | None:
    """The HTML report of every axis that got so far, or None (said) when none did."""
    # the command's work, imported when it runs: --help imports every command module
    from ..present.report import write_report

    try:
        return write_report(out)
    except InputError as exc:
        print(f"no report: {exc}")
        return None


#: What a child of the demo runs: one axis (its options as JSON in argv).
AXIS_COMMAND = "from heliquad.host.commands.demo import axis_main; axis_main()"
_STOPPED_BY: list = []


def _on_signal(signum, frame):
    _STOPPED_BY.append(signum)
    raise stop_exception(signum)


def axis_main() -> None:
    """A child of the demo (:data:`AXIS_COMMAND`): sweep, identify and validate one axis, fly
    and identify its tuning sweep, and report to the demo ``{"status": "done", "summary":
    [...], "sim_s": ...}``, or
    ``{"status": "stopped" | "failed", "error": ...}``. Ctrl-C, SIGTERM and SIGHUP stop it in order
    (the sweep keeps its log and manifest)."""
    # the command's work, imported when it runs: --help imports every command module
    from ..process.workers import send_result

    signal.signal(signal.SIGINT, _on_signal)
    signal.signal(signal.SIGTERM, _on_signal)
    if signal.getsignal(signal.SIGHUP) is not signal.SIG_IGN:    # nohup's stays ignored
        signal.signal(signal.SIGHUP, _on_signal)
    options = json.loads(sys.argv[1])
    try:
        result = {"status": "done", **_run_axis(**options)}
    except KeyboardInterrupt as exc:
        result = {"status": "stopped", "error": WORDS[stopped_by(exc)]}
    except (InputError, DiskFull, OSError) as exc:
        result = {"status": "failed", "error": str(exc)}
    except Exception as exc:                       # noqa: BLE001 - one axis's failure, said
        traceback.print_exc()
        result = {"status": "failed", "error": f"{type(exc).__name__}: {exc}"}
    send_result(result)


def _run_axis(axis, out, ideal_sensor, seed, firmware, turbulence, link,
              load_params=None) -> dict:
    """One axis of the demo in ``out/AXIS``: ``{"summary": _compare's row, "sim_s": ...}``."""
    # Everything a sweep uses is imported before it starts: a Ctrl-C that lands inside an
    # import leaves Python to end by SIGINT after the tool has stopped in order.
    from ...sim.rig.setup import SilConfig
    from ..acquire.sweep import default_plan
    from ..campaign.identify import identify_dir
    from ..present.plot_process import InlinePlots
    from ..campaign.validation import save_validation
    from ..records.models import read_models_json
    from ..validate.closed_loop import model_gains, sweep_inputs, validate_model

    importlib.import_module("..estimate.fsf", __package__)        # a sweep's dwell check uses it
    folder = os.path.join(out, axis)
    os.makedirs(folder, exist_ok=True)
    print(f"== sweep on the {axis} rig, {firmware} firmware in the loop")
    cfg = SilConfig(axis=axis, inject="mixer", plant="vehicle", rig=axis,
                    ideal_sensor=ideal_sensor, seed=seed, firmware=firmware,
                    firmware_link=link, turbulence=turbulence, load_params=load_params)
    sim_s = _fly(cfg, default_plan(axis), folder)
    print("== identify")
    try:
        # The plots here, not beside: the axes keep every core busy already.
        identified = identify_dir(folder, progress=print, plots=InlinePlots())
    except InputError as exc:                 # a failed sweep: say so, go on
        print(f"== not identified: {exc}")
        return {"summary": (axis, None, str(exc), float("nan"), float("nan")), "sim_s": sim_s}
    result = identified["result"]
    model = result.models[result.recommended] if result.recommended is not None else None
    if model is not None:
        print("== validate")
        models_path = os.path.join(folder, "models.json")
        doc = read_models_json(models_path)
        report, traces = validate_model(
            model.num, model.den, model.delay_s, axis, model_gains(doc, axis)[0], "moderate",
            seed, **sweep_inputs(models_path, doc))
        save_validation(folder, report, traces)
    sim_s += _tuning_sweep(cfg, axis, folder)
    return {"summary": _compare(axis, model, result.reason, identified["truth"]),
            "sim_s": sim_s}


def _fly(cfg, plan, folder: str) -> float:
    """One sweep of ``plan`` on the simulated rig ``cfg``, its log and manifest into
    ``folder``: the seconds simulated. A sweep ended in order by a signal stops the axis."""
    # the command's work, imported when it runs (before the sweep starts, as _run_axis's):
    # --help imports every command module
    from ..acquire.session import SilSession
    from ..acquire.sweep import SWEEP_TLOG, run_sweep, sil_source

    with SilSession(cfg, os.path.join(folder, SWEEP_TLOG)) as session:
        run_sweep(session, plan, folder, {**sil_source(cfg), "firmware": session.fw.record()})
        sim_s = session.time_us * 1e-6
    if _STOPPED_BY:                  # the sweep ended in order on a signal: stop
        raise stop_exception(_STOPPED_BY[0])
    return sim_s


#: Where each axis's tuning sweep goes, inside the axis's folder (sweep.tlog, manifest.json
#: and identify's files: the models heliquad tune designs on).
TUNING_SWEEP = "tuning"


def _tuning_sweep(cfg, axis: str, folder: str) -> float:
    """The axis's tuning sweep (the same rig, air and seed as its sweep; the dwell over the
    tuning band, from the Table 1 band's bottom to 45 Hz) into ``folder/tuning``, identified
    there: a model that holds where tune reads every margin, the phase crossovers included,
    which lie far above the paper's bands. Returns the seconds simulated."""
    # the command's work, imported when it runs (already, by _run_axis): --help imports
    # every command module
    from ..acquire.sweep import default_plan, tuning_freqs_hz
    from ..campaign.identify import identify_dir
    from ..present.plot_process import InlinePlots

    tuning = os.path.join(folder, TUNING_SWEEP)
    os.makedirs(tuning, exist_ok=True)
    freqs = tuning_freqs_hz(axis)
    print(f"== tuning sweep: {freqs[0]:.3g}-{freqs[-1]:.3g} Hz, for heliquad tune")
    sim_s = _fly(cfg, default_plan(axis, freqs_hz=freqs), tuning)
    print("== identify the tuning sweep")
    try:
        identify_dir(tuning, progress=print, plots=InlinePlots())
    except InputError as exc:              # said; tune then says the axis is not tuned
        print(f"== tuning sweep not identified: {exc}")
    return sim_s


def _compare(axis, model, reason, truth):
    """Worst error of the recommended model against the simulator's sampled-data truth
    across the band (identify's record of it, :mod:`.truth`)."""
    # the command's work, imported when it runs: --help imports every command module
    from ..estimate.fit import format_tf

    if model is None or not truth:
        return (axis, None, reason, float("nan"), float("nan"))
    return (axis, format_tf(model), reason, truth["model_worst_db"], truth["model_worst_deg"])


def _print_summary(summary, report_path, wall, sim_s) -> None:
    print("\n== identified versus the simulator's truth (worst error across each axis's band)")
    for axis, text, reason, db, deg in summary:
        if text is None:
            print(f"{axis:>6}: no model; {reason}")
        else:
            print(f"{axis:>6}: {text}\n        error {db:.2f} dB, {deg:.1f} deg; {reason}")
    print(f"\n{sim_s:.0f} s simulated in {wall:.0f} s ({sim_s / wall:.1f}x real time)")
    if report_path is not None:
        print(f"report: {os.path.abspath(report_path)}")
