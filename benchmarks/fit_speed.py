"""Benchmark: transfer-function fits with and without a fitted delay, time and cost.

Point sets like a sweep's: each of the paper's models of an axis (host/records/paper.py MODELS)
at 15 log-spaced frequencies across the axis's band (paper.BANDS_HZ), times a pure delay
(15 ms by default) and a zero-order hold at 200 Hz ((1 - e^{-sT}) / (sT): half a sample of
delay and a slight droop), times (1 + e) with e complex Gaussian noise of the given RMS
levels (0 is the noise-free set; fixed seed). Every order the paper fitted on the axis is
fitted to every set, with and without a delay, with fit_tf's default weights 1/|F|.

Each fit is timed as the best of --repeats calls (CPU time of this process). The baseline,
measured in the same run on the same points, is one plain Levy solve (fit_levy, one linear
least-squares problem); times are printed in ms and as multiples of it. The cost printed is
the one the fit minimises, sum |F - G|^2 / |F|^2 over the points, and tau the fitted delay.
The last lines give, per point set, the total time of the axis's orders with a delay.

`--exhaustive` also fits with a delay refining every start of the delay grid fully (the
search fit_tf made before it chose among them; host/estimate/fit.py STARTS_PER_KIND = None), once,
and prints its time and by how much its cost is below the one found (relative; 0 or
negative when the chosen starts found the same minimum or a better one).

    python benchmarks/fit_speed.py [--axes roll yaw] [--noise 0 0.01 0.03] [--delay-ms 15]
        [--seed 1] [--repeats 3] [--exhaustive]

CPU times on a shared machine move with its load. Never a test.
"""

from __future__ import annotations

import argparse
import math
import time

import numpy as np

SAMPLE_HZ = 200.0
N_POINTS = 15


def point_set(axis, truth, delay_s, noise, seed):
    """``(omega, F)``: the paper's ``truth`` model of ``axis`` with a delay, a zero-order
    hold and complex noise of RMS ``noise``."""
    from heliquad.host.estimate.fit import model_response
    from heliquad.host.records import paper

    num, den = paper.MODELS[axis][truth]
    lo, hi = paper.BANDS_HZ[axis]
    omega = 2 * math.pi * np.logspace(math.log10(lo), math.log10(hi), N_POINTS)
    s_t = 1j * omega / SAMPLE_HZ
    zoh = (1 - np.exp(-s_t)) / s_t
    rng = np.random.default_rng(seed)
    e = (rng.normal(size=N_POINTS) + 1j * rng.normal(size=N_POINTS)) * noise / math.sqrt(2)
    return omega, model_response(num, den, delay_s, omega) * zoh * (1 + e)


def best_time(fn, repeats):
    """Smallest CPU time of ``repeats`` calls, and the last result."""
    best = math.inf
    for _ in range(repeats):
        t0 = time.process_time()
        result = fn()
        best = min(best, time.process_time() - t0)
    return best, result


def cost(model, omega, F):
    """The weighted output error the fit minimises (weights 1/|F|)."""
    return float(np.sum(np.abs((F - model.response(omega)) / F) ** 2))


def exhaustive(omega, F, order):
    """CPU time and model of a delay fit that refines every start of the delay grid."""
    from heliquad.host.estimate import fit

    chosen = fit.STARTS_PER_KIND
    fit.STARTS_PER_KIND = None
    try:
        return best_time(lambda: fit.fit_tf(omega, F, order, delay=True), 1)
    finally:
        fit.STARTS_PER_KIND = chosen


def one_set(axis, truth, noise, args):
    """Fit every order of the axis to one point set; print a line per order. Returns the
    total delay-fit time over the orders."""
    from heliquad.host.estimate.fit import fit_levy, fit_tf
    from heliquad.host.records import paper

    omega, F = point_set(axis, truth, args.delay_ms * 1e-3, noise, args.seed)
    levy, _ = best_time(lambda: fit_levy(omega, F, truth), max(args.repeats, 20))
    total = 0.0
    for order in paper.MODELS[axis]:
        t_plain, plain = best_time(lambda: fit_tf(omega, F, order), args.repeats)
        t_delay, delayed = best_time(lambda: fit_tf(omega, F, order, delay=True), args.repeats)
        total += t_delay
        line = (f"{axis:>5} {truth[0]}/{truth[1]} {noise:5.2f} {order[0]}/{order[1]} "
                f"{levy * 1e6:7.0f} {t_plain * 1e3:8.1f} {t_plain / levy:7.0f} "
                f"{cost(plain, omega, F):11.4e} {t_delay * 1e3:8.1f} {t_delay / levy:7.0f} "
                f"{cost(delayed, omega, F):11.4e} {delayed.delay_s * 1e3:6.2f}")
        if args.exhaustive:
            t_all, every = exhaustive(omega, F, order)
            found, best = cost(delayed, omega, F), cost(every, omega, F)
            line += f" {t_all * 1e3:9.1f} {(found - best) / best:+9.1e}"
        print(line, flush=True)
    return total


def main():
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    from heliquad.host.records import paper

    parser.add_argument("--axes", nargs="+", choices=tuple(paper.MODELS),
                        default=["roll", "yaw"])
    parser.add_argument("--noise", nargs="+", type=float, default=[0.0, 0.01, 0.03],
                        help="RMS complex noise per point, relative (0: noise-free)")
    parser.add_argument("--delay-ms", type=float, default=15.0, help="the points' delay")
    parser.add_argument("--seed", type=int, default=1)
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--exhaustive", action="store_true",
                        help="also refine every start of the delay grid (slow)")
    args = parser.parse_args()

    print(f"{'axis':>5} {'set':>3} {'noise':>5} {'fit':>3} {'levy us':>7} {'plain ms':>8} "
          f"{'x levy':>7} {'cost':>11} {'delay ms':>8} {'x levy':>7} {'cost':>11} "
          f"{'tau ms':>6}" + (f" {'all ms':>9} {'above':>9}" if args.exhaustive else ""))
    totals = []
    for axis in args.axes:
        for truth in paper.MODELS[axis]:
            for noise in args.noise:
                totals.append((axis, truth, noise, one_set(axis, truth, noise, args)))
    print("\nwith a delay, all orders of the axis per point set:")
    for axis, truth, noise, total in totals:
        print(f"{axis:>5} {truth[0]}/{truth[1]} {noise:5.2f} {total * 1e3:8.1f} ms")
    print(f"mean {np.mean([t for *_, t in totals]) * 1e3:.1f} ms, worst "
          f"{max(t for *_, t in totals) * 1e3:.1f} ms")


if __name__ == "__main__":
    main()
