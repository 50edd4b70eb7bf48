"""``heliquad report DIR``: one self-contained HTML page of an identification session.

DIR is a sweep folder (manifest.json, after ``heliquad identify`` and optionally
``heliquad validate``), or a folder of such folders (one per axis). The page opens with a
summary, one row per axis: the recommended model, its error against the simulator's truth
(a simulated sweep's), the verdict and the next step. Then the quality flags: only what a
user must act on, each saying what is wrong: low-coherence points, points or a recommended
model further from the simulator's truth than :data:`ACCURACY_DB` / :data:`ACCURACY_DEG`, a
recommended model that fits its points poorly, unstable models, no recommended model, a
damaged log, frequencies not measured, not used or saturated, a sweep stopped early, a
cascade unstable inside the identified band, margins read inside it that the truth puts
further away than the same accuracy. Then what this session does not validate (not wrong,
not checked), one line per axis with the sweep that would check it: margins read outside
the identified band, a cascade unstable only there. Then each axis: the sweep's source and
settings as a table, every table (frequencies, the paper-style points table with each
point's coherences with the excitation, the recommended model's replay error and, for a
simulated sweep, its error against the simulator's truth; models and their metrics; how
the points were estimated, the replay and the truth in a line each, with the points'
error/sigma statistic and what it means; validation: each loop's margins, the model's beside
those measured through the excitation and the simulator's truth's), and every plot
(embedded as PNG data, so the file stands alone).

The sections live beside this module: the HTML primitives and style (:mod:`.report_html`),
the sweep (:mod:`.report_sweep`), the points (:mod:`.report_points`), the models
(:mod:`.report_models`), their checks (:mod:`.report_checks`) and the closed-loop
validation (:mod:`.report_validation`); a folder of ``heliquad effectiveness`` (here or among
the sub-folders) adds each rotor's identified effectiveness against the geometry's
(:mod:`.report_effectiveness`), and a folder of ``heliquad tune`` its gains before and after,
predicted and, once ``heliquad verify`` flew them, measured (:mod:`.report_tune`). This module reads a folder, assembles the page and gives each
axis its summary and verdict.
"""

from __future__ import annotations

import datetime
import html
import os

from ...sim.base.errors import InputError
from ..estimate.thresholds import ACCURACY_DB, ACCURACY_DEG
from ..records.manifest import read_manifest
from ..records.models import read_models_json
from ..records.output import atomic_write, check_output
from ..records.points import read_points_csv, read_points_table
from ..records.validation import read_validation
from .report_checks import checks_html
from .report_effectiveness import effectiveness_html, read_effectiveness
from .report_html import STYLE, image_html, number_text, table_html
from .report_models import models_html, order_text, tf_html
from .report_points import points_html
from .report_tune import TUNE, tune_html
from .report_sweep import loop_rate_hz, sweep_html
from .report_validation import validation_html

__all__ = ["write_report"]


def _read(reader, path):
    """A folder's file through its reader (:mod:`..records`): None when it is not there; a
    damaged one is an InputError (a report must not quietly leave out what it cannot read)."""
    return reader(path) if os.path.lexists(path) else None


def _axis_section(folder) -> dict:
    """One axis's part of the page: ``{"axis", "body" (HTML), "flags" (quality flags, to act
    on), "notes" ((what is not validated, the next step) pairs), "summary" (what the page's
    summary shows of it)}``: the sweep, the points, the models, the plots and the
    validation, each as far as the folder holds it."""
    manifest = _read(read_manifest, os.path.join(folder, "manifest.json")) or {}
    models = _read(read_models_json, os.path.join(folder, "models.json"))
    validation = _read(read_validation, os.path.join(folder, "validation.json"))
    table = _read(read_points_table, os.path.join(folder, "points_table.csv"))
    points = _read(read_points_csv, os.path.join(folder, "points.csv"))
    axis = manifest.get("axis") or (models and models.axis) or os.path.basename(folder)
    flags, notes = [], []
    parts = [f'<h2 id="axis-{html.escape(str(axis))}">{html.escape(str(axis))}</h2>']
    if manifest:
        parts.append(sweep_html(manifest, axis, flags))
    if table is not None:
        parts.append(points_html(table, points, models, axis, flags))
    if models:
        parts.append(models_html(models, axis, flags))
        parts.append(checks_html(models, points))
    parts.append(image_html(os.path.join(folder, "bode.png"), f"{axis} Bode plot"))
    parts.append(image_html(os.path.join(folder, "responses.png"), f"{axis} time responses"))
    if validation:
        parts.append(validation_html(validation, axis, flags, notes, loop_rate_hz(manifest)))
        parts.append(image_html(os.path.join(folder, "validation.png"), f"{axis} validation"))
    return {"axis": str(axis), "body": "".join(parts), "flags": flags, "notes": notes,
            "summary": _summary(models)}


def _summary(models) -> dict:
    """What the page's summary says of an axis's models: the recommended model (None when
    there is none), its fit to the points, and its worst error against the simulator's
    truth across the band (None on a board)."""
    rec = None if models is None else models.recommended
    if rec is None:
        return {"model": None, "fit": None, "truth": None}
    truth = models.sil_truth or {}
    worst = (truth.get("model_worst_db"), truth.get("model_worst_deg"))
    quality = models.quality or {}
    fit = models.models[rec].metrics.get("J")
    return {"model": models.models[rec],
            "fit": f"{quality.get('level', 'fit')}: J = {number_text(fit, '.2g')}",
            "truth": worst if None not in worst else None}


