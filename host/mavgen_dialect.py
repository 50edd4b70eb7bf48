"""Generate a MAVLink dialect's pymavlink module with a given Python's own pymavlink (a
script: ``heliquad mavlink-dialect`` runs it with the Python whose pymavlink makes the
module, which may be another virtualenv's, so it imports nothing of heliquad's).

    python mavgen_dialect.py DIALECT.xml OUT_DIR

Copies DIALECT.xml and the message definitions it includes (pymavlink's common.xml,
standard.xml, minimal.xml) into OUT_DIR, generates OUT_DIR/DIALECT.py (Python 3, MAVLink 2,
mavgen's library interface: the same in every pymavlink since 2.4) and prints one JSON line:
that pymavlink's folder and version. mavgen's chatter goes to stderr only if it fails.
"""

import contextlib
import io
import json
import os
import shutil
import sys

INCLUDED = ("common.xml", "standard.xml", "minimal.xml")


def main(xml: str, out: str) -> int:
    import pymavlink
    from pymavlink.generator import mavgen

    here = os.path.dirname(os.path.abspath(pymavlink.__file__))
    for name in INCLUDED:
        shutil.copy(os.path.join(here, "dialects", "v20", name), out)
    shutil.copy(xml, out)
    name = os.path.splitext(os.path.basename(xml))[0]
    chatter = io.StringIO()
    with contextlib.redirect_stdout(chatter):
        opts = mavgen.Opts(os.path.join(out, name + ".py"), wire_protocol="2.0",
                           language="Python3")
        ok = mavgen.mavgen(opts, [os.path.join(out, os.path.basename(xml))])
    if not ok:
        sys.stderr.write(chatter.getvalue())
        return 1
    try:
        from importlib.metadata import version
        found = version("pymavlink")
    except Exception:                  # an unpackaged checkout: its folder says enough
        found = "unknown"
    print(json.dumps({"pymavlink": here, "version": found}))
    return 0


if __name__ == "__main__":
    sys.exit(main(*sys.argv[1:3]))
