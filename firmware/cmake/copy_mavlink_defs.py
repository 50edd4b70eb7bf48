"""Copy pymavlink's common.xml and what it includes into a folder (the build's dialect step).

Run at build time with the build's Python, so the files come from the pymavlink that Python
imports now: a build folder configured once keeps working when that pymavlink moves (pip's
isolated build environments live in a new temporary folder each time).

    python copy_mavlink_defs.py OUT_DIR
"""

import os
import shutil
import sys

import pymavlink

defs = os.path.join(os.path.dirname(pymavlink.__file__), "dialects", "v20")
for name in ("common.xml", "standard.xml", "minimal.xml"):
    shutil.copy(os.path.join(defs, name), sys.argv[1])
