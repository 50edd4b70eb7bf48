"""POINTS.csv, frequency-response points (docs/file-formats.md, "POINTS.csv"), and the
paper-style points table ``heliquad identify`` writes beside it (docs/file-formats.md,
"points_table.csv"). POINTS.csv: a header row, columns ``omega_rad_s,magnitude,phase_rad``
and optionally ``sigma,coherence``, ``coherence_ry,coherence_ru`` and ``lost_share``; one row
per frequency, omega strictly increasing; phase wrapped or not.

A frequency point is one type from end to end, :class:`FrequencyPoint`: the estimator
(host/estimate/fsf.py) returns it, :func:`write_points_csv` stores it, :func:`read_points_csv`
gives it back, the fit (host/estimate/models.py), the Bode plot and the report take it.
:func:`known_column` turns a list of them into the array of one attribute where a computation
wants arrays. points_table.csv, a table of printed numbers for people, reads as a
:class:`PointsTable`.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from ...sim.base.errors import InputError
from .output import atomic_write
from .reading import first_bad, read_table

__all__ = ["FrequencyPoint", "PointsTable", "frequency_points", "known_column", "POINTS_COLUMNS", "POINTS_OPTIONAL", "POINTS_EXCITATION", "POINTS_LOSS",
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


@dataclasses.dataclass(frozen=True)
class FrequencyPoint:
    """One frequency-response point: what one sine experiment (or one line of a multisine)
    measured of ``G(j omega)``, with its uncertainty and coherence.

    The estimator (host/estimate/fsf.py) fills every attribute. A point read from points.csv
    has what the file stores (frequency, gain, sigma, the coherences, the lost share; NaN
    where the file has no such column, ``estimate`` "excitation" when it has the excitation's
    coherences); the estimator's diagnostics (``period_samples`` to ``offset``,
    ``input_gain``, ``input_sigma``, ``order``) are not stored and keep their defaults.

    Attributes
    ----------
    omega_rad_s : float
        Excitation frequency actually analysed, rad/s.
    gain : complex
        ``G(j omega)``, the fundamental's output/input ratio.
    sigma : float
        Standard deviation of the complex ``gain`` from the residuals, ``sqrt(E|dG|^2)``.
    coherence : float
        Magnitude-squared coherence between input and output at ``omega``, one segment per
        whole period after the discarded ones (NaN with fewer than two periods).
    period_samples : float
        Samples per excitation period (an integer for the ``"fsf"`` method).
    n_periods : int
        Whole periods of regression rows (after the discarded periods and, for the FSF, the
        period that fills the filter).
    method : str
        ``"fsf"`` (integer period) or ``"sinefit"`` (non-integer period); ``""`` when not
        known (a point read from a file).
    harmonics : dict
        ``{l: G_l}`` for ``l = 1..L``; NaN where the input does not excite ``l``.
    offset : float
        Estimated output offset ``c`` (0 when ``offset=False``).
    estimate : str
        ``"input"``: ``y`` regressed on the measured input ``u`` (the direct estimate, right
        for open-loop data); ``"excitation"``: ``G = (Y/R) / (U/R)``, both against the
        injected excitation ``r`` (:func:`estimate_against_excitation`, for closed-loop data).
    coherence_ry, coherence_ru : float
        With ``estimate="excitation"``: the coherence of ``r`` with ``y`` and with ``u``
        (``coherence`` is the smaller); NaN otherwise.
    input_gain : complex
        With ``estimate="excitation"``: ``U/R``, how the input followed the excitation (in a
        loop broken where ``r`` is injected, ``L = R/U - 1``); NaN otherwise.
    input_sigma : float
        Standard deviation of ``input_gain`` (NaN without it).
    order : int
        The harmonic of the record's (base) period this point is at: 1 for a sine; a
        multisine's line (:func:`estimate_multisine`), whose ``period_samples`` is the base
        period.
    lost_share : float
        The share of the record's samples lost on the link (0 when every one arrived;
        ``heliquad identify`` sets it from the sweep's count).
    """

    omega_rad_s: float
    gain: complex
    sigma: float = math.nan
    coherence: float = math.nan
    period_samples: float = math.nan
    n_periods: int = 0
    method: str = ""
    harmonics: dict = dataclasses.field(default_factory=dict)
    offset: float = 0.0
    estimate: str = "input"
    coherence_ry: float = math.nan
    coherence_ru: float = math.nan
    input_gain: complex = complex("nan+nanj")
    input_sigma: float = math.nan
    order: int = 1
    lost_share: float = 0.0

    @property
    def magnitude(self) -> float:
        """Linear magnitude ``|G|``."""
        return float(abs(self.gain))

    @property
    def phase_rad(self) -> float:
        """Phase of ``G`` in radians, wrapped to (-pi, pi]."""
        return float(np.angle(self.gain))

    @property
    def freq_hz(self) -> float:
        """Excitation frequency in Hz."""
        return self.omega_rad_s / (2.0 * math.pi)


@dataclasses.dataclass(frozen=True)
class PointsTable:
    """points_table.csv as read: one array per column (frequency, omega, magnitude, phase in
    degrees, real and imaginary parts, coherence: NaN where not known), each holding the
    numbers as printed in the file."""

    freq_hz: np.ndarray
    omega_rad_s: np.ndarray
    magnitude: np.ndarray
    phase_deg: np.ndarray
    real: np.ndarray
    imag: np.ndarray
    coherence: np.ndarray

    def column(self, name: str) -> np.ndarray:
        """The column ``name`` of :data:`TABLE_COLUMNS`."""
        return getattr(self, name)


def frequency_points(omega_rad_s, gain, **columns) -> list[FrequencyPoint]:
    """:class:`FrequencyPoint` objects from arrays: ``omega_rad_s``, the complex ``gain``, and
    any other attribute by name (``sigma=``, ``coherence=``, ...: an array beside them, or
    None for not known), for points measured by other means than heliquad's estimator."""
    given = {name: np.asarray(values) for name, values in columns.items() if values is not None}
    return [FrequencyPoint(omega_rad_s=float(w), gain=complex(g),
                           **{name: values[i].item() for name, values in given.items()})
            for i, (w, g) in enumerate(zip(np.asarray(omega_rad_s, float),
                                           np.asarray(gain, complex)))]


