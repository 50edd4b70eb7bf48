"""The file formats of the host tool (docs/file-formats.md is the reference).

* RUN.csv: header row, columns ``t_s,u,y`` (in any order, extra columns ignored), uniformly
  sampled, time strictly increasing.
* POINTS.csv: header row, columns ``omega_rad_s,magnitude,phase_rad`` and optionally
  ``sigma,coherence`` and ``coherence_ry,coherence_ru``; one row per frequency, omega strictly
  increasing; phase wrapped or not.
* MODELS.json: ``{"models": [...], "recommended": INDEX, ...}``, coefficients in descending
  powers of s, den monic.
* A sweep folder's manifest.json, a gains file, validation.json and points_table.csv.
* A .params file (a board's parameters): MAVProxy's ``NAME VALUE`` lines or
  QGroundControl's ``SYSID COMPID NAME VALUE TYPE``; written as QGroundControl's.

There is one reader per format; every command and the library read through it. Each JSON
reader checks its document against a schema (:mod:`.schema`). Readers raise
:class:`InputError` with a one-line message naming the file and the key or row at fault.
"""

from __future__ import annotations

import contextlib
import csv
import functools
import io
import json
import math
import os
import tempfile
import warnings

import numpy as np

from ...sim.base import dialect as names
from ...sim.base.userfiles import read_text
from . import schema as S
from ...sim.base.errors import DiskFull, InputError, no_room

__all__ = ["RUN_COLUMNS", "POINTS_COLUMNS", "POINTS_EXCITATION", "read_text", "read_run_csv", "read_points_csv",
           "read_points_table", "read_json", "read_manifest", "read_models_json", "read_gains",
           "read_validation", "check_output", "check_output_folder", "write_run_csv",
           "write_points_csv", "write_models_json", "write_models_mat", "model_to_dict",
           "atomic_write", "write_json", "save_figure", "figure_format", "check_figure_output", "new_output_folder", "read_params_file",
           "write_params_file"]

RUN_COLUMNS = ("t_s", "u", "y")
TABLE_COLUMNS = ("freq_hz", "omega_rad_s", "magnitude", "phase_deg", "real", "imag", "coherence")
POINTS_COLUMNS = ("omega_rad_s", "magnitude", "phase_rad")
POINTS_OPTIONAL = ("sigma", "coherence")
#: POINTS.csv's columns for points estimated against the excitation r (``heliquad
#: identify``): the coherence of r with the output and with the input.
POINTS_EXCITATION = ("coherence_ry", "coherence_ru")
#: POINTS.csv's column for points whose record lost samples on the link (``heliquad
#: identify``, when any did): the share lost, 0..1.
POINTS_LOSS = ("lost_share",)
#: Largest spread of sample intervals, relative to the mean interval, still called uniform.
UNIFORM_TOLERANCE = 0.01


def _temporary_beside(path):
    """(fd, name) of a new temporary file in ``path``'s folder; InputError if there is none."""
    folder = os.path.dirname(os.path.abspath(path))
    try:
        return tempfile.mkstemp(prefix=f".{os.path.basename(path)}.", suffix=".tmp", dir=folder)
    except OSError as exc:
        raise _write_error(path, exc) from None


def check_output(path, option: str) -> None:
    """Refuse, before any work is done, an output file that could not be written: a folder,
    or a name whose folder is missing, is a file, or takes no new file (tried with a
    temporary file, removed again)."""
    path = os.fspath(path)
    if os.path.isdir(path):
        raise InputError(f"{option} {path}: is a folder; give a file name")
    fd, tmp = _temporary_beside(path)
    os.close(fd)
    os.unlink(tmp)


def check_output_folder(path, option: str) -> None:
    """As :func:`check_output`, for an output folder that may not exist yet: it, or the
    nearest folder above it that exists, must be a folder that takes new files."""
    given = os.fspath(path)
    where = os.path.abspath(given)
    while not os.path.lexists(where):
        where = os.path.dirname(where)
    if not os.path.isdir(where):
        raise InputError(f"{option} {given}: {where} is a file, not a folder")
    try:
        check_output(os.path.join(where, ".heliquad-probe"), option)
    except InputError:
        raise InputError(f"{option} {given}: cannot write into {where}") from None


@contextlib.contextmanager
def atomic_write(path, mode: str = "w"):
    """A file object for ``path`` that replaces it only once everything is written: the
    data goes to a temporary file beside it, is flushed to the disk, and is renamed over
    ``path`` at the end. A failure (a full disk, an exception while writing) leaves the old
    file as it was and no temporary file behind; a write that finds no room raises
    :class:`DiskFull` naming ``path``, any other OSError an InputError."""
    path = os.fspath(path)
    fd, tmp = _temporary_beside(path)
    try:
        with os.fdopen(fd, mode, **({} if "b" in mode else {"newline": ""})) as fh:
            yield fh
            fh.flush()
            os.fsync(fh.fileno())
        os.chmod(tmp, 0o644)
        os.replace(tmp, path)
    except BaseException as exc:
        with contextlib.suppress(OSError):
            os.unlink(tmp)
        if isinstance(exc, OSError):
            raise _write_error(path, exc) from None
        raise


