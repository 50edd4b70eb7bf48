"""The cascade's gains designed from identified models (``heliquad tune``; docs/tuning.md)."""

from __future__ import annotations

import os

from ...sim.base.errors import InputError
from ...sim.base.firmware_facts import LOOP_RATE_HZ
from ..records.gains import AXIS_COMMAND_MAX, DERIVATIVE_FILTER_N
from .shared_options import number_in

__all__ = ["add_parser", "run"]

HELP = f"""\
Design the cascade's gains from identified models (one MODELS.json per axis, its axis from
the file; heliquad identify writes them): the rate PID (Kc, tau_I, tau_D) and, for roll and
pitch, the angle PD (Kc, tau_D), for the firmware's discrete loops at {LOOP_RATE_HZ:g} Hz
with the model's delay. The derivative filter is the firmware's fixed N =
{DERIVATIVE_FILTER_N:g} (tau_f = tau_D / N), not designed. The design is the highest rate
crossover that keeps, on the recommended model and on the second-best one: the phase and
gain margins at every crossover of every loop (rate; angle and input for roll and pitch)
after taking off the model's uncertainty there (k times the points' relative sigma), the
rate loop's gain crossovers inside the identified band (its margins measured, not
extrapolated), the gains in the firmware's parameter ranges, and the predicted step's peak
axis command within the limit (the firmware clamps the axis command to
{AXIS_COMMAND_MAX:g}); then the angle loop below it. Writes tune.json, tuned.params
(QGroundControl's format, as params save writes it, for heliquad params load and
QGroundControl; --mavproxy for MAVProxy's param load)
and tune.png into --out, and prints current against tuned per axis. Exit code 1 when a
band forbids the spec (nothing written; the sweep band that would allow it is said), 2 for
bad input or a spec no gains meet.

example: heliquad tune roll/models.json pitch/models.json yaw/models.json --out tuned
"""


def add_parser(sub, fmt) -> None:
    p = sub.add_parser("tune", help="design the cascade's gains from identified models",
                       description=HELP, formatter_class=fmt)
    p.add_argument("models", metavar="MODELS.json", nargs="+")
    p.add_argument("--out", metavar="DIR", required=True,
                   help="where tune.json, tuned.params and tune.png go")
    p.add_argument("--phase-margin", type=number_in(0, 90, lo_open=True, hi_open=True),
                   default=45.0, metavar="DEG", help="at every gain crossover (default 45)")
    p.add_argument("--gain-margin", type=number_in(0, 40, lo_open=True), default=6.0,
                   metavar="DB", help="at every phase crossover (default 6)")
    p.add_argument("--coverage", type=number_in(0, 5), default=2.0, metavar="K",
                   help="the model's uncertainty at a crossover is K times the points' relative "
                        "sigma there (default 2; 0: none)")
    p.add_argument("--step-deg", type=number_in(0, 80, lo_open=True), metavar="DEG",
                   help="roll and pitch: the angle step whose peak command is limited "
                        "(default 10, validate's step)")
    p.add_argument("--step-deg-s", type=number_in(0, 400, lo_open=True), metavar="DEG_S",
                   help="yaw: the rate step whose peak command is limited (default 30, "
                        "validate's step)")
    p.add_argument("--max-command", type=number_in(0, AXIS_COMMAND_MAX, lo_open=True),
                   default=AXIS_COMMAND_MAX, metavar="C", help="the largest |axis command| the step may "
                   f"ask for (default {AXIS_COMMAND_MAX:g}, the firmware's clamp)")
    p.add_argument("--min-crossover", type=number_in(0, 1e4), default=0.0, metavar="RAD_S",
                   help="the slowest rate-loop crossover acceptable (default 0: any)")
    p.add_argument("--mavproxy", action="store_true",
                   help="write tuned.params in MAVProxy's layout (NAME VALUE), which its param "
                        "load reads, instead of QGroundControl's (as params save --mavproxy)")
    p.set_defaults(func=run)


