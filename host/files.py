"""The file formats of the host tool (docs/file-formats.md is the reference).

* RUN.csv: header row, columns ``t_s,u,y`` (in any order, extra columns ignored), uniformly
  sampled, time strictly increasing.
* POINTS.csv: header row, columns ``omega_rad_s,magnitude,phase_rad`` and optionally
  ``sigma,coherence``; one row per frequency, omega strictly increasing; phase wrapped or not.
* MODELS.json: ``{"models": [...], "recommended": INDEX, ...}``, coefficients in descending
  powers of s, den monic.

Readers raise :class:`InputError` with a one-line message naming the file and the problem.
"""

from __future__ import annotations

import contextlib
import csv
import json
import math
import os
import tempfile
import warnings

import numpy as np

from .errors import DiskFull, InputError, no_room

__all__ = ["RUN_COLUMNS", "POINTS_COLUMNS", "read_run_csv", "read_points_csv",
           "write_run_csv", "write_points_csv", "write_models_json", "write_models_mat", "model_to_dict",
           "atomic_write", "write_json", "save_figure", "new_output_folder"]

RUN_COLUMNS = ("t_s", "u", "y")
POINTS_COLUMNS = ("omega_rad_s", "magnitude", "phase_rad")
POINTS_OPTIONAL = ("sigma", "coherence")
#: Largest spread of sample intervals, relative to the mean interval, still called uniform.
UNIFORM_TOLERANCE = 0.01


@contextlib.contextmanager
def atomic_write(path, mode: str = "w"):
    """A file object for ``path`` that replaces it only once everything is written: the
    data goes to a temporary file beside it, is flushed to the disk, and is renamed over
    ``path`` at the end. A failure (a full disk, an exception while writing) leaves the old
    file as it was and no temporary file behind; a write that finds no room raises
    :class:`DiskFull` naming ``path``, any other OSError an InputError."""
    path = os.fspath(path)
    folder = os.path.dirname(os.path.abspath(path))
    try:
        fd, tmp = tempfile.mkstemp(prefix=f".{os.path.basename(path)}.", suffix=".tmp",
                                   dir=folder)
    except OSError as exc:
        raise _write_error(path, exc) from None
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
    """``doc`` as indented JSON, atomically (:func:`atomic_write`)."""
    with atomic_write(path) as fh:
        json.dump(doc, fh, indent=2)
        fh.write("\n")


def save_figure(fig, path, **kwargs) -> None:
    """A matplotlib figure to ``path`` (format from its extension), atomically."""
    fmt = os.path.splitext(os.fspath(path))[1].lstrip(".") or "png"
    with atomic_write(path, "wb") as fh:
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


def _read_table(path, required, optional=()):
    """Read a headed CSV of numbers; returns {column: array} for required + present optional."""
    try:
        with open(path, newline="") as fh:
            header = next(csv.reader(fh), None)
            if header is None:
                raise InputError(f"{path}: empty file (expected a header row: "
                                 f"{','.join(required)})")
            names = [h.strip() for h in header]
            missing = [c for c in required if c not in names]
            if missing:
                raise InputError(f"{path}: missing column(s) {','.join(missing)}; header has "
                                 f"{','.join(names) or 'nothing'} (expected {','.join(required)})")
            wanted = list(required) + [c for c in optional if c in names]
            cols = [names.index(c) for c in wanted]
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")      # "empty input file" from numpy
                data = np.loadtxt(fh, delimiter=",", usecols=cols, ndmin=2, dtype=float)
    except FileNotFoundError:
        raise InputError(f"{path}: no such file") from None
    except IsADirectoryError:
        raise InputError(f"{path}: is a directory, not a CSV file") from None
    except UnicodeDecodeError:
        raise InputError(f"{path}: not a text CSV file") from None
    except ValueError as exc:
        if isinstance(exc, InputError):
            raise
        first = str(exc).splitlines()[0] if str(exc) else "malformed row"
        raise InputError(f"{path}: {first} (data rows count from 1 after the header)") from None
    if data.shape[0] == 0:
        raise InputError(f"{path}: no data rows after the header")
    table = {c: data[:, i] for i, c in enumerate(wanted)}
    for c in required:
        bad = np.flatnonzero(~np.isfinite(table[c]))
        if bad.size:
            raise InputError(f"{path}: column {c} has NaN or infinity at data row {bad[0] + 1}")
    return table


