"""Log a board's telemetry to a .tlog (``heliquad log``)."""

from __future__ import annotations

import sys

from ...sim.base.errors import DiskFull, InputError
from .shared_options import add_baud_argument, add_port_argument, number_in

__all__ = ["add_parser", "run"]

HELP = """\
Log every MAVLink message from a board's telemetry port to a .tlog (8-byte big-endian
timestamp in us, then the packet; pymavlink reads it). The file is flushed as it goes, so
Ctrl-C or a crash leaves a valid log; a full disk or a link that goes away ends the session
with one line and exit 1, the log kept up to its last whole record. Ctrl-C, SIGTERM and
SIGHUP end it after the summary, with exit 130, 143 and 129. Lost samples are counted from the gaps in
HQ_SYSID_SAMPLE.seq; a summary is printed at the end, and a status line every 5 s.

--port takes a serial device, auto (the one heliquad board attached by USB or running as
heliquad board, found by its USB identity) or a network link (udpin:, udpout:, tcp:, tcpin:),
as MAVProxy and mavutil write them; a listening link (udpin:, tcpin:) sends the host's heartbeat once it
has heard from the board.

examples: heliquad board --telemetry /tmp/rig &  heliquad log --port /tmp/rig --out flight.tlog
          heliquad log --port udpin:0.0.0.0:14550 --out flight.tlog   (a forwarder sends there)
"""



def add_parser(sub, fmt) -> None:
    p = sub.add_parser("log", help="log a board's (or a SIL's) telemetry to a .tlog",
                       description=HELP, formatter_class=fmt)
    add_port_argument(p)
    p.add_argument("--out", required=True, metavar="FILE.tlog")
    add_baud_argument(p)
    p.add_argument("--duration-s", type=number_in(0, 1e7, lo_open=True), metavar="S", help="stop after S seconds "
                   "(default: until Ctrl-C)")
    p.set_defaults(func=run)


def run(args) -> int:
    # the command's work, imported when it runs: --help imports every command module
    from ..acquire.log_session import run_log
    from ..acquire.ports import resolve_port

    if args.duration_s is not None and args.duration_s <= 0:
        raise InputError("--duration-s must be positive")
    port = resolve_port(args.port)
    print(f"logging {port} to {args.out} (Ctrl-C to stop)", flush=True)
    r = run_log(port, args.out, args.baud, args.duration_s)
    print(f"{r['seconds']:.1f} s: {r['messages']} messages, {r['samples']} samples"
          + (f" (seq {r['first_seq']}..{r['last_seq']})" if r["samples"] else "")
          + f", {r['lost']} lost; wrote {args.out}")
    if r["interrupted"] is not None:             # said, and its code, by the command line
        raise r["interrupted"]
    stopped = r["stopped"]
    if isinstance(stopped, DiskFull):
        raise stopped.also("logging stopped; the log up to here is kept")
    if stopped is not None:
        sys.stderr.write(f"heliquad log: {stopped}; the log up to here is kept in {args.out}\n")
        return 1
    return 0
