"""A board's parameters over the MAVLink parameter protocol (``heliquad params``)."""

from __future__ import annotations

import datetime
import os
import sys

from ...sim.base.errors import InputError
from .. import __version__
from .shared_options import add_board_actions, finite, require_port

__all__ = ["add_parser", "run"]

HELP = """\
Read and change the board's parameters over its telemetry link, with MAVLink's parameter
protocol (what QGroundControl and MAVProxy use): the firmware answers PARAM_REQUEST_LIST,
PARAM_REQUEST_READ and PARAM_SET with PARAM_VALUE. Values travel as single-precision
floats; whole-number parameters (INT32) take whole numbers only.

  list            every parameter: name, value, type
  get NAME        one parameter
  set NAME VALUE  set it and check the board's answer; a value the board refuses (out of
                  its range, or while it flies) is one line quoting the board's reason
                  (exit 1). The firmware saves a change only while disarmed: on an armed
                  board the change is in force at once and saved when it disarms (said)
  save FILE       every parameter into FILE (QGroundControl's .params format, or with
                  --mavproxy MAVProxy's, which its param load reads; never over a file that
                  exists)
  load FILE       set every parameter of FILE (QGroundControl's or MAVProxy's format) that
                  differs from the board, checking each; the ones refused are listed, the
                  rest still set (exit 1 when any was refused)
  from-vehicle VEHICLE.toml --out FILE
                  no board: the vehicle file's geometry (its rotors and weight) as the
                  firmware's CA_* parameters, into a new .params file that load then sets
                  (docs/vehicle-geometry.md); a vehicle the firmware cannot fly (not 4 to 8
                  rotors, a figure beyond a parameter's range, a geometry its allocation
                  refuses) is one line (exit 2)

A list lost on the way is asked for again by index; every request goes again a few times
before the board is given up on (exit 1, as for a refusal; exit 2 is for wrong arguments
or files). The host's heartbeat goes out all along, as the firmware
wants. File formats: docs/file-formats.md (.params); ground stations:
docs/ground-stations.md.

examples: heliquad params --port /dev/ttyACM0 list
          heliquad params --port auto list          (the one heliquad board: docs/usb.md)
          heliquad params --port udpin:0.0.0.0:14550 set RATE_RLL_KC 2.5
          heliquad params --port /dev/ttyACM0 save rig-2026-11-24.params
          heliquad params from-vehicle my-vehicle.toml --out my-vehicle.params
          heliquad params --port auto load my-vehicle.params
"""


def add_parser(sub, fmt) -> None:
    p, actions = add_board_actions(sub, "params", "list, get, set, save and load the board's "
                                   "parameters; a vehicle file's geometry as parameters",
                                   HELP, fmt, port_required=False)
    actions.add_parser("list", help="every parameter: name, value, type")
    actions.add_parser("get", help="one parameter").add_argument("name", metavar="NAME")
    setter = actions.add_parser("set", help="set one parameter and check the board took it")
    setter.add_argument("name", metavar="NAME")
    setter.add_argument("value", metavar="VALUE", type=finite)
    saver = actions.add_parser("save", help="every parameter into a new .params file")
    saver.add_argument("file", metavar="FILE")
    saver.add_argument("--mavproxy", action="store_true",
                       help="MAVProxy's layout (NAME VALUE), which its param load reads, instead "
                            "of QGroundControl's")
    actions.add_parser("load", help="set the parameters of a .params file").add_argument(
        "file", metavar="FILE")
    vehicle = actions.add_parser("from-vehicle", help="a vehicle file's geometry as a new "
                                 ".params file (no board)")
    vehicle.add_argument("vehicle", metavar="VEHICLE.toml",
                         help="the vehicle file (sim/plant/vehicle.toml is the reference)")
    vehicle.add_argument("--out", required=True, metavar="FILE",
                         help="the .params file to write (never over one that exists)")
    p.set_defaults(func=run)


