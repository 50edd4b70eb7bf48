"""Frequency-response points from sine runs (``heliquad fsf``)."""

from __future__ import annotations

import math
import sys

import numpy as np

from ...sim.base.errors import InputError
from ..estimate.thresholds import LOW_COHERENCE
from .shared_options import int_in, number_in

__all__ = ["add_parser", "run"]

HELP = """\
Estimate frequency-response points with the frequency sampling filter (FSF) and least
squares (the paper's step 2, docs/paper.md): one point per sine experiment, or, with
--orders, one point per line of a multisine experiment (a sum of sines at harmonics of one
base frequency, all estimated from the one record).

RUN.csv: a header row, then columns t_s,u,y (seconds, input, output; any order, other
columns ignored), uniformly sampled, one sine frequency (or one multisine) per file.
POINTS.csv (written): omega_rad_s,magnitude,phase_rad,sigma,coherence, one row per point,
sorted by frequency; magnitude linear, phase in radians, sigma the standard deviation of
the complex gain, coherence the magnitude-squared coherence at that frequency.

examples: heliquad fsf runs/*.csv --discard-periods 2 --out points.csv
          heliquad fsf multisine.csv --freq-hz 0.1 --orders 5 7 10 14 20 28 40 --out points.csv
"""

#: Settling periods dropped by default: a sine's first period; none of a multisine's (the
#: filter's first base period is its settling).
DISCARD_SINE, DISCARD_MULTISINE = 1, 0
#: A multisine run's base period may differ from a whole number of samples by this much
#: (relative): the sampling rate is estimated from the timestamps, which may jitter.
PERIOD_TOLERANCE = 1e-4
#: A multisine run's input has a line at least this many times the power of the frequencies
#: around it, or its base frequency or lines were given wrong.
LINE_SNR = 10.0
#: Harmonics of a sine run's FSF model by default (as in the paper).
HARMONICS = 3


def add_parser(sub, fmt) -> None:
    p = sub.add_parser("fsf", help="frequency-response points from sine or multisine runs",
                       description=HELP, formatter_class=fmt)
    p.add_argument("runs", nargs="+", metavar="RUN.csv", help="one experiment per file")
    p.add_argument("--freq-hz", type=number_in(0, 1e6, lo_open=True), action="append", metavar="F",
                   help="excitation frequency (a multisine's base frequency): once for all "
                        "runs or once per run (default for sines: found from the input signal; "
                        "a multisine needs it)")
    p.add_argument("--orders", type=int_in(1, 1_000_000), nargs="+", metavar="L",
                   help="the runs are multisines with lines at these harmonics of the base "
                        "frequency --freq-hz (whose period must be a whole number of samples): "
                        "one point per line the input excites (give them after the RUN.csv "
                        "files, or before another option)")
    p.add_argument("--harmonics", type=int_in(1, 50), metavar="L",
                   help=f"sine runs: harmonics -L..L in the FSF model (default {HARMONICS}, "
                        "as in the paper)")
    p.add_argument("--discard-periods", type=int_in(0, 1_000_000), metavar="K",
                   help=f"settling periods dropped at the start of each run (default "
                        f"{DISCARD_SINE} for a sine; {DISCARD_MULTISINE} for a multisine, whose "
                        "first base period the filter takes to settle)")
    p.add_argument("--no-offset", action="store_true",
                   help="do not estimate a constant output offset")
    p.add_argument("--out", required=True, metavar="POINTS.csv", help="points file to write")
    p.set_defaults(func=run)


def run(args) -> int:
    # the command's work, imported when it runs: --help imports every command module
    from ..records.output import check_output
    from ..records.points import write_points_csv
    from ..records.run_csv import read_run_csv

    check_output(args.out, "--out")
    freqs = _frequencies(args)
    points, origin = [], {}
    for i, (path, freq) in enumerate(zip(args.runs, freqs), 1):
        fs_hz, u, y = read_run_csv(path)
        try:
            found = _estimate(args, u, y, fs_hz, freq)
        except InputError as exc:
            raise InputError(f"{path}: {exc}") from None
        for point in found:
            key = round(point.omega_rad_s, 9)
            if key in origin:
                raise InputError(f"{path} and {origin[key]} are both at {point.freq_hz:.6g} "
                                 "Hz; one point per frequency")
            origin[key] = path
        points += found
        _say(i, len(args.runs), path, found, multisine=args.orders is not None)
    write_points_csv(args.out, points)
    print(f"wrote {len(points)} point(s) to {args.out}")
    return 0


