"""Published facts of the vehicle this project started from (docs/paper.md restates them).

Source: A. A. Hoshu, L. Wang, S. Ansari, A. Sattar, M. H. A. Bilal, "System Identification of
Heterogeneous Multirotor Unmanned Aerial Vehicle", Drones 2022, 6(10), 309,
doi 10.3390/drones6100309. Table 1 (frequency bands), the identified models, and the
auto-tuned cascade gains.
"""

from __future__ import annotations

__all__ = ["BANDS_HZ", "MODELS", "CHOSEN_ORDER", "DEFAULT_ORDERS", "RATE_GAINS", "ANGLE_GAINS"]

#: Table 1: lowest and highest excitation frequency per axis, Hz.
BANDS_HZ = {"roll": (0.5, 4.5), "pitch": (0.5, 4.8), "yaw": (0.15, 1.6)}

#: Identified models, rate in -> rate out: {axis: {(m, n): (num, den)}}, descending powers.
MODELS = {
    "roll": {
        (0, 2): ([28.19], [1, 5.13, 22.93]),
        (0, 3): ([914.3], [1, 28.75, 241.5, 636.2]),
        (2, 4): ([17.95, 609.3, 4396], [1, 18.77, 368.7, 1045, 5230]),
    },
    "pitch": {
        (0, 2): ([33.64], [1, 5.374, 23.65]),
        (0, 3): ([1298], [1, 33.3, 313.2, 780.8]),
        (2, 4): ([17.88, 788.6, 5101], [1, 20.15, 413.1, 1174, 5274]),
    },
    "yaw": {
        (0, 1): ([1.191], [1, 1.178]),
        (2, 2): ([0.008, 0.736, 0.0471], [1, 1.068, 0.210]),
        (2, 3): ([0.810, 0.669, 18.48], [1, 2.555, 23.54, 30.59]),
    },
}

#: The order the paper chose per axis.
CHOSEN_ORDER = {"roll": (0, 2), "pitch": (0, 2), "yaw": (0, 1)}

#: The orders the paper fitted per axis (the default order list of an identification).
DEFAULT_ORDERS = {axis: tuple(models) for axis, models in MODELS.items()}

#: Inner (rate) loop, ideal PID form Kc (1 + 1/(tau_I s) + tau_D s): (Kc, tau_I_s, tau_D_s).
RATE_GAINS = {"roll": (2.422, 0.439, 0.051), "pitch": (2.386, 0.439, 0.048),
              "yaw": (7.393, 0.397, 0.043)}

#: Outer (angle) loop, PD: (Kc, tau_D_s).
ANGLE_GAINS = {"roll": (1.488, 0.107), "pitch": (1.501, 0.106)}
