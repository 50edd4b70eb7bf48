"""The ``heliquad`` subcommands, one module each.

Every command module has ``add_parser(sub, fmt)``, which adds its subparser and sets
``func`` to its ``run(args) -> exit code``. The modules here hold the commands that are a
front end to library code elsewhere in :mod:`heliquad.host`; ``demo``, ``dmp-image``,
``flash`` and ``mavlink-dialect`` live in the modules that do their work. :data:`COMMANDS` is the order
``heliquad --help`` lists them in.
"""

from __future__ import annotations

import importlib

__all__ = ["COMMANDS", "add_parsers"]

#: Module of each subcommand, relative to :mod:`heliquad.host`.
COMMANDS = ("commands.fsf", "commands.fit", "commands.sil", "commands.board",
            "commands.validate", "commands.log", "commands.tlog", "commands.sweep",
            "commands.identify", "commands.report", "commands.params", "demo", "dmp_image",
            "flash", "mavlink_dialect")


def add_parsers(sub, fmt) -> None:
    """Add every subcommand's parser to ``sub`` (argparse subparsers)."""
    for name in COMMANDS:
        importlib.import_module(f"heliquad.host.{name}").add_parser(sub, fmt)
