"""Transfer functions from frequency-response points (``heliquad fit``)."""

from __future__ import annotations

from ...sim.base.errors import InputError
from ..estimate.thresholds import LOW_COHERENCE
from ..records.choices import COSTS

__all__ = ["add_parser", "run", "print_models", "add_cost_option"]

DEFAULT_FIT_ORDERS = ("0/1", "0/2", "0/3", "2/2", "2/3", "2/4")

HELP = """\
Fit transfer functions of the given orders to frequency-response points: Levy's method,
Sanathanan-Koerner iterations, an output-error refinement with stable poles (docs/paper.md,
step 3), then, by default, a last stage that minimises CIFER's J itself (--cost). Prints
each model's metrics, what was minimised, and the recommended model.

POINTS.csv: a header row, columns omega_rad_s,magnitude,phase_rad (rad/s, linear, rad;
omega strictly increasing) and optionally sigma,coherence (and coherence_ry,coherence_ru,
which heliquad identify writes; --plot draws the coherences under the Bode plot).
MODELS.json (written): {"models": [{"order": [M, N], "num": [...], "den": [...],
"delay_s": 0.0, "stable": true, "metrics": {"rms", "J", "aicc", ...}, "poles", "zeros",
"dc_gain"}, ...], "recommended": INDEX, "reason": "..."}; coefficients in descending
powers of s, den monic.
Outputs: every one (--json, --mat, --plot) is checked before the fit, so a name that cannot
be written (a missing folder; a --plot extension that is no image format matplotlib writes,
docs/file-formats.md) is refused in one line and nothing is written.

example: heliquad fit points.csv --order 0/2 --order 0/3 --order 2/4 --json models.json --plot bode.png
"""



def add_parser(sub, fmt) -> None:
    p = sub.add_parser("fit", help="transfer functions from frequency-response points",
                       description=HELP, formatter_class=fmt)
    p.add_argument("points", metavar="POINTS.csv")
    p.add_argument("--order", action="append", metavar="M/N",
                   help="numerator/denominator degree; repeat for several "
                        f"(default: {' '.join(DEFAULT_FIT_ORDERS)}, those the points support)")
    p.add_argument("--delay", action="store_true", help="fit a pure time delay with each model")
    p.add_argument("--weights", choices=("auto", "sigma", "coherence", "none"), default="auto",
                   help="point weights: 1/sigma, CIFER coherence weight, or equal relative "
                        "weight (default auto: sigma, else coherence, else none)")
    add_cost_option(p)
    p.add_argument("--allow-unstable", action="store_true",
                   help="do not constrain poles to the left half plane (unstable results "
                        "are flagged)")
    p.add_argument("--json", required=True, metavar="MODELS.json", help="models file to write")
    p.add_argument("--plot", metavar="BODE.png", help="write a Bode plot of points and models "
                   "(and the points' coherence, when the file has it); the format is the "
                   "name's extension (.png, .pdf, .svg, ... any matplotlib writes; PNG when "
                   "there is none), checked with the other outputs before anything is done")
    p.add_argument("--mat", metavar="MODELS.mat", help="also write the models for MATLAB (a "
                   "struct array, docs/file-formats.md)")
    p.set_defaults(func=run)


def add_cost_option(p) -> None:
    """``--cost``, on fit and identify."""
    p.add_argument("--cost", choices=COSTS, default="j",
                   help="what the fits minimise: j (default), CIFER's J itself (the dB and "
                        "degree errors of every point, weighted by its coherence: the number "
                        "the table compares models by), started from the relative fit; "
                        "relative: the weighted relative complex error alone, the fit "
                        "before J's stage")


def run(args) -> int:
    # the command's work, imported when it runs: --help imports every command module
    from ..records.figures import check_figure_output
    from ..records.models import fitted_models, write_models_json, write_models_mat
    from ..records.output import check_output
    from ..records.points import read_points_csv

    for option in ("json", "mat"):                  # all writable, or none is written
        if getattr(args, option):
            check_output(getattr(args, option), f"--{option}")
    if args.plot:
        check_figure_output(args.plot, "--plot")
    points = read_points_csv(args.points)
    # after the file is read, so that a bad file is said at once: the fits' modules are slow
    from ..estimate.fit import n_parameters, parse_order
    from ..estimate.models import fit_orders

    if args.order:
        orders = [parse_order(o) for o in args.order]
    else:
        n = len(points)
        orders = [o for o in map(parse_order, DEFAULT_FIT_ORDERS)
                  if 2 * n >= n_parameters(o, args.delay) + 1]
        if not orders:
            raise InputError(f"{args.points}: {n} point(s) are too few for any default order")
    result = fit_orders(points, orders, weights=args.weights, delay=args.delay,
                        stable=not args.allow_unstable, cost=args.cost)
    print_models(result)
    fitted = fitted_models(result, points_file=str(args.points))
    write_models_json(args.json, fitted)
    print(f"wrote {args.json}")
    if args.mat:
        write_models_mat(args.mat, fitted)
        print(f"wrote {args.mat}")
    if args.plot:
        # the command's work, imported when it runs: --help imports every command module
        from ..present.bode import write_bode

        write_bode(args.plot, points, models=result.models, recommended=result.recommended,
                   title=str(args.points), gate=LOW_COHERENCE)
        print(f"wrote {args.plot}")
    return 0


def print_models(result) -> None:
    # the command's work, imported when it runs: --help imports every command module
    from ..estimate.fit import format_tf, order_name

    minimised = ("CIFER's J (coherence-weighted dB and deg errors)" if result.cost == "j"
                 else "the weighted relative complex error")
    print(f"weights: {result.weights}; minimised: {minimised}")
    print(f"{'order':>8} {'J':>9} {'rms %':>8} {'AICc':>10} {'max dB':>7} {'max deg':>8} "
          f"{'stable':>6}  model")
    for i, m in enumerate(result.models):
        k = m.metrics
        mark = "*" if i == result.recommended else " "
        order = order_name(m.structure, m.delay_fitted)
        print(f"{mark}{order:>7} {k['J']:9.3g} {100 * k['rms']:8.3g} {k['aicc']:10.4g} "
              f"{k['max_mag_err_db']:7.3f} {k['max_phase_err_deg']:8.2f} "
              f"{'yes' if m.stable else 'NO':>6}  {format_tf(m)}"
              + (f"  [degenerate: {m.degenerate_why or 'flagged'}; the points do not "
                 "support this order]" if m.degenerate else ""))
    print(f"recommended: {result.reason}")
    if result.quality:
        print(f"quality: {result.quality[0]} ({result.quality[1]})")
