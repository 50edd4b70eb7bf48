"""The board's on-board identification program (``heliquad program``): set, show, clear."""

from __future__ import annotations

from ...sim.base import dialect as names
from ..acquire.link import INPUT_OUTPUT
from .shared_options import add_board_actions
from .sweep_options import add_design_arguments, sweep_plan

__all__ = ["add_parser", "run"]

HELP = """\
The board's on-board identification program: a sweep stored on the board and run by the
pilot with no computer attached (a cable drags on a rig that swings +-80 deg). The pilot arms,
raises the throttle and moves channel 7 from low to high: the board runs the program's steps
one after another, each an excitation under every rule a host's has (bounds, the angle and
rate limits, the failsafes); releasing channel 7, disarming or any stop ends it, with its
reason. The samples go out in the telemetry as a host's sweep's do (docs/safety.md).

  set   the sweep as `heliquad sweep` designs it (--axis, --inject and the design options),
        with a fixed dwell (--cycles, default 8) and fixed amplitudes (a mixer's default: a
        quarter of the firmware's bound, the design's first): the board checks every step
        against its bounds and keeps its old program when one is refused (exit 1, the
        board's reason)
  show  the program the board keeps, one step a line
  clear forget it

Set and clear only while the board is disarmed. The program survives a reset (the board's
own store).

examples: heliquad program --port auto set --axis roll
          heliquad program --port /dev/ttyACM0 set --axis pitch --signal multisine
          heliquad program --port auto show
"""


def add_parser(sub, fmt) -> None:
    p, actions = add_board_actions(sub, "program", "set, show or clear the board's on-board "
                                   "sweep", HELP, fmt)
    setter = actions.add_parser("set", help="store a sweep as the board's program")
    setter.add_argument("--axis", choices=tuple(names.AXES), required=True)
    setter.add_argument("--inject", choices=tuple(INPUT_OUTPUT), default="mixer")
    add_design_arguments(setter, on_board=True)
    actions.add_parser("show", help="the board's program, one step a line")
    actions.add_parser("clear", help="forget the board's program")
    p.set_defaults(func=run)


def run(args) -> int:
    # the command's work, imported when it runs: --help imports every command module
    from ..acquire.link import TelemetryLink
    from ..acquire.ports import resolve_port
    from ..acquire.program import ProgramClient, program_steps, step_text

    steps = None
    if args.action == "set":
        steps = program_steps(sweep_plan(args, on_board=True))
    link = TelemetryLink(resolve_port(args.port), baud=args.baud)
    try:
        client = ProgramClient(link, progress=lambda text: print(text, flush=True))
        if args.action == "set":
            client.set(steps)
            print(f"the board keeps a program of {_steps(len(steps))}; channel 7 runs it")
        elif args.action == "clear":
            client.clear()
            print("the board keeps no program")
        else:
            shown = client.show()
            print(_steps(len(shown)) if shown else "no program stored")
            for i, step in enumerate(shown, 1):
                print(step_text(i, step))
        return 0
    finally:
        link.close()


def _steps(n: int) -> str:
    return f"{n} step" if n == 1 else f"{n} steps"
