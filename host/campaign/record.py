"""``heliquad identify --from-record``: points from a record without a designed periodic
excitation (pilot inputs, turbulence, a chirp, or a sweep's whole log read as one record),
by the composite of overlapped windows of several lengths (:mod:`..estimate.composite`).

The record is the log's HQ_SYSID_SAMPLE stream: the longest stretch of armed loops (a
stretch is broken by a disarmed loop; samples lost on the link inside it are holes, filled
by a straight line between their neighbours and counted). The input and the output are the
fields named (by default those of the sweep's injection, or ``axis_cmd`` and ``rate``: the
torque command into the mixer and the measured rate, the plant the paper identifies). Where
the record carries an excitation (its ``excitation`` field is not zero throughout) and the
estimate is ``excitation``, each point is conditioned on it, as the periodic estimates are;
otherwise it is the direct estimate, which is right only where the input is not fed by the
output's noise (a pilot's inputs that outweigh the turbulence, not turbulence alone under a
closed loop: there it reads the controller, not the plant).

Points are estimated at :data:`RECORD_POINTS` frequencies, log-spaced over the band
(``--band``, else the span of the sweep's frequencies or of its multisine's lines, else the
paper's band for the axis); a point
whose coherence is below :data:`~..estimate.composite.MIN_COHERENCE` is left out and said.
"""

from __future__ import annotations

import math
import os

import numpy as np

from ...sim.base.dialect import AXES, dialect
from ...sim.base.errors import InputError
from ..acquire.link import input_output
from ..estimate.composite import MIN_COHERENCE, composite_response, default_windows_s
from ..records import paper
from ..records.tlog import TlogDamage, read_tlog_table

__all__ = ["record_points", "read_record", "longest_run", "coherent", "RECORD_POINTS"]

#: Frequencies of a record's estimate, log-spaced over its band.
RECORD_POINTS = 20
#: A stretch of armed loops is a record only this long or more, s.
MIN_RECORD_S = 4.0


def read_record(path):
    """``(samples, damage, folder for the outputs)`` of a .tlog (a ``heliquad log`` session;
    a sweep folder is read by identify's ``load_sweep``)."""
    damage = TlogDamage()
    if not path.endswith(".tlog"):
        raise InputError(f"{path}: not a folder or a .tlog")
    try:
        samples = read_tlog_table(path, dialect(), "HQ_SYSID_SAMPLE", damage=damage)
    except OSError as exc:
        raise InputError(f"{path}: {exc.strerror or exc}") from None
    return samples, damage, os.path.dirname(path) or "."


def longest_run(mask) -> tuple:
    """``(start, end)`` of the longest run of True in ``mask`` (the first of equal ones;
    ``(0, 0)`` when there is none)."""
    edges = np.diff(np.concatenate([[0], np.asarray(mask, dtype=np.int8), [0]]))
    starts, ends = np.flatnonzero(edges == 1), np.flatnonzero(edges == -1)
    if not starts.size:
        return 0, 0
    i = int(np.argmax(ends - starts))
    return int(starts[i]), int(ends[i])


def coherent(found) -> tuple:
    """``(points, said)``: the points of coherence MIN_COHERENCE or more, and a line for
    each one left out."""
    return ([p for p in found if p.coherence >= MIN_COHERENCE],
            [f"{p.freq_hz:.4g} Hz: coherence {p.coherence:.2f} below {MIN_COHERENCE:g}"
             for p in found if p.coherence < MIN_COHERENCE])


def _armed_stretch(samples):
    """The rows of the longest run of armed samples (in sequence order, once each)."""
    _, rows = np.unique(samples.seq.astype(np.int64), return_index=True)
    start, end = longest_run(samples.armed[rows] != 0)
    return rows[start:end]


def _named_axis(samples) -> str:
    """The axis a record's samples name most."""
    counts = np.bincount(samples.axis.astype(int), minlength=max(AXES.values()) + 1)
    axis = {v: k for k, v in AXES.items()}.get(int(np.argmax(counts)))
    if axis is None:
        raise InputError("the record names no axis: give --axis")
    return axis


