"""``heliquad demo``: the identification pipeline end to end on a simulated rig.

For each axis the demo runs the paper's sine dwells (15 log-spaced frequencies over the
axis's Table 1 band) through a known plant, estimates the frequency response with the FSF,
fits the paper's model orders, recommends one and compares it with the truth.

The rig here is :mod:`heliquad.sim.dwell`: SPEC.md's chosen model of each axis, simulated
exactly, with white sensor noise on the output. The firmware is not in the loop yet; when
the SIL lands, the demo runs the same steps through it.
"""

from __future__ import annotations

import math
import os
import sys

import numpy as np

from . import paper
from .files import write_models_json, write_points_csv
from .fit import model_response
from .fsf import estimate_fsf

__all__ = ["add_demo_parser", "run_demo"]

#: Frequencies per axis (SPEC.md: about 15 were used).
N_FREQUENCIES = 15
#: Cycles recorded per frequency after settling.
MEASURED_CYCLES = 10
#: The plant settles for this many of its slowest time constants before recording.
SETTLE_TIME_CONSTANTS = 8


def add_demo_parser(sub, fmt) -> None:
    p = sub.add_parser("demo", help="identify all three axes of the simulated rig",
                       description=__doc__, formatter_class=fmt)
    p.add_argument("--out", default="heliquad-demo", metavar="DIR",
                   help="output directory (default ./heliquad-demo)")
    p.add_argument("--axes", nargs="+", choices=tuple(paper.BANDS_HZ), default=list(paper.BANDS_HZ))
    p.add_argument("--noise-pct", type=float, default=2.0, metavar="P",
                   help="output noise std as a percentage of the largest output amplitude "
                        "in the band (default 2)")
    p.add_argument("--fs-hz", type=float, default=200.0, help="sampling rate (default 200)")
    p.add_argument("--seed", type=int, default=1, help="noise seed (default 1)")
    p.set_defaults(func=run_demo)


def run_demo(args) -> int:
    from .errors import InputError
    from .identify import fit_orders
    from .plot import plot_bode

    if not 0 <= args.noise_pct < 100:
        raise InputError(f"--noise-pct must be in [0, 100), got {args.noise_pct}")
    rng = np.random.default_rng(args.seed)
    os.makedirs(args.out, exist_ok=True)
    summary = []
    for axis in args.axes:
        num, den = paper.MODELS[axis][paper.CHOSEN_ORDER[axis]]
        print(f"== {axis}: true plant {paper.CHOSEN_ORDER[axis]} {num} / {den}", flush=True)
        axis_dir = os.path.join(args.out, axis)
        os.makedirs(os.path.join(axis_dir, "runs"), exist_ok=True)
        points = _sweep(axis, num, den, args, rng, axis_dir)
        table = {"omega": np.array([p.omega_rad_s for p in points]),
                 "F": np.array([p.gain for p in points]),
                 "sigma": np.array([p.sigma for p in points]),
                 "coherence": np.array([p.coherence for p in points])}
        result = fit_orders(table, paper.DEFAULT_ORDERS[axis])
        write_points_csv(os.path.join(axis_dir, "points.csv"), points)
        write_models_json(os.path.join(axis_dir, "models.json"), result.models,
                          result.recommended, result.reason, axis=axis)
        truth = (f"truth {paper.CHOSEN_ORDER[axis]}", lambda w: model_response(num, den, 0, w))
        plot_bode(os.path.join(axis_dir, "bode.png"), table["omega"], table["F"],
                  sigma=table["sigma"], models=result.models, recommended=result.recommended,
                  title=f"{axis}: simulated rig, {args.noise_pct:g} % noise", truth=truth)
        summary.append(_compare(axis, result, num, den))
    _print_summary(summary, args.out)
    return 0


def _sweep(axis, num, den, args, rng, axis_dir):
    from ..sim.dwell import simulate_sine_dwell

    lo, hi = paper.BANDS_HZ[axis]
    freqs = np.logspace(math.log10(lo), math.log10(hi), N_FREQUENCIES)
    slowest = 1.0 / np.min(np.abs(np.roots(den).real))
    peak = np.max(np.abs(model_response(num, den, 0, 2 * np.pi * freqs)))
    noise = args.noise_pct / 100.0 * peak
    points = []
    for i, f in enumerate(freqs, 1):
        settle = math.ceil(SETTLE_TIME_CONSTANTS * slowest * f)
        dwell = simulate_sine_dwell(num, den, f, fs_hz=args.fs_hz, cycles=MEASURED_CYCLES,
                                    settle_cycles=settle, noise_std=noise, rng=rng)
        dwell.to_csv(os.path.join(axis_dir, "runs", f"f{i:02d}_{dwell.freq_hz:.4f}hz.csv"))
        point = estimate_fsf(dwell.u, dwell.y, dwell.fs_hz, freq_hz=dwell.freq_hz,
                             discard_periods=0)
        points.append(point)
        print(f"  [{i:2d}/{len(freqs)}] {point.freq_hz:6.3f} Hz  "
              f"{20 * math.log10(point.magnitude):+7.2f} dB  "
              f"{math.degrees(point.phase_rad):+8.2f} deg  coherence {point.coherence:.4f}",
              flush=True)
    return points


def _compare(axis, result, num, den):
    from .cli import format_tf

    lo, hi = paper.BANDS_HZ[axis]
    dense = 2 * np.pi * np.logspace(math.log10(lo), math.log10(hi), 200)
    if result.recommended is None:
        return (axis, None, result.reason, float("nan"), float("nan"))
    model = result.models[result.recommended]
    ratio = model.response(dense) / model_response(num, den, 0, dense)
    return (axis, format_tf(model), result.reason,
            float(np.max(np.abs(20 * np.log10(np.abs(ratio))))),
            float(np.max(np.abs(np.degrees(np.angle(ratio))))))


def _print_summary(summary, out) -> None:
    print("\n== identified versus true (worst error across each axis's band)")
    for axis, text, reason, db, deg in summary:
        num, den = paper.MODELS[axis][paper.CHOSEN_ORDER[axis]]
        print(f"{axis:>6}: identified {text}\n        true       {num} / {den}\n"
              f"        error {db:.3f} dB, {deg:.2f} deg; {reason}")
    print(f"\nresults (runs, points.csv, models.json, bode.png per axis) are in "
          f"{os.path.abspath(out)}", file=sys.stdout)
