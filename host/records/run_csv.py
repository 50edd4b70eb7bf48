"""RUN.csv, one sine (or multisine) experiment's record (docs/file-formats.md, "RUN.csv"):
a header row, then columns ``t_s,u,y`` (any order, other columns ignored), uniformly
sampled, time strictly increasing. ``heliquad sil`` writes it; ``heliquad fsf`` reads it.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from ...sim.base.errors import InputError
from .output import atomic_write
from .reading import first_bad, read_table

__all__ = ["RUN_COLUMNS", "Run", "read_run_csv", "write_run_csv"]

RUN_COLUMNS = ("t_s", "u", "y")
#: Largest spread of sample intervals, relative to the mean interval, still called uniform.
UNIFORM_TOLERANCE = 0.01
#: Sampling rates, Hz, and the largest magnitude of a sample.
RATE_RANGE_HZ = (1e-3, 1e7)
MAX_SAMPLE = 1e150


class Run(NamedTuple):
    """A RUN.csv as read: its sampling rate and the input and output samples."""
    fs_hz: float
    u: np.ndarray
    y: np.ndarray


def read_run_csv(path) -> Run:
    """Read a sine experiment: :class:`Run` ``(fs_hz, u, y)``."""
    table = read_table(path, RUN_COLUMNS, what="RUN.csv (columns t_s,u,y)")
    t = table["t_s"]
    if t.size < 3:
        raise InputError(f"{path}: only {t.size} samples; a run needs many periods of data")
    for c in RUN_COLUMNS:
        first_bad(path, c, table[c], np.abs(table[c]) <= MAX_SAMPLE,
                  f"within +/-{MAX_SAMPLE:g}")
    dt = np.diff(t)
    bad = np.flatnonzero(dt <= 0)
    if bad.size:
        raise InputError(f"{path}: time t_s does not increase at data row {bad[0] + 2}")
    mean_dt = (t[-1] - t[0]) / (t.size - 1)
    lo, hi = RATE_RANGE_HZ
    if not lo <= 1.0 / mean_dt <= hi:
        raise InputError(f"{path}: sampling rate {1.0 / mean_dt:.3g} Hz is outside "
                         f"[{lo:g}, {hi:g}] Hz (t_s is in seconds)")
    spread = float(np.max(np.abs(dt - mean_dt)) / mean_dt)
    if spread > UNIFORM_TOLERANCE:
        row = int(np.argmax(np.abs(dt - mean_dt))) + 2
        raise InputError(f"{path}: not uniformly sampled (interval at data row {row} differs "
                         f"from the mean {mean_dt:.6g} s by {100 * spread:.1f} %); resample first")
    return Run(1.0 / mean_dt, table["u"], table["y"])


def write_run_csv(path, rows) -> None:
    """RUN.csv: a ``t_s,u,y`` header, then one row per sample (``rows``: (t_s, u, y))."""
    with atomic_write(path) as fh:
        np.savetxt(fh, np.asarray(rows, dtype=float).reshape(-1, 3), delimiter=",",
                   header=",".join(RUN_COLUMNS), comments="", fmt="%.9g")

