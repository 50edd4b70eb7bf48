"""Benchmark: how close each fit's J comes to the best J reachable for its order.

CIFER users compare models by J (host/estimate/cifer.py). For every order the paper fitted
on an axis (roll and pitch 0/2, 0/3, 2/4; yaw 0/1, 2/2, 2/3), with and without a delay, on
each point set, this prints the J of

* ``relative``: the fit that minimises the weighted relative complex error alone
  (``heliquad fit --cost relative``, the fit before J's stage);
* ``j``: the default fit, whose last stage minimises J (``--cost j``);
* ``best``: the best J found for the order by a search far wider than the fit's: J's stage
  from every output-error start refined fully (STARTS_PER_KIND None), each refined to
  REFINE_EVALUATIONS, plus RESTARTS random restarts around the best (fixed seed),

and each one's excess over ``best`` in per cent, whether the model is stable, and the CPU
time of the two fits (the baseline: the relative fit of the same points, measured in the
same run). The last lines give, per set and cost, the largest excess and how many of the 18
fits are within 1 % of the best.

Point sets:

* ``sil``: each axis's sweep on the simulated rig in still air (``heliquad sweep --sil --axis
  AXIS`` with its defaults, then ``heliquad identify``): the points of the axis's table, as
  the paper lists its measured points, with their coherence and sigma (the fit's weights
  are identify's: 1/sigma). Run here, in a temporary folder; ``--points AXIS=POINTS.csv``
  takes a file instead.
* ``noisy``: the paper's chosen model of each axis at 15 log-spaced frequencies over its
  band, with a 15 ms delay, a 200 Hz zero-order hold and 10 % complex noise (seed 2), where
  J is in the tens and the costs differ more.

    python benchmarks/fit_j.py [--sets sil noisy] [--points roll=P.csv ...] [--restarts 20]

CPU times move with the machine's load; the J figures do not. Never a test.
"""

from __future__ import annotations

import argparse
import math
import os
import subprocess
import sys
import tempfile
import time

import numpy as np

from heliquad.host.estimate import fit
from heliquad.host.estimate.metrics import evaluate_model
from heliquad.host.estimate.models import point_weights
from heliquad.host.records import paper
from heliquad.host.records.points import frequency_points, known_column, read_points_csv
from heliquad.sim.base.dialect import AXES

RESTARTS = 20
NOISE, SEED, DELAY_S, SAMPLE_HZ, N_POINTS = 0.1, 2, 0.015, 200.0, 15


def sil_points(axis, folder):
    """The axis's still-air sweep on the simulated rig, identified: its points."""
    out = os.path.join(folder, axis)
    for args in (["sweep", "--sil", "--axis", axis, "--out", out], ["identify", out]):
        done = subprocess.run([sys.executable, "-m", "heliquad.host.cli.parser", *args],
                              capture_output=True,
                              text=True)
        if done.returncode:
            raise SystemExit(f"heliquad {args[0]} {axis}: {done.stderr.strip()}")
    return read_points_csv(os.path.join(out, "points.csv"))


def noisy_points(axis):
    num, den = paper.MODELS[axis][paper.CHOSEN_ORDER[axis]]
    lo, hi = paper.BANDS_HZ[axis]
    omega = 2 * math.pi * np.logspace(math.log10(lo), math.log10(hi), N_POINTS)
    s_t = 1j * omega / SAMPLE_HZ
    rng = np.random.default_rng(SEED)
    e = (rng.normal(size=N_POINTS) + 1j * rng.normal(size=N_POINTS)) * NOISE / math.sqrt(2)
    F = fit.model_response(num, den, DELAY_S, omega) * (1 - np.exp(-s_t)) / s_t * (1 + e)
    return frequency_points(omega, F)


