"""The board's on-board logs over the MAVLink log protocol (``heliquad logs``)."""

from __future__ import annotations

import datetime
import os

from ...sim.base.errors import InputError
from .shared_options import add_board_actions, int_in

__all__ = ["add_parser", "run"]

HELP = """\
List, download and erase the logs the board keeps on its SD card (DataFlash .BIN files,
read by pymavlink's mavlogdump.py), over its telemetry link with MAVLink's log protocol
(what MAVProxy's log module and Mission Planner use). The board serves its logs only while
disarmed.

  list            every log: number, size, time (UTC; - when the board had no time)
  download N      log N into --out (default ./0000000N.BIN, never over a file that exists),
                  with a progress line at each tenth. What has come is kept in OUT.part as
                  it comes: a download cut off (the link gone, Ctrl-C) resumes there when
                  run again. The whole file is checked against the size the list gave and
                  written at once
  erase           erase every log (asks nothing: scripts use it) and say what went

Packets lost on the way are asked for again; a board that stops answering is given up on
after a few requests (exit 1, as for an armed board; exit 2 is for wrong arguments, files,
or a log the board does not have). --port auto finds the one heliquad board (docs/usb.md).
Protocol: docs/ground-stations.md.

examples: heliquad logs --port /dev/ttyACM0 list
          heliquad logs --port auto download 3 --out hover.BIN
          heliquad logs --port auto erase
"""

#: LOG_ENTRY.id and LOG_REQUEST_DATA.id are uint16.
MAX_LOG_ID = 0xFFFF


def add_parser(sub, fmt) -> None:
    p, actions = add_board_actions(sub, "logs", "list, download and erase the board's "
                                   "on-board logs", HELP, fmt)
    actions.add_parser("list", help="every log: number, size, time")
    getter = actions.add_parser("download", help="one log into a file, resumable")
    getter.add_argument("log_id", metavar="N", type=int_in(1, MAX_LOG_ID))
    getter.add_argument("--out", metavar="FILE",
                        help="where the log goes (default ./0000000N.BIN: the card's name)")
    actions.add_parser("erase", help="erase every log on the board")
    p.set_defaults(func=run)


def run(args) -> int:
    # the command's work, imported when it runs: --help imports every command module
    from ..acquire.link import TelemetryLink
    from ..acquire.log_protocol import LogClient
    from ..acquire.ports import resolve_port
    from ..records.output import check_output

    if args.action == "download":
        args.out = args.out or f"{args.log_id:08d}.BIN"
        if os.path.lexists(args.out):
            raise InputError(f"--out {args.out} exists: heliquad never writes over a log; "
                             "give another name")
        check_output(args.out, "--out")
    link = TelemetryLink(resolve_port(args.port), baud=args.baud)
    try:
        client = LogClient(link, progress=lambda text: print(text, flush=True))
        return _ACTIONS[args.action](client, args)
    finally:
        link.close()


def _when(time_utc_s: int) -> str:
    if not time_utc_s:
        return "-"
    t = datetime.datetime.fromtimestamp(time_utc_s, datetime.timezone.utc)
    return t.strftime("%Y-%m-%d %H:%M:%S")


def _list(client, args) -> int:
    logs = client.list()
    if not logs:
        print(f"no logs on the board at {client.link.name}")
        return 0
    print(f"{'LOG':>5}  {'BYTES':>10}  TIME (UTC)")
    for e in logs:
        print(f"{e.id:>5}  {e.size_bytes:>10}  {_when(e.time_utc_s)}")
    print(f"{len(logs)} logs, {sum(e.size_bytes for e in logs)} bytes")
    return 0


def _download(client, args) -> int:
    entry = client.entry(args.log_id)
    print(f"downloading log {entry.id} ({entry.size_bytes} bytes) from {client.link.name} "
          f"into {args.out}", flush=True)
    resumed = client.download(entry, args.out)
    again = f", resumed at {resumed}" if resumed else ""
    print(f"wrote log {entry.id} to {args.out} ({entry.size_bytes} bytes{again})")
    return 0


def _erase(client, args) -> int:
    logs = client.list()
    client.erase()
    if not logs:
        print(f"erased: the board at {client.link.name} had no logs")
        return 0
    print(f"erased {len(logs)} logs ({logs[0].id}..{logs[-1].id}, "
          f"{sum(e.size_bytes for e in logs)} bytes) from the board at {client.link.name}")
    return 0


_ACTIONS = {"list": _list, "download": _download, "erase": _erase}
