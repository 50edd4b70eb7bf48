"""The ``heliquad`` subcommands: one module here per command, named after it (``dmp-image``
is ``dmp_image.py``), and this registry of them.

Every command module has ``add_parser(sub, fmt)``, which adds its subparser and sets
``func`` to its ``run(args) -> exit code``; the work itself lives in the stage packages
(acquire, estimate, validate, present, campaign). :data:`COMMANDS` lists the commands in
the order ``heliquad --help`` shows them; a command's module is imported only when that
command runs (or when every command must be listed).
"""

from __future__ import annotations

import importlib

__all__ = ["COMMANDS", "add_parsers", "module_of"]

#: The subcommands, in the order ``heliquad --help`` lists them.
COMMANDS = ("fsf", "fit", "sil", "board", "validate", "tune", "verify", "log", "tlog", "sweep", "identify",
            "study", "effectiveness", "report", "params", "logs", "program", "demo", "dmp-image", "flash",
            "usb-descriptors", "mavlink-dialect", "sd-image")


def module_of(command: str) -> str:
    """The module that holds ``command``: ``heliquad.host.commands.<command>``, its dashes
    as underscores."""
    return f"{__name__}.{command.replace('-', '_')}"


def add_parsers(sub, fmt, argv=()) -> None:
    """Add the subcommands' parsers to ``sub`` (argparse subparsers): only the one the
    command line ``argv`` names, when its first word is a command, else every one (to list
    them, to say which there are, or for an option before the command: ``heliquad -h
    identify``). A command then pays for importing its own module only, not every
    command's (numpy, the vehicle, the dialect: a tenth of a second)."""
    named = argv[0] if argv else None
    for name in [named] if named in COMMANDS else COMMANDS:
        importlib.import_module(module_of(name)).add_parser(sub, fmt)
