"""A copy of the installed pymavlink in a folder of its own (not a test module: a helper the
tests import), so ``heliquad mavlink-dialect --install`` and the tools that load a dialect by
name (mavlogdump.py, MAVProxy) run against it and never touch the real site-packages."""

from __future__ import annotations

import os
import pathlib
import shutil

import pymavlink

#: The definitions a copy keeps (every other generated dialect is 80 MB nobody here needs).
KEPT_DIALECTS = {"__init__", "common", "standard", "minimal"}


def private_pymavlink(folder: pathlib.Path) -> tuple[pathlib.Path, dict]:
    """Copies pymavlink into ``folder``/pymavlink; returns that package's folder and the
    environment that makes Python import it instead of the real one."""
    def ignore(where, names):
        skip = {n for n in names if n == "__pycache__"}
        if os.path.basename(os.path.dirname(where)) == "dialects":     # dialects/v10, v20
            skip |= {n for n in names if os.path.splitext(n)[0] not in KEPT_DIALECTS}
        return skip

    shutil.copytree(os.path.dirname(pymavlink.__file__), folder / "pymavlink", ignore=ignore)
    env = dict(os.environ, PYTHONPATH=str(folder), MAVLINK_DIALECT="common")
    return folder / "pymavlink", env