def _armed_record(samples, names) -> tuple:
    """The longest armed stretch's times (s, on the loop's grid), its sample rate, its fields
    ``names`` with the samples lost on the link filled by a straight line, and the share
    lost."""
    rows = _armed_stretch(samples)
    if rows.size < 2:
        raise InputError("the record has no armed loops: nothing flew")
    seq = samples.seq[rows].astype(np.int64)
    t = samples.time_us[rows].astype(np.int64) * 1e-6
    step = float(np.median(np.diff(t)))
    if not step > 0:
        raise InputError("the record's samples have no time step (their times do not increase)")
    place = seq - seq[0]
    grid = np.arange(int(place[-1]) + 1)
    if grid.size * step < MIN_RECORD_S:
        raise InputError(f"the record's armed stretch is {t[-1] - t[0]:.3g} s; at least "
                         f"{MIN_RECORD_S:g} s is needed")
    signals = {name: np.interp(grid, place, samples[name][rows].astype(float))
               for name in dict.fromkeys(names)}
    return np.interp(grid, place, t), 1.0 / step, signals, 1.0 - rows.size / grid.size


def _band(manifest, axis, band_hz):
    if band_hz is not None:
        return tuple(band_hz)
    if manifest is not None and manifest.get("frequencies"):
        used = [e["freq_hz"] * k for e in manifest["frequencies"] if e.get("freq_hz")
                for k in (e.get("orders") or [1])]           # a multisine's lines
        used += [e["stop_hz"] for e in manifest["frequencies"] if e.get("stop_hz")]  # a chirp's
        if len(set(used)) > 1:
            return min(used), max(used)
    return paper.BANDS_HZ[axis]


def record_points(manifest, samples, estimate: str, progress, axis=None, fields=None,
                  band_hz=None) -> dict:
    """The record's points and what they came from: ``{"points", "skipped", "record",
    "segment", "axis", "inject"}``, ``record`` models.json's description of the estimate and
    ``segment`` the responses figure's record."""
    if not len(samples):
        raise InputError("the log holds no HQ_SYSID_SAMPLE: no record to identify")
    named = _named_axis(samples)
    if axis is not None and axis != named:
        raise InputError(f"--axis {axis}: the record's samples are {named}'s (HQ_SYSID_SAMPLE "
                         "names the axis its fields are of)")
    axis = (manifest or {}).get("axis") or named
    inject = (manifest or {}).get("inject", "mixer")
    u_name, y_name = fields or input_output(inject)
    t, fs, signals, lost = _armed_record(samples, (u_name, y_name, "excitation"))
    duration = t.size / fs
    lo, hi = _band(manifest, axis, band_hz)
    if not 0 < lo < hi < fs / 2:
        raise InputError(f"the band {lo:.4g}-{hi:.4g} Hz must be positive, increasing and "
                         f"below the record's Nyquist frequency ({fs / 2:.4g} Hz)")
    freqs = np.geomspace(lo, hi, RECORD_POINTS)
    windows = default_windows_s(duration, lo, hi)
    r = signals["excitation"]
    conditioned = estimate == "excitation" and bool(np.any(r != 0))
    if estimate == "excitation" and not conditioned:
        progress("  the record carries no excitation: the points are the direct estimate "
                 f"({y_name} over {u_name}), right only where the input is not fed by the "
                 "output's noise")
    found = composite_response(signals[y_name], signals[u_name], fs, freqs,
                               r=r if conditioned else None, windows_s=windows)
    points, skipped = coherent(found)
    resolved = {round(p.freq_hz, 9) for p in found}
    skipped += [f"{f:.4g} Hz: no window resolves it" for f in freqs
                if round(f, 9) not in resolved]
    progress(f"  record: {duration:.1f} s of {u_name} and {y_name} at {fs:.4g} Hz"
             + (f" ({100 * lost:.1f} % lost on the link, filled)" if lost else "")
             + f"; windows {', '.join(f'{w:.3g}' for w in windows)} s; "
             f"{len(points)} of {len(freqs)} points with coherence >= {MIN_COHERENCE:g}")
    record = {"input": u_name, "output": y_name, "duration_s": duration, "rate_hz": fs,
              "lost_share": lost, "windows_s": [float(w) for w in windows],
              "band_hz": [float(lo), float(hi)],
              "estimate": "excitation" if conditioned else "input"}
    segment = (math.sqrt(lo * hi), t, signals[u_name], signals[y_name])
    return {"points": points, "skipped": skipped, "record": record, "segment": segment,
            "axis": axis, "inject": inject}
