"""Summarise a .tlog (``heliquad tlog``)."""

from __future__ import annotations

import sys

from ...sim.base.errors import InputError

__all__ = ["add_parser", "run"]


def add_parser(sub, fmt) -> None:
    p = sub.add_parser("tlog", help="summarise a .tlog: messages, time span, lost samples",
                       description="Summarise a .tlog written by heliquad (or any MAVLink 2 "
                                   "log of this dialect). A damaged or truncated file is read "
                                   "up to the damage, with a warning.", formatter_class=fmt)
    p.add_argument("path", metavar="FILE.tlog")
    p.set_defaults(func=run)


def run(args) -> int:
    # the command's work, imported when it runs: --help imports every command module
    from ..acquire.log_session import summarise_tlog

    r = summarise_tlog(args.path)
    if not r["messages"]:
        raise InputError(f"{args.path}: " + ("empty file" if not r["bytes"] else
                                              "no MAVLink record in it (not a .tlog?)"))
    if r["damage"]:
        print(f"heliquad tlog: warning: {r['damage']}", file=sys.stderr)
    print(f"{args.path}: {r['messages']} messages over {r['span_s']:.2f} s; {r['samples']} "
          f"samples, {r['lost']} lost")
    for name, count in r["types"].most_common():
        print(f"  {count:8d}  {name}")
    return 0