def best_j(omega, F, w, coherence, order, delay, restarts, rng):
    """The lowest J found by the wide search (see the module's text)."""
    saved = fit.STARTS_PER_KIND, fit.J_STARTS, fit.J_EVALUATIONS, fit._refined

    def widened(problem, starts, tau_max):
        refined = saved[3](problem, starts, tau_max)
        best = min(refined, key=lambda r: r[1])[0]
        for _ in range(restarts):            # poles moved by up to a factor e, delay anywhere
            trial = best + rng.uniform(-1.0, 1.0, best.size)
            if problem.delay:
                trial[-1] = rng.uniform(0.0, tau_max)
            refined.append(fit._refine(problem, trial, tau_max, fit.REFINE_EVALUATIONS)[:2])
        return refined

    fit.STARTS_PER_KIND, fit.J_STARTS, fit.J_EVALUATIONS = None, 10 ** 6, fit.REFINE_EVALUATIONS
    fit._refined = widened
    try:
        model = fit.fit_tf(omega, F, order, weights=w, delay=delay, coherence=coherence)
    finally:
        fit.STARTS_PER_KIND, fit.J_STARTS, fit.J_EVALUATIONS, fit._refined = saved
    return evaluate_model(model, omega, F, w, coherence)["J"]


def run_set(name, points_of_axis, restarts):
    print(f"\n{name}: {'order':>7} {'J relative':>11} {'J j':>9} {'J best':>9} "
          f"{'relative %':>10} {'j %':>8} {'stable':>6} {'t rel s':>7} {'t j s':>6} {'j/rel':>5}")
    excess = {"relative": [], "j": []}
    rng = np.random.default_rng(1)
    for axis in AXES:
        points = sorted(points_of_axis[axis], key=lambda p: p.omega_rad_s)
        w, _ = point_weights(points)
        omega, F = known_column(points, "omega_rad_s"), known_column(points, "gain")
        coherence = known_column(points, "coherence")
        for order in paper.DEFAULT_ORDERS[axis]:
            for delay in (False, True):
                J, t, stable = {}, {}, True
                for cost in ("relative", "j"):
                    t0 = time.process_time()
                    model = fit.fit_tf(omega, F, order, weights=w, delay=delay, cost=cost,
                                       coherence=coherence)
                    t[cost] = time.process_time() - t0
                    J[cost] = evaluate_model(model, omega, F, w, coherence)["J"]
                    stable = stable and model.stable
                best = min(best_j(omega, F, w, coherence, order, delay, restarts, rng),
                           *J.values())
                pct = {c: 100.0 * (J[c] / best - 1.0) if best > 0 else 0.0 for c in J}
                for c in pct:
                    excess[c].append(pct[c])
                print(f"{axis:>5} {fit.order_name(order, delay):>7} {J['relative']:11.4g} "
                      f"{J['j']:9.4g} {best:9.4g} {pct['relative']:+10.2f} {pct['j']:+8.3f} "
                      f"{'yes' if stable else 'NO':>6} {t['relative']:7.2f} {t['j']:6.2f} "
                      f"{t['j'] / max(t['relative'], 1e-9):5.1f}")
    for cost, values in excess.items():
        within = sum(v <= 1.0 for v in values)
        print(f"{name}, {cost}: largest excess over the best J {max(values):+.3f} %; "
              f"{within} of {len(values)} fits within 1 %")


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--sets", nargs="+", choices=("sil", "noisy"), default=["sil", "noisy"])
    parser.add_argument("--points", action="append", default=[], metavar="AXIS=POINTS.csv",
                        help="an axis's points from a file (the sil set)")
    parser.add_argument("--restarts", type=int, default=RESTARTS,
                        help="random restarts of the search for the best J (default "
                             f"{RESTARTS})")
    args = parser.parse_args(argv)
    given = {}
    for item in args.points:
        axis, _, path = item.partition("=")
        if axis not in AXES or not path:
            parser.error(f"--points {item}: give AXIS=POINTS.csv, AXIS one of "
                         f"{', '.join(AXES)}")
        given[axis] = read_points_csv(path)
    if "sil" in args.sets:
        with tempfile.TemporaryDirectory(prefix="heliquad-fit-j-") as folder:
            sets = {axis: given.get(axis) or sil_points(axis, folder) for axis in AXES}
        run_set("sil (still air, 1/sigma weights)", sets, args.restarts)
    if "noisy" in args.sets:
        run_set("noisy (10 % noise, 1/|F| weights)", {a: noisy_points(a) for a in AXES},
                args.restarts)


if __name__ == "__main__":
    main()