def run(args) -> int:
    # the command's work, imported when it runs: --help imports every command module
    from ..acquire.link import TelemetryLink
    from ..acquire.param_protocol import ParamClient
    from ..acquire.ports import resolve_port
    from ..records.params_file import check_name, read_params_file

    if args.action == "from-vehicle":
        return _from_vehicle(args)
    require_port(args)
    entries = None
    if args.action == "save":
        _check_new_file(args.file, "save")
    elif args.action == "load":
        entries = [(name, value) for name, value, _ in read_params_file(args.file)]
    elif args.action in ("get", "set"):
        check_name(args.name)
    link = TelemetryLink(resolve_port(args.port), baud=args.baud)
    try:
        client = ParamClient(link, progress=lambda text: print(text, flush=True))
        return _ACTIONS[args.action](client, args, entries)
    finally:
        link.close()


def _check_new_file(path, action: str) -> None:
    """``path`` may become a new parameter file: heliquad never writes over one."""
    # the command's work, imported when it runs: --help imports every command module
    from ..records.output import check_output

    if os.path.lexists(path):
        raise InputError(f"{path} exists: heliquad never writes over a parameter file; give "
                         "another name")
    check_output(path, action)


def _from_vehicle(args) -> int:
    """The vehicle file's geometry parameters into a new .params file (no board)."""
    # the command's work, imported when it runs: --help imports every command module
    from ...sim.base.dialect import dialect
    from ...sim.plant.rotor_geometry import geometry_params
    from ...sim.plant.vehicle_params import load_params
    from ..acquire.param_protocol import Param
    from ..records.params_file import write_params_file

    vehicle = load_params(args.vehicle)
    geometry = geometry_params(vehicle)
    _check_new_file(args.out, "--out")
    mav = dialect()
    params = [Param(g.name, g.value, mav.MAV_PARAM_TYPE_INT32 if g.integer
                    else mav.MAV_PARAM_TYPE_REAL32, index)
              for index, g in enumerate(geometry)]
    write_params_file(args.out, params, header=f"heliquad {__version__}, the geometry of the "
                      f"vehicle file {args.vehicle} (heliquad params from-vehicle)")
    print(f"wrote {len(params)} parameters to {args.out}: {len(vehicle.rotors)} rotors, "
          f"weight {geometry[1].value:.4g} N")
    return 0


def _list(client, args, entries) -> int:
    # the command's work, imported when it runs: --help imports every command module
    from ..records.params_file import TYPE_NAMES

    params = client.fetch_all()
    width = max([len("NAME")] + [len(p.name) for p in params])
    print(f"{'NAME':<{width}}  {'VALUE':>14}  TYPE")
    for p in params:
        print(f"{p.name:<{width}}  {p.text():>14}  {TYPE_NAMES.get(p.type, p.type)}")
    return 0


def _get(client, args, entries) -> int:
    p = client.get(args.name)
    print(f"{p.name} {p.text()}")
    return 0


def _set(client, args, entries) -> int:
    param = client.get(args.name)
    got = client.set(param, args.value)
    same = " (unchanged)" if got.text() == param.text() else ""
    when = ""
    if not same and client.is_armed():
        when = " (in force now; the board is armed: it saves the change when it disarms)"
    print(f"{got.name}: {param.text()} -> {got.text()}{same}{when}")
    return 0


def _save(client, args, entries) -> int:
    # the command's work, imported when it runs: --help imports every command module
    from ..records.params_file import write_params_file

    params = client.fetch_all()
    when = datetime.datetime.now(datetime.timezone.utc).isoformat(timespec="seconds")
    write_params_file(args.file, params,
                      header=f"heliquad {__version__}, from {client.link.name}, {when}",
                      layout="mavproxy" if args.mavproxy else "qgc")
    print(f"wrote {len(params)} parameters to {args.file}")
    return 0


def _load(client, args, entries) -> int:
    # the command's work, imported when it runs: --help imports every command module
    from ..acquire.param_protocol import load_params

    print(f"loading {len(entries)} parameters from {args.file}", flush=True)
    r = load_params(client, entries)
    refused = r["refused"]
    print(f"{len(r['changed'])} set, {r['unchanged']} already so, {len(refused)} refused")
    if refused:
        names = ", ".join(name for name, _ in refused)
        sys.stderr.write(f"heliquad params: the board refused {len(refused)} of "
                         f"{len(entries)} parameters from {args.file}: {names} (why: above)\n")
        return 1
    return 0


_ACTIONS = {"list": _list, "get": _get, "set": _set, "save": _save, "load": _load}