def known_column(points, name: str):
    """The attribute ``name`` of every point in ``points`` (a sequence of
    :class:`FrequencyPoint`) as an array (complex for ``gain``), or None when no point knows
    it (every value NaN: a file without that column)."""
    values = np.array([getattr(p, name) for p in points])
    if values.dtype.kind in "fc" and not np.any(np.isfinite(values)):
        return None
    return values


def write_points_csv(path, points):
    """Write :class:`FrequencyPoint` objects, sorted by frequency; the
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


def read_points_csv(path) -> list[FrequencyPoint]:
    """Read frequency-response points: a list of :class:`FrequencyPoint`, in increasing
    frequency, each with NaN for a column the file does not have (``lost_share``: 0)."""
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
    if "sigma" in table:
        s = table["sigma"]
        first_bad(path, "sigma", s, np.isfinite(s) & (s >= 0), "finite and non-negative")
    for name in ("coherence", *POINTS_EXCITATION):
        if name in table:
            c = table[name]
            first_bad(path, name, c, np.isnan(c) | ((c >= 0) & (c <= 1)),
                      "in [0, 1] (or nan: not known)")
    gains = mag * np.exp(1j * table["phase_rad"])
    stored = {c: table[c] for c in POINTS_OPTIONAL + POINTS_EXCITATION + POINTS_LOSS
              if c in table}
    estimate = "excitation" if any(c in table for c in POINTS_EXCITATION) else "input"
    return [FrequencyPoint(omega_rad_s=float(w), gain=complex(g), estimate=estimate,
                           **{c: float(v[i]) for c, v in stored.items()})
            for i, (w, g) in enumerate(zip(omega, gains))]


def write_points_table(path, points) -> None:
    """points_table.csv, the paper's tables 4-6: per point (sorted by frequency) its
    frequency, omega, magnitude, phase, real and imaginary parts and coherence."""
    with atomic_write(path) as fh:
        fh.write(",".join(TABLE_COLUMNS) + "\n")
        for p in sorted(points, key=lambda q: q.omega_rad_s):
            fh.write(f"{p.freq_hz:.6g},{p.omega_rad_s:.6g},{p.magnitude:.6g},"
                     f"{math.degrees(p.phase_rad):.4f},{p.gain.real:.6g},{p.gain.imag:.6g},"
                     f"{p.coherence:.5f}\n")


def read_points_table(path) -> PointsTable:
    """Read the paper-style table ``heliquad identify`` writes (points_table.csv): columns
    ``freq_hz,omega_rad_s,magnitude,phase_deg,real,imag,coherence`` (coherence may be nan)."""
    table = read_table(path, TABLE_COLUMNS[:-1], TABLE_COLUMNS[-1:],
                       what="points table (" + ",".join(TABLE_COLUMNS) + ")")
    if "coherence" not in table:
        raise InputError(f"{path}: missing column coherence")
    c = table["coherence"]
    first_bad(path, "coherence", c, np.isnan(c) | ((c >= 0) & (c <= 1)),
              "in [0, 1] (or nan: not known)")
    return PointsTable(**{name: table[name] for name in TABLE_COLUMNS})
