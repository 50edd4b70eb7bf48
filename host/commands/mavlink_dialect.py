"""``heliquad mavlink-dialect``: the project's MAVLink dialect for outside tools.

heliquad's messages (HQ_SYSID_SAMPLE, HQ_EXCITATION, ...) are defined in
``firmware/mavlink/heliquad.xml`` (installed with the package as
``heliquad/mavlink/heliquad.xml``), which includes MAVLink's common.xml. pymavlink's tools
(MAVProxy, mavlogdump.py, mavgraph.py) decode them once they have a module generated from
it, ``pymavlink/dialects/v20/heliquad.py``, and are told ``--dialect heliquad``. This
command makes that module with a Python's own pymavlink (its mavgen, MAVLink 2), and its
MAVLink 1 twin ``dialects/v10/heliquad.py`` (which pymavlink loads first wherever the
environment does not say ``MAVLINK20``, then leaves for the v20 module at the first
MAVLink 2 frame), and writes them with the XML they came from into a folder, or installs
them into that pymavlink.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import tempfile

from ...sim.base.dialect import dialect
from ...sim.base.errors import InputError

__all__ = ["dialect_xml", "generate", "add_parser"]

NAME = "heliquad"
#: The MAVLink 1 module, in the folder and in pymavlink's dialects (``mavgen_script.py``).
V10_MODULE = os.path.join("v10", f"{NAME}.py")
#: The files a folder gets: the dialect, what it includes, and the generated modules.
FOLDER_FILES = (f"{NAME}.xml", "common.xml", "standard.xml", "minimal.xml", f"{NAME}.py",
                V10_MODULE)
#: What an install puts into pymavlink's dialects folder (common.xml and the rest are there):
#: each file made, and where it goes under ``dialects``.
INSTALLED_FILES = ((f"{NAME}.py", os.path.join("v20", f"{NAME}.py")),
                   (f"{NAME}.xml", os.path.join("v20", f"{NAME}.xml")),
                   (V10_MODULE, V10_MODULE))
SCRIPT = os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), "cli",
                      "mavgen_script.py")
#: Runs SCRIPT without putting its folder (or the working folder) on the other Python's path.
RUNNER = ("import runpy, sys\n"
          "if sys.path and sys.path[0] == '': del sys.path[0]\n"
          "sys.argv = sys.argv[1:]\n"
          "runpy.run_path(sys.argv[0], run_name='__main__')\n")
GENERATE_TIMEOUT_S = 600

HELP = """\
Make heliquad's MAVLink dialect available to outside tools. heliquad's messages
(HQ_SYSID_SAMPLE, HQ_EXCITATION_STATUS, ...) are defined in heliquad.xml (installed with
heliquad), which includes MAVLink's common.xml. pymavlink's tools (MAVProxy, mavlogdump.py,
mavgraph.py) decode them with a module generated from it,
pymavlink/dialects/v20/heliquad.py, when told --dialect heliquad. This command generates
that module with a Python's own pymavlink (mavgen, MAVLink 2), and its MAVLink 1 twin
v10/heliquad.py: pymavlink loads dialects/v10 first wherever MAVLINK20 is not in the
environment (mavgraph.py; MAVLINK_DIALECT=heliquad alone), and moves to the v20 module at
the first MAVLink 2 frame. heliquad's own messages exist in the v20 module only (their ids
need MAVLink 2).

Without --install it writes DIR (default ./heliquad-mavlink): heliquad.xml, the common.xml,
standard.xml and minimal.xml it includes (from that pymavlink), heliquad.py and
v10/heliquad.py. A file there that already holds something else is never replaced (the
command stops first). --install puts heliquad.py and heliquad.xml into that pymavlink's
dialects/v20 folder and v10/heliquad.py into dialects/v10; then:

  mavproxy.py --master udpin:0.0.0.0:14550 --dialect heliquad
  mavlogdump.py --dialect heliquad --types HQ_SYSID_SAMPLE sweep.tlog
  mavgraph.py --dialect heliquad sweep.tlog HQ_SYSID_SAMPLE.rate

--python names another Python, for a MAVProxy in its own virtualenv or pipx: its pymavlink
generates the module and gets it. Run again after upgrading heliquad or that pymavlink.
More in docs/ground-stations.md.

examples: heliquad mavlink-dialect --install
          heliquad mavlink-dialect --install --python ~/mavproxy-venv/bin/python
          heliquad mavlink-dialect --out heliquad-mavlink
"""


def dialect_xml() -> str:
    """The installed heliquad.xml (beside the generated module), or a source checkout's."""
    for path in (os.path.join(os.path.dirname(dialect().__file__), "mavlink", f"{NAME}.xml"),
                 os.path.join(os.path.dirname(SCRIPT), os.pardir, "firmware", "mavlink",
                              f"{NAME}.xml")):
        if os.path.isfile(path):
            return os.path.normpath(path)
    raise InputError(f"{NAME}.xml is not installed with heliquad: reinstall it (pip install .)")


