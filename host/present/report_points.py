"""The report's points section: the paper-style points table with what else the folder
knows of each point (its coherences with the excitation, the recommended model's replay
error, a simulated sweep's error against the simulator's truth); flags low coherence, and
points and a recommended model further from the truth than the accuracy."""

from __future__ import annotations


import numpy as np

from ..estimate.thresholds import ACCURACY_DB, ACCURACY_DEG, LOW_COHERENCE
from ..records.points import TABLE_COLUMNS, known_column
from .report_html import number_text, table_html

#: Two frequencies of one folder's files are the same point within this relative difference
#: (points_table.csv holds six digits).
SAME_FREQUENCY = 1e-4
#: points.csv's coherences with the excitation, and their headers in the report.
POINT_COHERENCES = {"coherence_ry": "coherence r->y", "coherence_ru": "coherence r->u"}


def points_html(table, points, models, axis, flags):
    """The paper-style points table (:func:`..records.points.read_points_table`, written as identify
    writes it), and beside each point what else the folder knows of it: its coherences with
    the excitation (points.csv), the recommended model's replay error and, for a simulated
    sweep, its error against the simulator's truth (models.json). Flags low coherence, and
    points and a recommended model further from the truth than the accuracy
    (:func:`_truth_flags`)."""
    freqs = table.freq_hz
    columns = _point_columns(freqs, points, models)
    digits = {"phase_deg": ".4f", "coherence": ".5f"}
    rows = [[format(table.column(c)[i], digits.get(c, ".6g")) for c in TABLE_COLUMNS]
            + [cells[i] for _, cells in columns] for i in range(freqs.size)]
    for i, (f, coherence) in enumerate(zip(freqs, table.coherence)):
        if coherence < LOW_COHERENCE:
            each = "".join(f", {name} {cells[i]}" for name, cells in columns
                           if name.startswith("coherence "))
            flags.append(f"{axis}: low coherence {coherence:.2f} at {f:.3g} Hz{each}")
    _truth_flags(models, axis, flags)
    return ("<h3>Frequency response (the paper's tables 4-6, then the checks of each point)</h3>"
            + table_html(list(TABLE_COLUMNS) + [name for name, _ in columns], rows))


def _point_columns(freqs, points, models):
    """The columns after the paper's: ``(header, cells)`` for what points.csv (``points``,
    :class:`~heliquad.host.records.points.FrequencyPoint`, or None) and models.json hold of
    the points at ``freqs`` (Hz)."""
    columns = []
    if points:
        rows = [{"freq_hz": p.freq_hz, **{k: getattr(p, k) for k in POINT_COHERENCES}}
                for p in points]
        columns += [(name, _column(freqs, rows, key, ".4f"))
                    for key, name in POINT_COHERENCES.items()
                    if known_column(points, key) is not None]
    replay = models and models.replay
    if replay and models.recommended is not None:
        columns.append(("replay error %", _column(freqs, replay["points"], "nrmse", ".3g", 100)))
    truth = models and models.sil_truth
    if truth:
        columns += [(name, _column(freqs, truth["points"], key, spec))
                    for key, name, spec in (("error_db", "truth error dB", ".3f"),
                                            ("error_deg", "truth error deg", ".2f"),
                                            ("error_over_sigma", "truth error / sigma", ".2f"))]
    return columns


def _column(freqs, entries, key, spec, factor=1.0):
    """The cells of ``key`` (times ``factor``) of ``entries`` (objects with ``freq_hz``) at
    each of ``freqs``, matched to the tables' six digits; "-" where none matches or the
    value is not known."""
    at_hz = np.array([e["freq_hz"] for e in entries], float)
    cells = []
    for f in freqs:
        i = int(np.argmin(np.abs(at_hz - f))) if at_hz.size else -1
        value = entries[i].get(key) if i >= 0 and abs(at_hz[i] - f) <= SAME_FREQUENCY * f \
            else None
        cells.append(number_text(None if value is None else factor * float(value), spec))
    return cells


def beyond_accuracy(db, deg) -> bool:
    """Whether an error (dB, deg; None: not known) is beyond :data:`ACCURACY_DB` or
    :data:`ACCURACY_DEG`."""
    return (db is not None and abs(db) > ACCURACY_DB) or \
        (deg is not None and abs(deg) > ACCURACY_DEG)


def _accuracy_text() -> str:
    return f"{ACCURACY_DB:g} dB or {ACCURACY_DEG:g} deg"


def _truth_flags(models, axis, flags):
    """A simulated sweep's (``sil_truth``: a board has no truth): one flag for the points
    further from the simulator's truth than the accuracy (:data:`ACCURACY_DB`,
    :data:`ACCURACY_DEG`), naming the worst; one when the recommended model is, somewhere in
    the band."""
    truth = models and models.sil_truth
    if not truth:
        return
    far = [p for p in truth["points"] if beyond_accuracy(p.get("error_db"), p.get("error_deg"))]
    if far:
        worst = max(far, key=lambda p: max(abs(p.get("error_db") or 0) / ACCURACY_DB,
                                           abs(p.get("error_deg") or 0) / ACCURACY_DEG))
        flags.append(f"{axis}: {len(far)} of {len(truth['points'])} points are further than "
                     f"{_accuracy_text()} from the simulator's truth (the worst, "
                     f"{worst['freq_hz']:.3g} Hz: {number_text(worst.get('error_db'), '.2f')} dB, "
                     f"{number_text(worst.get('error_deg'), '.1f')} deg): those frequencies were "
                     "measured wrongly; look at their coherence, saturation and responses, and "
                     "measure them again")
    db, deg = truth.get("model_worst_db"), truth.get("model_worst_deg")
    if models.recommended is not None and beyond_accuracy(db, deg):
        flags.append(f"{axis}: the recommended model is up to {number_text(db, '.2f')} dB and "
                     f"{number_text(deg, '.1f')} deg from the simulator's truth across the band, "
                     f"beyond the {_accuracy_text()} a controller design can take: do not design "
                     "on it; try other orders (or a delay), or measure more frequencies")