def run(args) -> int:
    # the command's work, imported when it runs: --help imports every command module
    from ..campaign.tune import TUNE_FIGURE, axis_input, tune_axis, write_outputs
    from ..present.tune import write_tune_figure
    from ..records.figures import check_figure_output
    from ..records.output import check_output_folder
    from ..validate.tuning import Spec
    from .shared_options import check_model

    steps = {k: v for k, v in (("step_angle_deg", args.step_deg),
                               ("step_rate_deg_s", args.step_deg_s)) if v is not None}
    spec = Spec(phase_margin_deg=args.phase_margin, gain_margin_db=args.gain_margin,
                coverage_k=args.coverage, command_max=args.max_command,
                min_crossover_rad_s=args.min_crossover, **steps)
    inputs = [axis_input(path) for path in args.models]
    seen = {}
    for inp in inputs:
        if inp.axis in seen:
            raise InputError(f"{inp.path} and {seen[inp.axis]} are both of {inp.axis}: give one "
                             "MODELS.json per axis")
        seen[inp.axis] = inp.path
        for plant in inp.plants[:1]:
            check_model(f"{inp.path}: {plant.name}", plant.num, plant.den)
    check_output_folder(args.out, "--out")
    results = [tune_axis(inp, spec) for inp in inputs]
    for r in results:
        if r.entry is not None:
            _print_axis(r.entry, r.inp.axis)
    failed = [r.message for r in results if r.outcome == "spec"]
    if failed:
        raise InputError("; ".join(failed))
    forbidden = [r.message for r in results if r.outcome == "band"]
    if forbidden:
        for message in forbidden:
            print(message)
        print("nothing written")
        return 1
    os.makedirs(args.out, exist_ok=True)
    figure = os.path.join(args.out, TUNE_FIGURE)
    check_figure_output(figure, "--out")
    written = write_outputs(args.out, spec, results,
                            layout="mavproxy" if args.mavproxy else "qgc")
    write_tune_figure(figure, [(r.inp.axis, r.inp.band, r.traces) for r in results])
    print(f"wrote {', '.join(os.path.join(args.out, n) for n in written + [TUNE_FIGURE])}")
    return 0


def _cell(design) -> dict:
    """The figures a design's column shows."""
    rate = design["loops"]["rate"]
    step = design.get("step")
    fmt = lambda v, f: "-" if v is None else format(v, f)             # noqa: E731
    return {"rate crossover (rad/s)": fmt(rate["gain_crossover_rad_s"], ".3g"),
            "rate PM (deg)": fmt(rate["phase_margin_deg"], ".1f"),
            "rate GM (dB)": fmt(rate["gain_margin_db"], ".1f"),
            **{f"{n} PM/GM": f"{fmt(lp['phase_margin_deg'], '.1f')} / "
                             f"{fmt(lp['gain_margin_db'], '.1f')}"
               for n, lp in design["loops"].items() if n != "rate"},
            "step rise 10-90 % (s)": fmt(step and step["rise_time_s"], ".3f"),
            "step overshoot (%)": fmt(step and step["overshoot_pct"], ".1f"),
            "step peak command": fmt(step and step["peak_command"], ".2f"),
            "turbulence rate RMS (deg/s)": fmt(design.get("disturbance", {}).get(
                "rate_rms_deg_s"), ".2f")}


def _print_axis(entry, axis) -> None:
    """Current against tuned, side by side, and what limited the design."""
    cur, tun = _cell(entry["current"]), _cell(entry["tuned"])
    gains = lambda d: ", ".join(f"[{', '.join(f'{v:.4g}' for v in d['gains'][k])}]"  # noqa: E731
                                for k in ("rate", "angle") if d["gains"][k] is not None)
    print(f"{axis}: current gains {gains(entry['current'])} ({entry['current_from']}; "
          f"{'meets' if entry['current_meets_spec'] else 'does not meet'} the spec); tuned "
          f"{gains(entry['tuned'])} ({'meets' if entry['meets_spec'] else 'DOES NOT MEET'} it)")
    width = max(map(len, cur))
    print(f"  {'':{width}}  {'current':>12}  {'tuned':>12}")
    for key in cur:
        print(f"  {key:{width}}  {cur[key]:>12}  {tun[key]:>12}")
    for line in entry["said"]:
        print(f"  {line}")