def _write_error(path, exc: OSError) -> Exception:
    """What a failed write of ``path`` is reported as: no room is :class:`DiskFull`, anything
    else an InputError naming the file."""
    if no_room(exc):
        return DiskFull.from_os_error(path, exc)
    return InputError(f"cannot write {path}: {exc.strerror or exc}")


def write_json(path, doc) -> None:
    """``doc`` as indented JSON, atomically (:func:`atomic_write`); numbers that are not
    finite are written as null (JSON has none, and the readers refuse Python's NaN)."""
    with atomic_write(path) as fh:
        json.dump(_finite_or_null(doc), fh, indent=2)
        fh.write("\n")


def _finite_or_null(doc):
    if isinstance(doc, float):
        return doc if math.isfinite(doc) else None
    if isinstance(doc, dict):
        return {k: _finite_or_null(v) for k, v in doc.items()}
    if isinstance(doc, (list, tuple)):
        return [_finite_or_null(v) for v in doc]
    return doc


#: zlib's level for the PNGs heliquad writes: 1 writes a figure's picture in about a quarter
#: of the default's (6) time, in a file about a fifth larger.
PNG_COMPRESS_LEVEL = 1


#: How heliquad's figures draw their text: without FreeType's hinting (matplotlib's default
#: hints every glyph, most of what a figure's tick labels cost: identify's responses figure
#: drew its 300 labels in 0.22 s instead of 0.30 s), the glyphs a shade softer.
FIGURE_RC = {"text.hinting": "none"}


#: Figure formats matplotlib writes only with a program outside Python: the rcParams entry
#: that names the program. pgf sets its text with TeX (xelatex by default), and without it
#: matplotlib fails after the figure is drawn.
FIGURE_FORMAT_PROGRAMS = {"pgf": "pgf.texsystem"}


def figure_format(path) -> str:
    """The format a figure is written in: its file name's extension (any case), PNG when it
    has none."""
    return os.path.splitext(os.fspath(path))[1].lstrip(".").lower() or "png"


def check_figure_output(path, option: str) -> None:
    """:func:`check_output` for a figure, and refuse, before any work is done, a file name
    whose extension is no format matplotlib can write here (or whose format needs a program
    that is not installed): the error would otherwise come once the work was done."""
    import shutil

    import matplotlib
    from matplotlib.backend_bases import FigureCanvasBase

    fmt, given = figure_format(path), os.fspath(path)
    formats = FigureCanvasBase.get_supported_filetypes()
    if fmt not in formats:
        raise InputError(f"{option} {given}: .{_short(fmt, 20)} is not an image format "
                         f"heliquad can write; end the name with one of "
                         f"{', '.join('.' + f for f in sorted(formats))}")
    program = matplotlib.rcParams[FIGURE_FORMAT_PROGRAMS[fmt]] if fmt in FIGURE_FORMAT_PROGRAMS \
        else None
    if program and shutil.which(program) is None:
        raise InputError(f"{option} {given}: .{fmt} figures need {program}, which is not "
                         "installed; write .pdf or .svg instead")
    check_output(path, option)


def save_figure(fig, path, **kwargs) -> None:
    """A matplotlib figure to ``path`` (format :func:`figure_format`), atomically."""
    import matplotlib

    fmt = figure_format(path)
    if fmt == "png":
        kwargs.setdefault("pil_kwargs", {"compress_level": PNG_COMPRESS_LEVEL})
    with atomic_write(path, "wb") as fh, matplotlib.rc_context(FIGURE_RC):
        fig.savefig(fh, format=fmt, **kwargs)


def new_output_folder(path, what: str) -> bool:
    """Make ``path`` the folder ``what`` records into: it may be new or empty, never one that
    holds earlier records (an InputError says so before anything starts). True when this
    call created it (so that a run that records nothing can remove it again)."""
    path = os.fspath(path)
    if os.path.isdir(path) and os.listdir(path):
        raise InputError(f"{path} is not empty: {what} goes into a new (or empty) folder, so no "
                         "earlier record is overwritten or mixed with it; give another --out")
    if os.path.lexists(path) and not os.path.isdir(path):
        raise InputError(f"{path} exists and is not a folder: give another --out")
    created = not os.path.isdir(path)
    os.makedirs(path, exist_ok=True)
    return created