def generate(python: str, out: str) -> dict:
    """Generate the dialect with ``python``'s pymavlink into the folder ``out`` (the files of
    FOLDER_FILES); that pymavlink's ``{"pymavlink": folder, "version": ...}``."""
    try:
        run = subprocess.run([python, "-c", RUNNER, SCRIPT, dialect_xml(), out],
                             capture_output=True, text=True, timeout=GENERATE_TIMEOUT_S)
    except OSError as exc:
        raise InputError(f"--python {python}: cannot run it: {exc.strerror or exc}") from None
    except subprocess.TimeoutExpired:
        raise InputError(f"mavgen with {python} took over {GENERATE_TIMEOUT_S} s") from None
    if run.returncode != 0:
        if "No module named 'pymavlink'" in run.stderr:
            raise InputError(f"--python {python}: it has no pymavlink (install MAVProxy or "
                             "pymavlink into it)")
        last = (run.stderr.strip().splitlines() or ["no message"])[-1]
        raise InputError(f"mavgen with {python} failed: {last}")
    try:
        return json.loads(run.stdout.strip().splitlines()[-1])
    except (ValueError, IndexError):
        raise InputError(f"mavgen with {python} said nothing readable: {run.stdout!r}") from None


def _copy(pairs, source: str, target: str, replace: bool) -> None:
    """Copy each ``(name, to)`` of ``pairs``, ``source/name`` to ``target/to`` (each written
    whole, its folder made); unless ``replace``, a file there that holds something else
    stops it before anything is written."""
    # the command's work, imported when it runs: --help imports every command module
    from ..records.output import atomic_write

    data = {}
    for name, to in pairs:
        with open(os.path.join(source, name), "rb") as fh:
            data[to] = fh.read()
        there = os.path.join(target, to)
        if not replace and os.path.exists(there) and _read(there) != data[to]:
            raise InputError(f"{there} exists and holds something else; heliquad never "
                             "writes over it: remove it or give another --out")
    for to, content in data.items():
        os.makedirs(os.path.dirname(os.path.join(target, to)), exist_ok=True)
        with atomic_write(os.path.join(target, to), "wb") as fh:
            fh.write(content)


def _read(path: str) -> bytes | None:
    try:
        with open(path, "rb") as fh:
            return fh.read()
    except OSError:
        return None


def add_parser(sub, fmt) -> None:
    p = sub.add_parser("mavlink-dialect", help="write or install heliquad's MAVLink dialect "
                       "for MAVProxy, mavlogdump and other pymavlink tools",
                       description=HELP, formatter_class=fmt)
    p.add_argument("--out", metavar="DIR", help="the folder for the XML files and heliquad.py "
                   "(default ./heliquad-mavlink; with --install, none unless given)")
    p.add_argument("--install", action="store_true",
                   help="install heliquad.py (and .xml) into pymavlink's dialects/v20, and the "
                        "MAVLink 1 module into dialects/v10, so its tools take --dialect "
                        "heliquad")
    p.add_argument("--python", metavar="PYTHON", default=sys.executable,
                   help="the Python whose pymavlink generates (and with --install gets) the "
                        "module, e.g. MAVProxy's virtualenv's bin/python (default: this one)")
    p.set_defaults(func=_cmd)


def _cmd(args) -> int:
    out = args.out or (None if args.install else f"{NAME}-mavlink")
    if out is not None and os.path.exists(out) and not os.path.isdir(out):
        raise InputError(f"--out {out} exists and is not a folder")
    with tempfile.TemporaryDirectory() as work:
        found = generate(args.python, work)
        where = f"pymavlink {found['version']} at {found['pymavlink']}"
        if out is not None:
            os.makedirs(out, exist_ok=True)
            _copy([(name, name) for name in FOLDER_FILES], work, out, replace=False)
            print(f"wrote {', '.join(FOLDER_FILES)} to {out} (generated with {where})")
        if args.install:
            dialects = os.path.join(found["pymavlink"], "dialects")
            try:
                _copy(INSTALLED_FILES, work, dialects, replace=True)
            except InputError as exc:
                raise InputError(f"{exc}: install into a Python you may write to (a "
                                 "virtualenv, --python), or copy heliquad.py there yourself") from None
            print(f"installed {NAME}.py into {os.path.join(dialects, 'v20')} and "
                  f"{os.path.join(dialects, 'v10')} ({where}); its tools now take "
                  f"--dialect {NAME}: mavproxy.py --dialect {NAME}, mavlogdump.py --dialect "
                  f"{NAME}, mavgraph.py --dialect {NAME}")
    return 0
