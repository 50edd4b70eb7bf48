"""Frequency-response points from sine runs (``heliquad fsf``)."""

from __future__ import annotations

import math
import sys

from ..cli_args import number_in
from ..errors import InputError

__all__ = ["add_parser", "run"]

HELP = """\
Estimate one frequency-response point per sine experiment with the frequency sampling
filter (FSF) and least squares (the paper's step 2, docs/paper.md).

RUN.csv: a header row, then columns t_s,u,y (seconds, input, output; any order, other
columns ignored), uniformly sampled, one sine frequency per file.
POINTS.csv (written): omega_rad_s,magnitude,phase_rad,sigma,coherence, one row per run,
sorted by frequency; magnitude linear, phase in radians, sigma the standard deviation of
the complex gain, coherence the magnitude-squared coherence at that frequency.

example: heliquad fsf runs/*.csv --discard-periods 2 --out points.csv
"""



def add_parser(sub, fmt) -> None:
    p = sub.add_parser("fsf", help="frequency-response points from sine runs",
                       description=HELP, formatter_class=fmt)
    p.add_argument("runs", nargs="+", metavar="RUN.csv", help="one sine experiment per file")
    p.add_argument("--freq-hz", type=number_in(0, 1e6, lo_open=True), action="append", metavar="F",
                   help="excitation frequency: once for all runs or once per run "
                        "(default: found from the input signal)")
    p.add_argument("--harmonics", type=int, default=3, metavar="L",
                   help="harmonics -L..L in the FSF model (default 3, as in the paper)")
    p.add_argument("--discard-periods", type=int, default=1, metavar="K",
                   help="settling periods dropped at the start of each run (default 1)")
    p.add_argument("--no-offset", action="store_true",
                   help="do not estimate a constant output offset")
    p.add_argument("--out", required=True, metavar="POINTS.csv", help="points file to write")
    p.set_defaults(func=run)


def run(args) -> int:
    from ..files import check_output, read_run_csv, write_points_csv
    from ..report import LOW_COHERENCE

    check_output(args.out, "--out")
    freqs = args.freq_hz or [None]
    if len(freqs) not in (1, len(args.runs)):
        raise InputError(f"--freq-hz given {len(freqs)} times for {len(args.runs)} runs; "
                         "give it once for all runs or once per run")
    if len(freqs) == 1:
        freqs = freqs * len(args.runs)
    points, origin = [], {}
    for i, (path, freq) in enumerate(zip(args.runs, freqs), 1):
        fs_hz, u, y = read_run_csv(path)
        from ..fsf import estimate_fsf          # after the file is read: scipy takes a while

        try:
            point = estimate_fsf(u, y, fs_hz, freq_hz=freq, harmonics=args.harmonics,
                                 discard_periods=args.discard_periods, offset=not args.no_offset)
        except InputError as exc:
            raise InputError(f"{path}: {exc}") from None
        key = round(point.omega_rad_s, 9)
        if key in origin:
            raise InputError(f"{path} and {origin[key]} are both at {point.freq_hz:.6g} Hz; "
                             "one point per frequency")
        origin[key] = path
        points.append(point)
        print(f"[{i}/{len(args.runs)}] {path}: {_describe_point(point)}", flush=True)
        if point.coherence < LOW_COHERENCE:
            print(f"warning: {path}: low coherence {point.coherence:.2f}; the point is "
                  "unreliable", file=sys.stderr)
    write_points_csv(args.out, points)
    print(f"wrote {len(points)} point(s) to {args.out}")
    return 0


def _describe_point(p) -> str:
    return (f"{p.freq_hz:.4g} Hz  |G| {p.magnitude:.5g} ({20 * math.log10(p.magnitude):+.2f} dB)"
            f"  phase {math.degrees(p.phase_rad):+.2f} deg  sigma {100 * p.sigma / p.magnitude:.2g} %"
            f"  coherence {p.coherence:.4f}  [{p.method}, {p.n_periods} periods of "
            f"{p.period_samples:.6g} samples]")