#: The largest CSV file read (a long RUN.csv at 200 Hz is a few MB).
MAX_CSV_BYTES = 256 * 2**20
#: The largest JSON file read (heliquad's own are a few kB; a manifest grows with frequencies).
MAX_JSON_BYTES = 16 * 2**20
#: POINTS.csv holds one row per excitation frequency; a fit of more would take minutes.
MAX_POINTS = 10_000
#: POINTS.csv: frequencies and magnitudes heliquad fits (outside them a file is in the wrong
#: units, or its numbers cannot be scaled into double precision with a model's powers of s).
OMEGA_RANGE = (1e-6, 1e9)
MAGNITUDE_RANGE = (1e-12, 1e12)
#: POINTS.csv: the highest frequency at most this many times the lowest (six decades).
MAX_OMEGA_SPAN = 1e6
#: RUN.csv: sampling rates, Hz, and the largest magnitude of a sample.
RATE_RANGE_HZ = (1e-3, 1e7)
MAX_SAMPLE = 1e150
#: A sweep's signal (manifest.json and models.json ``signal``): the paper's dwell, one sine
#: at a time, or one multisine for the whole band.
SWEEP_SIGNALS = ("dwell", "multisine")
#: A manifest's loop rate (freq_hz x period_samples), Hz.
LOOP_RANGE_HZ = (1.0, 1e4)
#: A model's pure delay, s.
MAX_DELAY_S = 10.0


def _read_table(path, required, optional=(), what="CSV file"):
    """Read a headed CSV of numbers; returns {column: array} for required + present optional.
    Required columns must be finite; optional ones may hold nan (a value not known)."""
    text = read_text(path, MAX_CSV_BYTES, what)
    try:
        fh = io.StringIO(text, newline="")
        names = [h.strip() for h in next(csv.reader(fh))]
        missing = [c for c in required if c not in names]
        if missing:
            raise InputError(f"{path}: missing column(s) {','.join(missing)}; header has "
                             f"{_short(','.join(names)) or 'nothing'} (expected "
                             f"{','.join(required)})")
        twice = sorted({c for c in names if c and names.count(c) > 1})
        if twice:
            raise InputError(f"{path}: column {twice[0]} appears twice in the header")
        wanted = list(required) + [c for c in optional if c in names]
        _check_row_lengths(path, text.splitlines()[1:], len(names))
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")      # "empty input file" from numpy
            data = np.loadtxt(fh, delimiter=",", usecols=[names.index(c) for c in wanted],
                              ndmin=2, dtype=float)
    except csv.Error as exc:
        raise InputError(f"{path}: not a CSV file ({exc})") from None
    except ValueError as exc:
        if isinstance(exc, InputError):
            raise
        first = str(exc).splitlines()[0] if str(exc) else "malformed row"
        raise InputError(f"{path}: {_short(first)} (data rows count from 1 after the "
                         "header)") from None
    if data.shape[0] == 0:
        raise InputError(f"{path}: no data rows after the header")
    table = {c: data[:, i] for i, c in enumerate(wanted)}
    for c in required:
        bad = np.flatnonzero(~np.isfinite(table[c]))
        if bad.size:
            raise InputError(f"{path}: column {c} has NaN or infinity at data row {bad[0] + 1}")
    return table


def _check_row_lengths(path, rows, n) -> None:
    """Every data row has as many fields as the header (numpy would quietly ignore extra
    ones in columns it does not read)."""
    for i, row in enumerate(rows, 1):
        if row.strip() and not row.lstrip().startswith("#") and row.count(",") != n - 1:
            raise InputError(f"{path}: data row {i} has {row.count(',') + 1} fields; the header "
                             f"has {n}")


def _short(text: str, limit: int = 80) -> str:
    """A value or text for a one-line message: control characters escaped, cut at ``limit``."""
    text = text.encode("unicode_escape").decode("ascii") if not text.isprintable() else text
    return text if len(text) <= limit else text[:limit - 3] + "..."


def _first_bad(path, column, values, ok, what) -> None:
    """InputError naming the first data row of ``column`` whose value is not ``ok``."""
    bad = np.flatnonzero(~ok)
    if bad.size:
        raise InputError(f"{path}: {column} at data row {bad[0] + 1} is {values[bad[0]]:g}; "
                         f"it must be {what}")