def read_run_csv(path):
    """Read a sine experiment. Returns ``(fs_hz, u, y)``."""
    table = _read_table(path, RUN_COLUMNS)
    t = table["t_s"]
    if t.size < 3:
        raise InputError(f"{path}: only {t.size} samples; a run needs many periods of data")
    dt = np.diff(t)
    bad = np.flatnonzero(dt <= 0)
    if bad.size:
        raise InputError(f"{path}: time t_s does not increase at data row {bad[0] + 2}")
    mean_dt = (t[-1] - t[0]) / (t.size - 1)
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
        ``omega`` (rad/s), ``F`` (complex), and ``sigma`` / ``coherence`` arrays or None.
    """
    table = _read_table(path, POINTS_COLUMNS, POINTS_OPTIONAL)
    omega = table["omega_rad_s"]
    bad = np.flatnonzero(np.diff(omega) <= 0)
    if bad.size:
        raise InputError(f"{path}: omega_rad_s does not increase at data row {bad[0] + 2}")
    if omega[0] <= 0:
        raise InputError(f"{path}: omega_rad_s must be positive (row 1 has {omega[0]:g})")
    mag = table["magnitude"]
    if np.any(mag <= 0):
        raise InputError(f"{path}: magnitude must be positive and linear (not dB); data row "
                         f"{np.flatnonzero(mag <= 0)[0] + 1} is {mag[mag <= 0][0]:g}")
    out = {"omega": omega, "F": mag * np.exp(1j * table["phase_rad"]),
           "sigma": table.get("sigma"), "coherence": table.get("coherence")}
    for name in POINTS_OPTIONAL:
        col = out[name]
        if col is not None and (np.any(~np.isfinite(col)) or np.any(col < 0)):
            raise InputError(f"{path}: column {name} must be finite and non-negative")
    if out["coherence"] is not None and np.any(out["coherence"] > 1):
        raise InputError(f"{path}: coherence must lie in [0, 1]")
    return out


def write_points_csv(path, points):
    """Write :class:`~heliquad.host.fsf.FrequencyPoint` objects, sorted by frequency."""
    rows = sorted(points, key=lambda p: p.omega_rad_s)
    with atomic_write(path) as fh:
        fh.write(",".join(POINTS_COLUMNS + POINTS_OPTIONAL) + "\n")
        for p in rows:
            fh.write(f"{p.omega_rad_s:.12g},{p.magnitude:.12g},{p.phase_rad:.12g},"
                     f"{p.sigma:.6g},{p.coherence:.6g}\n")


def _clean(x):
    """JSON has no NaN or infinity: write them as null."""
    x = float(x)
    return x if math.isfinite(x) else None


def model_to_dict(model) -> dict:
    """A :class:`~heliquad.host.fit.TfModel` as the MODELS.json entry."""
    return {
        "order": list(model.order),
        "num": [float(c) for c in model.num],
        "den": [float(c) for c in model.den],
        "delay_s": float(model.delay_s),
        "stable": bool(model.stable),
        "degenerate": bool(model.degenerate),
        "metrics": {k: _clean(v) if isinstance(v, float) else v
                    for k, v in model.metrics.items()},
        "poles": [[float(p.real), float(p.imag)] for p in model.poles],
        "zeros": [[float(z.real), float(z.imag)] for z in model.zeros],
        "dc_gain": _clean(model.dc_gain),
    }


def write_models_json(path, models, recommended, reason, source=None, weights=None, axis=None,
                      extra=None):
    """Write MODELS.json; the file is replaced atomically so a failure never truncates it.
    ``extra``: more top-level entries (identify adds the log's condition and the frequencies
    it could not use)."""
    doc = {"models": [model_to_dict(m) for m in models], "recommended": recommended,
           "reason": reason, **(extra or {})}
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
