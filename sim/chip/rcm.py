"""The reset control module (RCM), as far as the firmware reads it: the system reset status
registers SRS0 and SRS1 (read only), one flag per source of the last reset, which the
firmware's boot report names (firmware/targets/teensy35/reset_cause_flags.hpp).

Every reset of the emulated chip is a power-on reset (:meth:`Machine.reset`), so the two hold
a power-on reset's flags, the SVD's reset values: SRS0 = POR | LVD (0x82), SRS1 = 0. The pin
filter and mode registers (RPFC, RPFW, MR) store what is written and do nothing else.
"""

from __future__ import annotations

from .peripheral import RegisterDevice


class Rcm(RegisterDevice):
    READ_ONLY = ("SRS0", "SRS1")

    def __init__(self, machine):
        super().__init__(machine, "RCM")