def read_run_csv(path):
    """Read a sine experiment. Returns ``(fs_hz, u, y)``."""
    table = _read_table(path, RUN_COLUMNS, what="RUN.csv (columns t_s,u,y)")
    t = table["t_s"]
    if t.size < 3:
        raise InputError(f"{path}: only {t.size} samples; a run needs many periods of data")
    for c in RUN_COLUMNS:
        _first_bad(path, c, table[c], np.abs(table[c]) <= MAX_SAMPLE,
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
    return 1.0 / mean_dt, table["u"], table["y"]


def write_run_csv(path, rows) -> None:
    """RUN.csv: a ``t_s,u,y`` header, then one row per sample (``rows``: (t_s, u, y))."""
    with atomic_write(path) as fh:
        np.savetxt(fh, np.asarray(rows, dtype=float).reshape(-1, 3), delimiter=",",
                   header="t_s,u,y", comments="", fmt="%.9g")


def read_points_csv(path):
    """Read frequency-response points.

    Returns
    -------
    dict
        ``omega`` (rad/s), ``F`` (complex), and ``sigma``, ``coherence``, ``coherence_ry``,
        ``coherence_ru``: arrays, or None for a column the file does not have.
    """
    table = _read_table(path, POINTS_COLUMNS, POINTS_OPTIONAL + POINTS_EXCITATION + POINTS_LOSS,
                        what="POINTS.csv (columns omega_rad_s,magnitude,phase_rad)")
    omega, mag = table["omega_rad_s"], table["magnitude"]
    if omega.size > MAX_POINTS:
        raise InputError(f"{path}: {omega.size} rows; a points file holds at most {MAX_POINTS} "
                         "(one per excitation frequency)")
    (wlo, whi), (mlo, mhi) = OMEGA_RANGE, MAGNITUDE_RANGE
    _first_bad(path, "omega_rad_s", omega, (omega >= wlo) & (omega <= whi),
               f"in [{wlo:g}, {whi:g}] rad/s")
    bad = np.flatnonzero(np.diff(omega) <= 0)
    if bad.size:
        raise InputError(f"{path}: omega_rad_s does not increase at data row {bad[0] + 2} "
                         "(one row per frequency, in increasing order)")
    if omega[-1] > MAX_OMEGA_SPAN * omega[0]:
        raise InputError(f"{path}: omega_rad_s spans {omega[0]:g} to {omega[-1]:g} rad/s, more "
                         f"than {math.log10(MAX_OMEGA_SPAN):g} decades: one model cannot be fitted "
                         "to it (split the band)")
    _first_bad(path, "magnitude", mag, mag > 0, "positive and linear (not dB)")
    _first_bad(path, "magnitude", mag, (mag >= mlo) & (mag <= mhi), f"in [{mlo:g}, {mhi:g}]")
    _first_bad(path, "phase_rad", table["phase_rad"], np.abs(table["phase_rad"]) <= 1e4,
               "within +/-1e4 rad")
    out = {"omega": omega, "F": mag * np.exp(1j * table["phase_rad"]),
           **{c: table.get(c) for c in POINTS_OPTIONAL + POINTS_EXCITATION + POINTS_LOSS}}
    if out["sigma"] is not None:
        s = out["sigma"]
        _first_bad(path, "sigma", s, np.isfinite(s) & (s >= 0), "finite and non-negative")
    for name in ("coherence", *POINTS_EXCITATION):
        if out[name] is not None:
            c = out[name]
            _first_bad(path, name, c, np.isnan(c) | ((c >= 0) & (c <= 1)),
                       "in [0, 1] (or nan: not known)")
    return out


def read_points_table(path):
    """Read the paper-style table ``heliquad identify`` writes (points_table.csv): columns
    ``freq_hz,omega_rad_s,magnitude,phase_deg,real,imag,coherence`` (coherence may be nan)."""
    table = _read_table(path, TABLE_COLUMNS[:-1], TABLE_COLUMNS[-1:],
                        what="points table (" + ",".join(TABLE_COLUMNS) + ")")
    if "coherence" not in table:
        raise InputError(f"{path}: missing column coherence")
    c = table["coherence"]
    _first_bad(path, "coherence", c, np.isnan(c) | ((c >= 0) & (c <= 1)),
               "in [0, 1] (or nan: not known)")
    return table


# --- JSON documents: one reader per format, each checked against its schema -----------------

def read_json(path, what: str, schema):
    """A JSON file checked against ``schema`` (:mod:`.schema`); InputError in one line naming
    the file (and the key at fault) for anything else."""
    text = read_text(path, MAX_JSON_BYTES, what)
    try:
        doc = json.loads(text)
    except json.JSONDecodeError as exc:
        raise InputError(f"{path}: not valid JSON ({exc.msg} at line {exc.lineno} column "
                         f"{exc.colno}): not a {what}") from None
    except RecursionError:
        raise InputError(f"{path}: JSON nested too deeply: not a {what}") from None
    except ValueError:                       # an integer of thousands of digits
        raise InputError(f"{path}: a number too long to read: not a {what}") from None
    return schema.check(path, "", doc)


@functools.cache
def _manifest_schema():
    frequency = S.Obj(
        required={"requested_hz": S.Num(0, 1e6, lo_open=True), "samples": S.Int(0, 2**31),
                  "status": S.Str()},
        optional={"amplitude": S.Num(), "freq_hz": S.Num(0, 1e6, lo_open=True),
                  "period_samples": S.Int(2, 2**31), "start_us": S.Int(0, 2**63 - 1),
                  "end_us": S.Int(0, 2**63 - 1), "messages": S.List(S.Str()),
                  **{k: S.Int(0, 2**31) for k in ("seq_gaps", "saturated", "collective_limited",
                                                  "sensor_clipped", "cycles", "lost",
                                                  "lost_run", "garbage_bytes")},
                  "period_inferred": S.Bool(),
                  "dwell_end": S.Str(("target", "cap", "amplitude")), "relative_sigma": S.Null(S.Num(0)),
                  "signal": S.Str(tuple(names.SIGNALS)),
                  "orders": S.List(S.Int(1, 2**31), 1, 16), "fade_samples": S.Int(0, 2**31)})
    return S.Obj(
        required={"axis": S.Str(tuple(names.AXES)), "inject": S.Str(tuple(names.INJECTIONS)),
                  "frequencies": S.List(frequency, 0, 10_000)},
        optional={"tlog": S.Str(file_name=True), "tlog_start_us": S.Null(S.Int(0, 2**63 - 1)),
                  "source": S.Obj(), "firmware": S.Str(),
                  "gains": S.Null(_recorded_gains_schema()), "params": S.Null(S.Obj(values=S.Num())),
                  "started": S.Str(), "cycles": S.Int(1, 65535),
                  "fade_cycles": S.Int(1, 65535), "limits": S.Obj(values=S.Num()),
                  "design": S.Obj(), "signal": S.Str(SWEEP_SIGNALS),
                  "complete": S.Bool(), "aborted": S.Null(S.Str()),
                  "in_progress_hz": S.Null(S.Num()),
                  "planned_hz": S.List(S.Num(0, 1e6, lo_open=True), 0, 10_000)})


def _check_orders(path, key, entry) -> None:
    """A multisine's lines: strictly increasing, each at least four samples per cycle."""
    orders = entry.get("orders")
    if orders is None:
        S.fail(path, f"{key}.orders", "is missing (a multisine whose status is ok)")
    if any(b <= a for a, b in zip(orders, orders[1:])):
        S.fail(path, f"{key}.orders", "must be strictly increasing", orders)
    if 4 * orders[-1] > entry["period_samples"]:
        S.fail(path, f"{key}.orders", f"the highest line has fewer than 4 samples per cycle of "
               f"the {entry['period_samples']}-sample period", orders[-1])


def read_manifest(path) -> dict:
    """A sweep folder's manifest.json, checked (docs/file-formats.md): every frequency that
    is ``ok`` has the frequency, period and sample window identification needs."""
    doc = read_json(path, "sweep manifest (manifest.json)", _manifest_schema())
    if doc["axis"] == "yaw" and doc["inject"] == "angle":
        S.fail(path, "inject", "angle is not possible on yaw (rate only)")
    for i, entry in enumerate(doc["frequencies"]):
        key = f"frequencies[{i}]"
        if entry["status"] == "ok":
            for name in ("freq_hz", "period_samples", "start_us", "end_us"):
                if name not in entry:
                    S.fail(path, f"{key}.{name}", "is missing (the frequency's status is ok)")
        if entry["status"] == "ok" and entry.get("signal") == "multisine":
            _check_orders(path, key, entry)
        if "start_us" in entry and entry["start_us"] > entry.get("end_us", math.inf):
            S.fail(path, f"{key}.end_us", "is before start_us", entry["end_us"])
        if "freq_hz" in entry and "period_samples" in entry:
            loop_hz = entry["freq_hz"] * entry["period_samples"]
            if not LOOP_RANGE_HZ[0] <= loop_hz <= LOOP_RANGE_HZ[1]:
                S.fail(path, key, f"freq_hz x period_samples, the loop rate, is {loop_hz:g} Hz; "
                       f"it must be in [{LOOP_RANGE_HZ[0]:g}, {LOOP_RANGE_HZ[1]:g}] Hz")
    return doc


@functools.cache
def _models_schema():
    pairs = S.List(S.Seq(("real", S.Num()), ("imag", S.Num())), 0, 12)
    model = S.Obj(
        required={"num": S.List(S.Num(), 1, 13), "den": S.List(S.Num(), 2, 13)},
        optional={"order": S.Seq(("M", S.Int(0, 12)), ("N", S.Int(1, 12))),
                  "delay_s": S.Num(0, MAX_DELAY_S), "stable": S.Bool(), "degenerate": S.Bool(),
                  "degenerate_why": S.Str(), "integrator": S.Bool(),
                  "metrics": S.Obj(values=S.Null(S.Num())), "poles": pairs, "zeros": pairs,
                  "dc_gain": S.Null(S.Num())})
    log = S.Obj(optional={"first_regions": S.List(S.List(S.Int(0, 2**63), 2, 2))},
                values=S.Int(0, 2**63))
    return S.Obj(
        required={"models": S.List(model, 1, 1000)},
        optional={"recommended": S.Null(S.Int(0, 999)), "reason": S.Str(),
                  "axis": S.Str(tuple(names.AXES)), "points_file": S.Str(), "weights": S.Str(), "log": log,
                  "skipped_frequencies": S.List(S.Str()),
                  "saturated_frequencies": S.List(S.Str()),
                  "estimate": S.Str(("excitation", "input")), "sil_truth": _sil_truth_schema(),
                  "signal": S.Str(SWEEP_SIGNALS),
                  "replay": _replay_schema(),
                  "quality": S.Obj(required={"level": S.Str(("good", "acceptable", "poor")),
                                             "why": S.Str()}),
                  "band_rad_s": S.Seq(("low", S.Num(0, 1e7, lo_open=True)),
                                      ("high", S.Num(0, 1e7, lo_open=True))),
                  "broken_loop": S.Obj(), "gains": _recorded_gains_schema()})


def _recorded_gains_schema():
    """The gains a sweep recorded from its board (manifest.json, carried into models.json):
    rate ``[Kc, tau_I_s, tau_D_s]``, angle ``[Kc, tau_D_s]`` or null (yaw)."""
    gain, tau_i, tau_d = S.Num(0, 1e4, lo_open=True), S.Num(0, 1e4), S.Num(0, 1e3)
    return S.Obj(required={"rate": S.Seq(("Kc", gain), ("tau_I_s", tau_i), ("tau_D_s", tau_d))},
                 optional={"angle": S.Null(S.Seq(("Kc", gain), ("tau_D_s", tau_d)))})


def _sil_truth_schema():
    """models.json's ``sil_truth`` (:func:`heliquad.host.validate.truth.truth_record`), as far as
    ``heliquad report`` reads it."""
    num = S.Null(S.Num())
    point = S.Obj(required={"freq_hz": S.Num(0, lo_open=True)},
                  optional={k: num for k in ("truth_db", "truth_deg", "error_db", "error_deg",
                                             "error_over_sigma")})
    return S.Obj(required={"points": S.List(point), "points_worst_db": S.Num(),
                           "points_worst_deg": S.Num()},
                 optional={k: num for k in ("points_rms_error_over_sigma", "model_worst_db",
                                            "model_worst_deg")})


def _replay_schema():
    """models.json's ``replay``: the recommended model's replay of each frequency's record."""
    point = S.Obj(required={"freq_hz": S.Num(0, lo_open=True), "periods": S.Int(1, 2**31),
                            "nrmse": S.Null(S.Num(0))})
    return S.Obj(required={"model": S.Int(0, 999), "points": S.List(point)},
                 optional={"discard_periods": S.Int(0, 2**31)})


def read_models_json(path) -> dict:
    """MODELS.json, checked (docs/file-formats.md): each model proper (num no longer than
    den, and both as long as its ``order`` says), den's leading coefficient not zero,
    ``recommended`` an index into ``models`` or null. A
    model without ``order`` gets the one its coefficients have."""
    doc = read_json(path, "MODELS.json", _models_schema())
    for i, m in enumerate(doc["models"]):
        key = f"models[{i}]"
        deg_num, deg_den = m.setdefault("order", [len(m["num"]) - 1, len(m["den"]) - 1])
        if deg_num > deg_den:
            S.fail(path, f"{key}.order", "is improper (numerator degree above the "
                   "denominator's)", m["order"])
        for name, want in (("num", deg_num + 1), ("den", deg_den + 1)):
            if len(m[name]) != want:
                S.fail(path, f"{key}.{name}", f"must have {want} coefficients (order "
                       f"{deg_num}/{deg_den})", m[name])
        if m["den"][0] == 0:
            S.fail(path, f"{key}.den[0]", "must not be 0 (the leading coefficient)")
        with np.errstate(all="ignore"):
            scaled = np.asarray(m["num"] + m["den"], float) / float(m["den"][0])
        if not np.all(np.isfinite(scaled)):
            S.fail(path, key, "has coefficients beyond double range once den is monic")
    band = doc.get("band_rad_s")
    if band is not None and not band[0] <= band[1]:
        S.fail(path, "band_rad_s", "must be [low, high] with low <= high", band)
    rec = doc.get("recommended")
    if rec is not None and rec >= len(doc["models"]):
        S.fail(path, "recommended", f"is not an index into models (0..{len(doc['models']) - 1})",
               rec)
    return doc


@functools.cache
def _gains_schema():
    gain, tau_i, tau_d = S.Num(0, 1e4, lo_open=True), S.Num(0, 1e4), S.Num(0, 1e3)
    rate = S.Seq(("Kc", gain), ("tau_I_s", tau_i), ("tau_D_s", tau_d))
    angle = S.Seq(("Kc", gain), ("tau_D_s", tau_d))
    return S.Obj(required={"rate": S.Obj(optional={a: rate for a in names.AXES}, strict=True)},
                 optional={"angle": S.Obj(optional={a: angle for a in names.AXES if a != "yaw"},
                                          strict=True)},
                 strict=True)


def read_gains(path, axis: str) -> tuple:
    """A gains file's gains for ``axis``: ``(rate, angle)``, rate ``(Kc, tau_I, tau_D)`` and
    angle ``(Kc, tau_D)`` (None for yaw, which is rate only). Keys and ranges:
    docs/file-formats.md."""
    doc = read_json(path, "gains file", _gains_schema())
    if axis not in doc["rate"]:
        S.fail(path, f"rate.{axis}", "is missing ([Kc, tau_I_s, tau_D_s])")
    if axis != "yaw" and axis not in doc.get("angle", {}):
        S.fail(path, f"angle.{axis}", "is missing ([Kc, tau_D_s])")
    rate = tuple(float(v) for v in doc["rate"][axis])
    return rate, None if axis == "yaw" else tuple(float(v) for v in doc["angle"][axis])


@functools.cache
def _validation_schema():
    num = S.Null(S.Num())
    crossing = S.Obj(required={"omega_rad_s": S.Num(0)}, optional={"in_band": S.Bool()},
                     values=num)
    crossings = {"gain_crossovers": S.List(crossing), "phase_crossovers": S.List(crossing)}
    loop = S.Obj(required={"closed_loop_stable": S.Bool()},
                 optional={**crossings, "not_validated": S.List(S.Str())}, values=num)
    truth = S.Obj(optional={**crossings, "not_validated": S.List(S.Str()),
                            "closed_loop_stable": S.Bool()}, values=num)
    point = S.Obj(required={"freq_hz": S.Num(0, lo_open=True), "magnitude_db": S.Num(),
                            "phase_deg": S.Num()})
    measured = S.Obj(required={"loop": S.Str(), "injection": S.Str()},
                     optional={**crossings, "unmeasured": S.List(S.Str()),
                               "points": S.List(point)}, values=num)
    return S.Obj(
        required={"stable": S.Bool(), "loops": S.Obj(values=loop)},
        optional={
            "band_rad_s": S.Seq(("low", S.Num(0)), ("high", S.Num(0))),
            "truth_loops": S.Obj(values=truth), "measured_loop": measured,
            "step": S.Obj(required={"size": S.Num(), "unit": S.Str()}, values=num),
            "sine": S.Obj(required={"freq_hz": S.Num()}, values=num),
            "turbulence": S.Obj(required={"level": S.Str(), "rate_rms_deg_s": S.Num(),
                                          "gust_rate_rms_deg_s": S.Num()}),
            "instability": S.Obj(required={"pole_rad_s": S.Num(0),
                                           "band_top_rad_s": S.Num(0, lo_open=True),
                                           "outside_band": S.Bool()})})


def read_validation(path) -> dict:
    """validation.json (``heliquad validate``), checked for what ``heliquad report`` shows."""
    doc = read_json(path, "validation.json", _validation_schema())
    if doc["stable"]:
        for name in ("step", "sine"):
            if name not in doc:
                S.fail(path, name, "is missing (the cascade is stable)")
    return doc


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


def _clean(x):
    """JSON has no NaN or infinity: write them as null."""
    x = float(x)
    return x if math.isfinite(x) else None


def model_to_dict(model) -> dict:
    """A :class:`~heliquad.host.estimate.fit.TfModel` as the MODELS.json entry."""
    return {
        "order": list(model.order),
        "integrator": bool(model.integrator),
        "num": [float(c) for c in model.num],
        "den": [float(c) for c in model.den],
        "delay_s": float(model.delay_s),
        "stable": bool(model.stable),
        "degenerate": bool(model.degenerate),
        **({"degenerate_why": model.degenerate_why} if model.degenerate_why else {}),
        "metrics": {k: _clean(v) if isinstance(v, float) else v
                    for k, v in model.metrics.items()},
        "poles": [[float(p.real), float(p.imag)] for p in model.poles],
        "zeros": [[float(z.real), float(z.imag)] for z in model.zeros],
        "dc_gain": _clean(model.dc_gain),
    }


def write_models_json(path, models, recommended, reason, source=None, weights=None, axis=None,
                      extra=None, band_rad_s=None):
    """Write MODELS.json; the file is replaced atomically so a failure never truncates it.
    ``extra``: more top-level entries (identify adds the log's condition and the frequencies
    it could not use). ``band_rad_s``: the lowest and highest frequency of the points the
    models were fitted to (validation trusts a model only there)."""
    doc = {"models": [model_to_dict(m) for m in models], "recommended": recommended,
           "reason": reason, **(extra or {})}
    if band_rad_s is not None:
        doc["band_rad_s"] = [float(band_rad_s[0]), float(band_rad_s[1])]
    if recommended is not None:
        from ..estimate.metrics import quality

        level, why = quality(models[recommended])
        doc["quality"] = {"level": level, "why": why}
    if axis is not None:
        doc["axis"] = axis
    if source is not None:
        doc["points_file"] = str(source)
    if weights is not None:
        doc["weights"] = weights
    write_json(path, doc)


#: MODELS.mat's struct fields; each model's metrics (MODELS.json's) come before dc_gain.
MAT_FIELDS = ("order", "num", "den", "delay_s", "stable", "degenerate", "dc_gain")


def write_models_mat(path, models, recommended):
    """Write MODELS.mat (docs/file-formats.md), atomically: ``models``, a 1-by-N MATLAB
    struct array with the fields of :data:`MAT_FIELDS` around every metric of the models
    (doubles, logical flags, coefficient row vectors), and ``recommended``, a 1-based index
    (0 when none)."""
    import scipy.io

    metrics = list(dict.fromkeys(k for m in models for k in m.metrics))
    fields = [*MAT_FIELDS[:-1], *metrics, MAT_FIELDS[-1]]
    array = np.empty((1, len(models)), dtype=[(f, object) for f in fields])
    for i, m in enumerate(models):
        entry = {"order": np.array([m.order], float), "num": np.array([m.num], float),
                 "den": np.array([m.den], float), "delay_s": float(m.delay_s),
                 "stable": bool(m.stable), "degenerate": bool(m.degenerate),
                 "dc_gain": float(m.dc_gain),
                 **{k: float(m.metrics.get(k, math.nan)) for k in metrics}}
        array[0, i] = tuple(entry[f] for f in fields)
    with atomic_write(path, "wb") as fh:
        scipy.io.savemat(fh, {"models": array,
                              "recommended": float(0 if recommended is None else recommended + 1)})


#: A parameter file is a few kB (a firmware has tens of parameters, ArduPilot about 1000).
MAX_PARAMS_BYTES = 2**20
#: QGroundControl's columns (and MAVProxy's two: NAME VALUE).
QGC_COLUMNS = "Vehicle-Id Component-Id Name Value Type"


def read_params_file(path) -> list:
    """A .params file: ``[(name, value, type or None)]`` in the file's order. Lines are
    MAVProxy's ``NAME VALUE`` (whitespace or a comma between) or QGroundControl's ``SYSID
    COMPID NAME VALUE TYPE`` (tabs), told apart by their number of fields; ``#`` starts a
    comment. A bad line is one InputError naming the file and the line."""
    from ..acquire.param_protocol import TYPE_NAMES, check_name

    text = read_text(path, MAX_PARAMS_BYTES, "parameter file (.params)")
    out, first = [], {}
    for number, line in enumerate(text.splitlines(), 1):
        fields = line.split("#", 1)[0].replace(",", " ").split()
        if not fields:
            continue
        where = f"{path}, line {number}"
        if len(fields) not in (2, 5):
            raise InputError(f"{where}: {len(fields)} fields; expected NAME VALUE (MAVProxy) "
                             "or SYSID COMPID NAME VALUE TYPE (QGroundControl)")
        name, value = fields[-3:-1] if len(fields) == 5 else fields
        ptype = _params_ints(where, fields) if len(fields) == 5 else None
        if ptype is not None and ptype not in TYPE_NAMES:
            raise InputError(f"{where}: type {ptype} is not a MAV_PARAM_TYPE (1 to 10)")
        try:
            check_name(name)
        except InputError as exc:
            raise InputError(f"{where}: {exc}") from None
        if name in first:
            raise InputError(f"{where}: {name} again (first on line {first[name]})")
        first[name] = number
        out.append((name, _params_value(where, name, value), ptype))
    if not out:
        raise InputError(f"{path}: no parameters in it (only comments)")
    return out


def _params_ints(where: str, fields) -> int:
    """A QGroundControl line's system and component ids (checked) and its type."""
    try:
        sysid, compid, ptype = int(fields[0]), int(fields[1]), int(fields[4])
    except ValueError:
        raise InputError(f"{where}: the system id, component id and type must be whole "
                         "numbers") from None
    if not (0 <= sysid <= 255 and 0 <= compid <= 255):
        raise InputError(f"{where}: system and component ids are 0 to 255")
    return ptype


def _params_value(where: str, name: str, text: str) -> float:
    try:
        value = float(int(text, 16)) if text.lower().startswith(("0x", "-0x")) else float(text)
    except ValueError:
        raise InputError(f"{where}: {name}'s value {_short(text)!r} is not a number") from None
    if not math.isfinite(value):
        raise InputError(f"{where}: {name}'s value {text} is not a finite number")
    return value


def write_params_file(path, params, header: str = "", layout: str = "qgc") -> None:
    """``params`` (:class:`~heliquad.host.acquire.param_protocol.Param`) as QGroundControl writes them: a
    header comment, then ``1<TAB>1<TAB>NAME<TAB>VALUE<TAB>TYPE`` per parameter, by name;
    with ``layout="mavproxy"``, as MAVProxy's ``param save`` does (``NAME VALUE``, which its
    ``param load`` reads). Each value the shortest decimal that reads back as the same
    single-precision float (a whole-number type's as an integer). Written whole
    (:func:`atomic_write`)."""
    if layout == "mavproxy":
        lines = [f"# {h}" for h in header.splitlines()]
        lines += [f"{p.name:<16} {p.text()}" for p in sorted(params, key=lambda p: p.name)]
        with atomic_write(path) as fh:
            fh.write("\n".join(lines) + "\n")
        return
    lines = ["# Onboard parameters for Vehicle 1", "#"]
    lines += [f"# {h}" for h in header.splitlines()] + ["#", f"# {QGC_COLUMNS}"]
    for p in sorted(params, key=lambda p: p.name):
        lines.append(f"1\t1\t{p.name}\t{p.text()}\t{p.type}")
    with atomic_write(path) as fh:
        fh.write("\n".join(lines) + "\n")
