"""POINTS.csv, frequency-response points (docs/file-formats.md, "POINTS.csv"), and the
paper-style points table ``heliquad identify`` writes beside it (docs/file-formats.md,
"points_table.csv"). POINTS.csv: a header row, columns ``omega_rad_s,magnitude,phase_rad``
and optionally ``sigma,coherence``, ``coherence_ry,coherence_ru`` and ``lost_share``; one row
per frequency, omega strictly increasing; phase wrapped or not.

The points written are :class:`~heliquad.host.estimate.fsf.FrequencyPoint` objects (the
estimator's record, read here by its attributes); the readers return ``{column: array}``,
which the fit, the plots and the report take as they are.
"""

from __future__ import annotations

import math

import numpy as np

from ...sim.base.errors import InputError
from .output import atomic_write
from .reading import first_bad, read_table

__all__ = ["POINTS_COLUMNS", "POINTS_OPTIONAL", "POINTS_EXCITATION", "POINTS_LOSS",
           "TABLE_COLUMNS", "read_points_csv", "write_points_csv", "read_points_table",
           "write_points_table"]

POINTS_COLUMNS = ("omega_rad_s", "magnitude", "phase_rad")
POINTS_OPTIONAL = ("sigma", "coherence")
#: POINTS.csv's columns for points estimated against the excitation r (``heliquad
#: identify``): the coherence of r with the output and with the input.
POINTS_EXCITATION = ("coherence_ry", "coherence_ru")
#: POINTS.csv's column for points whose record lost samples on the link (``heliquad
#: identify``, when any did): the share lost, 0..1.
POINTS_LOSS = ("lost_share",)
#: points_table.csv's columns.
TABLE_COLUMNS = ("freq_hz", "omega_rad_s", "magnitude", "phase_deg", "real", "imag", "coherence")
#: POINTS.csv holds one row per excitation frequency; a fit of more would take minutes.
MAX_POINTS = 10_000
#: POINTS.csv: frequencies and magnitudes heliquad fits (outside them a file is in the wrong
#: units, or its numbers cannot be scaled into double precision with a model's powers of s).
OMEGA_RANGE = (1e-6, 1e9)
MAGNITUDE_RANGE = (1e-12, 1e12)
#: POINTS.csv: the highest frequency at most this many times the lowest (six decades).
MAX_OMEGA_SPAN = 1e6


def write_points_csv(path, points):
    """Write :class:`~heliquad.host.estimate.fsf.FrequencyPoint` objects, sorted by frequency; the
    columns of :data:`POINTS_EXCITATION` too when any point was estimated against the
    excitation."""
    rows = sorted(points, key=lambda p: p.omega_rad_s)
    extra = POINTS_EXCITATION if any(p.estimate == "excitation" for p in rows) else ()
    extra += POINTS_LOSS if any(p.lost_share > 0 for p in rows) else ()
    with atomic_write(path) as fh:
        fh.write(",".join(POINTS_COLUMNS + POINTS_OPTIONAL + extra) + "\n")
        for p in rows:
            fh.write(f"{p.omega_rad_s:.12g},{p.magnitude:.12g},{p.phase_rad:.12g},"
                     f"{p.sigma:.6g},{p.coherence:.6g}"
                     + "".join(f",{getattr(p, c):.6g}" for c in extra) + "\n")


def read_points_csv(path):
    """Read frequency-response points.

    Returns
    -------
    dict
        ``omega`` (rad/s), ``F`` (complex), and ``sigma``, ``coherence``, ``coherence_ry``,
        ``coherence_ru``: arrays, or None for a column the file does not have.
    """
    table = read_table(path, POINTS_COLUMNS, POINTS_OPTIONAL + POINTS_EXCITATION + POINTS_LOSS,
                       what="POINTS.csv (columns omega_rad_s,magnitude,phase_rad)")
    omega, mag = table["omega_rad_s"], table["magnitude"]
    if omega.size > MAX_POINTS:
        raise InputError(f"{path}: {omega.size} rows; a points file holds at most {MAX_POINTS} "
                         "(one per excitation frequency)")
    (wlo, whi), (mlo, mhi) = OMEGA_RANGE, MAGNITUDE_RANGE
    first_bad(path, "omega_rad_s", omega, (omega >= wlo) & (omega <= whi),
              f"in [{wlo:g}, {whi:g}] rad/s")
    bad = np.flatnonzero(np.diff(omega) <= 0)
    if bad.size:
        raise InputError(f"{path}: omega_rad_s does not increase at data row {bad[0] + 2} "
                         "(one row per frequency, in increasing order)")
    if omega[-1] > MAX_OMEGA_SPAN * omega[0]:
        raise InputError(f"{path}: omega_rad_s spans {omega[0]:g} to {omega[-1]:g} rad/s, more "
                         f"than {math.log10(MAX_OMEGA_SPAN):g} decades: one model cannot be fitted "
                         "to it (split the band)")
    first_bad(path, "magnitude", mag, mag > 0, "positive and linear (not dB)")
    first_bad(path, "magnitude", mag, (mag >= mlo) & (mag <= mhi), f"in [{mlo:g}, {mhi:g}]")
    first_bad(path, "phase_rad", table["phase_rad"], np.abs(table["phase_rad"]) <= 1e4,
              "within +/-1e4 rad")
    out = {"omega": omega, "F": mag * np.exp(1j * table["phase_rad"]),
           **{c: table.get(c) for c in POINTS_OPTIONAL + POINTS_EXCITATION + POINTS_LOSS}}
    if out["sigma"] is not None:
        s = out["sigma"]
        first_bad(path, "sigma", s, np.isfinite(s) & (s >= 0), "finite and non-negative")
    for name in ("coherence", *POINTS_EXCITATION):
        if out[name] is not None:
            c = out[name]
            first_bad(path, name, c, np.isnan(c) | ((c >= 0) & (c <= 1)),
                      "in [0, 1] (or nan: not known)")
    return out


def write_points_table(path, points) -> None:
    """points_table.csv, the paper's tables 4-6: per point (sorted by frequency) its
    frequency, omega, magnitude, phase, real and imaginary parts and coherence."""
    with atomic_write(path) as fh:
        fh.write(",".join(TABLE_COLUMNS) + "\n")
        for p in sorted(points, key=lambda q: q.omega_rad_s):
            fh.write(f"{p.freq_hz:.6g},{p.omega_rad_s:.6g},{p.magnitude:.6g},"
                     f"{math.degrees(p.phase_rad):.4f},{p.gain.real:.6g},{p.gain.imag:.6g},"
                     f"{p.coherence:.5f}\n")


def read_points_table(path):
    """Read the paper-style table ``heliquad identify`` writes (points_table.csv): columns
    ``freq_hz,omega_rad_s,magnitude,phase_deg,real,imag,coherence`` (coherence may be nan)."""
    table = read_table(path, TABLE_COLUMNS[:-1], TABLE_COLUMNS[-1:],
                       what="points table (" + ",".join(TABLE_COLUMNS) + ")")
    if "coherence" not in table:
        raise InputError(f"{path}: missing column coherence")
    c = table["coherence"]
    first_bad(path, "coherence", c, np.isnan(c) | ((c >= 0) & (c <= 1)),
              "in [0, 1] (or nan: not known)")
    return table
