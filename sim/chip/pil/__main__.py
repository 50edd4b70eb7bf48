"""``python -m heliquad.sim.chip.pil``: the drop-in's program (:mod:`.program`)."""

import sys

from .program import main

sys.exit(main())