def _frequencies(args) -> list:
    """Each run's frequency (None: found from its input), the options checked together."""
    freqs = args.freq_hz or [None]
    if len(freqs) not in (1, len(args.runs)):
        raise InputError(f"--freq-hz given {len(freqs)} times for {len(args.runs)} runs; "
                         "give it once for all runs or once per run")
    if args.orders is not None:
        if freqs == [None]:
            raise InputError("--orders needs --freq-hz, the multisine's base frequency")
        if args.harmonics is not None:
            raise InputError("--harmonics is for sine runs; a multisine's lines are --orders")
        if any(b <= a for a, b in zip(args.orders, args.orders[1:])):
            raise InputError(f"--orders must be strictly increasing, got {args.orders}")
    return freqs * len(args.runs) if len(freqs) == 1 else freqs


def _estimate(args, u, y, fs_hz, freq) -> list:
    """One run's points: a sine's one, or every line of a multisine its input excites."""
    # the command's work, imported when it runs (after the file is read): --help imports every
    # command module
    from ..estimate.fsf import estimate_fsf, estimate_multisine

    if args.orders is None:
        discard = DISCARD_SINE if args.discard_periods is None else args.discard_periods
        return [estimate_fsf(u, y, fs_hz, freq_hz=freq,
                             harmonics=HARMONICS if args.harmonics is None else args.harmonics,
                             discard_periods=discard, offset=not args.no_offset)]
    period = fs_hz / freq
    if abs(period - round(period)) > PERIOD_TOLERANCE * period:
        raise InputError(f"the base period, {fs_hz:.6g} Hz / {freq:.6g} Hz = {period:.6g} "
                         "samples, is not a whole number: a multisine's lines are harmonics "
                         "of a whole period (give its exact base frequency)")
    discard = DISCARD_MULTISINE if args.discard_periods is None else args.discard_periods
    found = estimate_multisine(u, y, fs_hz, round(period), args.orders, discard_periods=discard,
                               offset=not args.no_offset)     # which checks lines and period
    if not _a_line_stands_out(u, round(period), args.orders, discard):
        raise InputError(f"none of the --orders lines of {freq:.6g} Hz stands out of the "
                         f"input's spectrum ({LINE_SNR:g} times the power of the frequencies "
                         "around it): is that the multisine's exact base frequency, and are "
                         "those its lines?")
    if not found:
        raise InputError("the input excites none of the lines --orders names")
    return found


def _a_line_stands_out(u, period: int, orders, discard: int) -> bool:
    """Whether the power of ``u`` at one of the harmonics ``orders`` of the period, at least,
    is LINE_SNR times the median power of the frequencies around it that are no harmonic
    (within two harmonics either side), over the whole periods after ``discard``: with ``n``
    whole periods, harmonic ``l`` is DFT bin ``n l`` and the bins between are no harmonic.
    A wrong base frequency puts nothing special at those bins; what else drives the input
    (noise, a disturbance the loop answers) spreads over all of them. True when it cannot
    tell (fewer than two whole periods)."""
    start = discard * period
    n = (len(u) - start) // period
    if n < 2:
        return True
    power = np.abs(np.fft.rfft(np.asarray(u[start:start + n * period], float))) ** 2
    for line in orders:
        at = n * line
        around = [k for k in range(at - 2 * n, at + 2 * n + 1) if k % n and 0 < k < power.size]
        if at < power.size and around and power[at] > LINE_SNR * np.median(power[around]):
            return True
    return False


def _say(i, n, path, points, multisine) -> None:
    """The run's points, and a warning for each of low coherence."""
    if multisine:
        print(f"[{i}/{n}] {path}: multisine, {len(points)} line(s)", flush=True)
        for p in points:
            print(f"    line {p.order}: {_describe_point(p)}", flush=True)
    else:
        print(f"[{i}/{n}] {path}: {_describe_point(points[0])}", flush=True)
    for p in points:
        if p.coherence < LOW_COHERENCE:
            print(f"warning: {path}: low coherence {p.coherence:.2f} at {p.freq_hz:.4g} Hz; "
                  "the point is unreliable", file=sys.stderr)


def _describe_point(p) -> str:
    return (f"{p.freq_hz:.4g} Hz  |G| {p.magnitude:.5g} ({20 * math.log10(p.magnitude):+.2f} dB)"
            f"  phase {math.degrees(p.phase_rad):+.2f} deg  sigma {100 * p.sigma / p.magnitude:.2g} %"
            f"  coherence {p.coherence:.4f}  [{p.method}, {p.n_periods} periods of "
            f"{p.period_samples:.6g} samples]")
