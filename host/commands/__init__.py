"""The ``heliquad`` subcommands, one module each.

Every command module has ``add_parser(sub, fmt)``, which adds its subparser and sets
``func`` to its ``run(args) -> exit code``. The modules here hold the commands that are a
front end to library code elsewhere in :mod:`heliquad.host`; ``demo``, ``dmp-image``,
``flash`` and ``mavlink-dialect`` live in the modules that do their work. :data:`COMMANDS`
names them, in the order ``heliquad --help`` lists them.
"""

from __future__ import annotations

import importlib

__all__ = ["COMMANDS", "add_parsers"]

#: Each subcommand's name and module (relative to :mod:`heliquad.host`), in the order
#: ``heliquad --help`` lists them.
COMMANDS = {"fsf": "commands.fsf", "fit": "commands.fit", "sil": "commands.sil",
            "board": "commands.board", "validate": "commands.validate", "log": "commands.log",
            "tlog": "commands.tlog", "sweep": "commands.sweep", "identify": "commands.identify",
            "report": "commands.report", "params": "commands.params", "demo": "demo",
            "dmp-image": "dmp_image", "flash": "flash", "mavlink-dialect": "mavlink_dialect"}


def add_parsers(sub, fmt, argv=()) -> None:
    """Add the subcommands' parsers to ``sub`` (argparse subparsers): only the one the
    command line ``argv`` names, when its first word is a command, else every one (to list
    them, to say which there are, or for an option before the command: ``heliquad -h
    identify``). A command then pays for importing its own module only, not every
    command's (numpy, the vehicle, the dialect: a tenth of a second)."""
    named = argv[0] if argv else None
    for name in [named] if named in COMMANDS else COMMANDS:
        importlib.import_module(f"heliquad.host.{COMMANDS[name]}").add_parser(sub, fmt)
