"""The cascade's gains designed from identified models (``heliquad tune``; docs/tuning.md)."""

from __future__ import annotations

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
    from ..campaign.tune import axis_input, tune_models
    from ..validate.tuning import Spec
    from .shared_options import check_model

    steps = {k: v for k, v in (("step_angle_deg", args.step_deg),
                               ("step_rate_deg_s", args.step_deg_s)) if v is not None}
    spec = Spec(phase_margin_deg=args.phase_margin, gain_margin_db=args.gain_margin,
                coverage_k=args.coverage, command_max=args.max_command,
                min_crossover_rad_s=args.min_crossover, **steps)
    inputs = [axis_input(path) for path in args.models]
    for inp in inputs:
        check_model(f"{inp.path}: {inp.plants[0].name}", inp.plants[0].num, inp.plants[0].den)
    return tune_models(inputs, spec, args.out, layout="mavproxy" if args.mavproxy else "qgc")
