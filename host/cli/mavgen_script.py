"""Generate a MAVLink dialect's pymavlink module with a given Python's own pymavlink (a
script: ``heliquad mavlink-dialect`` runs it with the Python whose pymavlink makes the
module, which may be another virtualenv's, so it imports nothing of heliquad's).

    python mavgen_script.py DIALECT.xml OUT_DIR

Copies DIALECT.xml and the message definitions it includes (pymavlink's common.xml,
standard.xml, minimal.xml) into OUT_DIR, generates OUT_DIR/DIALECT.py (Python 3, MAVLink 2)
and OUT_DIR/v10/DIALECT.py (the same definitions for MAVLink 1, which leaves out every
message whose id needs MAVLink 2), with mavgen's library interface (the same in every
pymavlink since 2.4), and prints one JSON line: that pymavlink's folder and version.
mavgen's chatter goes to stderr only if it fails.

Why a MAVLink 1 module: pymavlink's ``mavutil`` loads ``dialects/v10/NAME`` unless the
environment holds ``MAVLINK20`` (mavgraph.py, and any script run with ``MAVLINK_DIALECT``
alone), and fails on import where there is none; once it reads a MAVLink 2 frame it loads
``dialects/v20/NAME`` by itself.
"""

import contextlib
import io
import json
import os
import shutil
import sys
from importlib.metadata import version

import pymavlink
from pymavlink.generator import mavgen

INCLUDED = ("common.xml", "standard.xml", "minimal.xml")
#: Each module made: (its path in OUT_DIR, mavgen's wire protocol).
MODULES = (("{name}.py", "2.0"), (os.path.join("v10", "{name}.py"), "1.0"))


def main(xml: str, out: str) -> int:
    here = os.path.dirname(os.path.abspath(pymavlink.__file__))
    for name in INCLUDED:
        shutil.copy(os.path.join(here, "dialects", "v20", name), out)
    shutil.copy(xml, out)
    name = os.path.splitext(os.path.basename(xml))[0]
    os.makedirs(os.path.join(out, "v10"), exist_ok=True)
    for module, wire_protocol in MODULES:
        chatter = io.StringIO()
        with contextlib.redirect_stdout(chatter):
            opts = mavgen.Opts(os.path.join(out, module.format(name=name)),
                               wire_protocol=wire_protocol, language="Python3")
            ok = mavgen.mavgen(opts, [os.path.join(out, os.path.basename(xml))])
        if not ok:
            sys.stderr.write(chatter.getvalue())
            return 1
    try:
        found = version("pymavlink")
    except Exception:                  # an unpackaged checkout: its folder says enough
        found = "unknown"
    print(json.dumps({"pymavlink": here, "version": found}))
    return 0


if __name__ == "__main__":
    sys.exit(main(*sys.argv[1:3]))