def _verdict(ax) -> tuple:
    """``(css class, verdict, what it rests on, next step)`` of an axis, from its summary,
    flags and notes."""
    s, flags, notes = ax["summary"], ax["flags"], ax["notes"]
    if flags:
        n = len(flags)
        return ("bad", "no model to design on" if s["model"] is None else "check first",
                f"{n} quality flag{'s' if n > 1 else ''}",
                "act on the flag" + ("s" if n > 1 else "") + " below")
    if s["model"] is None:
        return "bad", "no model to design on", "", "look at the points and the models below"
    why = (f"within the {ACCURACY_DB:g} dB and {ACCURACY_DEG:g} deg a design needs"
           if s["truth"] is not None else f"fits its points ({s['fit']})")
    if notes:
        why += "; " + "; ".join(sorted({_not_validated_what(t) for t, _ in notes}))
    return ("good", "usable for design", why,
            "; ".join(step for _, step in notes) or "none: design on the model")


def _not_validated_what(note: str) -> str:
    """What a note says is not validated, in a few words."""
    return "the cascade's stability outside the band not validated" if "unstable" in note \
        else "margins outside the band not validated"


def _summary_html(axes) -> str:
    """The page's first screen: one row per axis (the model, its error against the
    simulator's truth when a sweep has one, the verdict, the next step)."""
    with_truth = any(ax["summary"]["truth"] is not None for ax in axes)
    rows = []
    for ax in axes:
        s = ax["summary"]
        cls, verdict, why, step = _verdict(ax)
        model = ("none" if s["model"] is None else
                 f"{tf_html(s['model'])}<br><span class=\"small\">"
                 f"{html.escape(order_text(s['model']))}, {html.escape(s['fit'])}</span>")
        name = html.escape(ax["axis"])
        row = [f'<a href="#axis-{name}"><b>{name}</b></a>', model]
        if with_truth:
            row.append("-" if s["truth"] is None else
                       f"{s['truth'][0]:.2f} dB, {s['truth'][1]:.1f} deg")
        rows.append(row + [f'<span class="{cls}">{html.escape(verdict)}</span>'
                           + (f'<br><span class="small">{html.escape(why)}</span>' if why else ""),
                           html.escape(step)])
    header = ["axis", "recommended model"] \
        + (["error against the simulator's truth (worst in the band)"] if with_truth else []) \
        + ["verdict", "next step"]
    return "<h2>Summary</h2>" + table_html(header, rows, raw=range(len(header)), cls="summary")


def _flags_html(axes) -> str:
    """The quality flags (to act on), then what the session does not validate."""
    flags = [f for ax in axes for f in ax["flags"]]
    notes = [n for ax in axes for n in ax["notes"]]
    against = (f" (accuracy {ACCURACY_DB:g} dB, {ACCURACY_DEG:g} deg against the simulator's "
               "truth)" if any(ax["summary"]["truth"] is not None for ax in axes) else "")
    out = "<h2>Quality flags</h2>"
    out += ("<ul>" + "".join(f'<li class="flag">{html.escape(f)}</li>' for f in flags) + "</ul>"
            if flags else '<p class="ok">No quality flags: the points, the models and the sweeps '
                          f"are all fine{html.escape(against)}.</p>")
    if notes:
        out += ("<h3>Not validated by this session</h3><ul>"
                + "".join(f'<li class="note">{html.escape(t)}.<br><b>Next:</b> '
                          f"{html.escape(step)}.</li>" for t, step in notes) + "</ul>")
    return out


#: What ``heliquad effectiveness`` writes: a folder holding it gets the effectiveness section.
EFFECTIVENESS = "effectiveness.json"


def _holding(dir_path: str, name: str) -> list:
    """DIR itself when it holds ``name``, else its sub-folders that do."""
    if os.path.exists(os.path.join(dir_path, name)):
        return [dir_path]
    return sorted(os.path.join(dir_path, d) for d in os.listdir(dir_path)
                  if os.path.exists(os.path.join(dir_path, d, name)))


def write_report(dir_path: str, out: str | None = None) -> str:
    """Write DIR/report.html (or ``out``); returns its path."""
    if not os.path.isdir(dir_path):
        raise InputError(f"{dir_path}: not a folder")
    out = out or os.path.join(dir_path, "report.html")
    check_output(out, "--out")
    folders, effectiveness = _holding(dir_path, "models.json"), _holding(dir_path, EFFECTIVENESS)
    tuned = _holding(dir_path, TUNE)
    if not folders and not effectiveness and not tuned:
        raise InputError(f"{dir_path}: no models.json, {EFFECTIVENESS} or {TUNE} here or in "
                         "its sub-folders (run heliquad identify, heliquad effectiveness or "
                         "heliquad tune first)")
    axes = [_axis_section(folder) for folder in folders]
    rotors = "".join(effectiveness_html(f, read_effectiveness(os.path.join(f, EFFECTIVENESS)))
                     for f in effectiveness)
    stamp = datetime.datetime.now(datetime.timezone.utc).strftime("%Y-%m-%d %H:%M UTC")
    page = (f"<!DOCTYPE html><html><head><meta charset='utf-8'><title>heliquad report</title>"
            f"<style>{STYLE}</style></head><body><h1>heliquad identification report</h1>"
            f"<p>{html.escape(os.path.abspath(dir_path))}, written {stamp}.</p>"
            + (_summary_html(axes) + _flags_html(axes) if axes else "")
            + "".join(ax["body"] for ax in axes) + "".join(tune_html(f) for f in tuned)
            + rotors + "</body></html>")
    with atomic_write(out) as fh:
        fh.write(page)
    return out
