"""Generate the heliquad MAVLink dialect with pymavlink's generator.

    python mavgen.py LANGUAGE OUTPUT DIALECT.xml        (LANGUAGE: C or Python3)

The generator's library interface (pymavlink.generator.mavgen: Opts, mavgen) is the same in
every pymavlink the project supports; the command-line module pymavlink.tools.mavgen exists
only from pymavlink 2.4.50 on.
"""

import sys

from pymavlink.generator import mavgen

language, output, xml = sys.argv[1:4]
opts = mavgen.Opts(output, wire_protocol="2.0", language=language)
sys.exit(0 if mavgen.mavgen(opts, [xml]) else 1)
