"""One self-contained HTML page of a session (``heliquad report``)."""

from __future__ import annotations

__all__ = ["add_parser", "run"]


def add_parser(sub, fmt) -> None:
    p = sub.add_parser("report", help="one self-contained HTML page of a session",
                       description="Write DIR/report.html: a summary per axis (the "
                                   "recommended model, its error against the simulator's "
                                   "truth, the verdict, the next step), the quality flags "
                                   "(what to act on: low coherence, unstable or poor fits, "
                                   "aborted frequencies, errors beyond 1 dB or 5 deg of the "
                                   "truth) and what is not validated, then every table, "
                                   "model, metric and plot of a sweep folder (or of a folder "
                                   "of them, one per axis); a heliquad effectiveness folder "
                                   "there adds each rotor's effectiveness against the "
                                   "geometry's.", formatter_class=fmt)
    p.add_argument("dir", metavar="DIR")
    p.add_argument("--out", metavar="FILE.html")
    p.set_defaults(func=run)


def run(args) -> int:
    # the command's work, imported when it runs: --help imports every command module
    from ..present.report import write_report

    print(f"wrote {write_report(args.dir, args.out)}")
    return 0
