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
"""

from __future__ import annotations

import base64
import datetime
import html
import math
import os

import numpy as np

from ...sim.base.errors import InputError
from ...sim.base.firmware_facts import MAX_FREQ_FRACTION
from ..records.output import atomic_write
from ..acquire.sweep import cut_text
from ..acquire.measure import saturation_text
from ..estimate.thresholds import (ACCURACY_DB, ACCURACY_DEG, LOW_COHERENCE, ROUND_OFF_SIGMA,
                                honest_sigma_bound)

__all__ = ["write_report"]

#: Two frequencies of one folder's files are the same point within this relative difference
#: (points_table.csv holds six digits).
SAME_FREQUENCY = 1e-4
#: points.csv's coherences with the excitation, and their headers in the report.
POINT_COHERENCES = {"coherence_ry": "coherence r->y", "coherence_ru": "coherence r->u"}
#: models.json's ``estimate``, in words.
ESTIMATES = {"excitation": "Points estimated against the logged excitation r: G = (Y/R) / (U/R), "
                           "unbiased with the loop closed.",
             "input": "Points estimated against the measured input u (the direct estimate, "
                      "right for open-loop data; biased when the loop is closed and the air moves)."}
STYLE = """body{font-family:sans-serif;margin:2em;max-width:1100px;color:#222}
table{border-collapse:collapse;margin:0.5em 0 1.5em;font-size:0.9em}
td,th{border:1px solid #bbb;padding:3px 8px;text-align:right}th{background:#eee}
td.l,th.l{text-align:left}.flag{color:#a00;font-weight:bold}.ok{color:#070}
.note{color:#735200}.bad{color:#a00;font-weight:bold}.good{color:#070;font-weight:bold}
.caution{color:#735200;font-weight:bold}table.summary{font-size:1em;width:100%}
table.summary td,table.summary th{vertical-align:top;text-align:left;padding:6px 8px}
table.summary td:nth-child(2){white-space:nowrap}
table.source td{text-align:left}table.source th{text-align:left;font-weight:normal}
.small{font-size:0.85em;color:#555}
img{max-width:100%;border:1px solid #ddd;margin:0.5em 0}h2{border-bottom:2px solid #ccc}"""


def _read(reader, path):
    """A folder's file through its reader (host/records): None when it is not there; a
    damaged one is an InputError (a report must not quietly leave out what it cannot read)."""
    return reader(path) if os.path.lexists(path) else None


def _img(path, alt):
    if not os.path.exists(path):
        return ""
    with open(path, "rb") as fh:
        data = base64.b64encode(fh.read()).decode()
    return f'<img alt="{html.escape(alt)}" src="data:image/png;base64,{data}">'


def _table(header, rows, left=(), cls=None, raw=()):
    """An HTML table: ``header`` then ``rows``; columns in ``left`` aligned left; cells of
    columns in ``raw`` are HTML already (everything else is escaped)."""
    out = [f'<table{f" class={chr(34)}{cls}{chr(34)}" if cls else ""}>'
           + ("<tr>" + "".join(f"<th>{html.escape(h)}</th>" for h in header) + "</tr>"
              if header else "")]
    for row in rows:
        cells = [(c if i in raw else html.escape(str(c)), ' class="l"' if i in left else "")
                 for i, c in enumerate(row)]
        out.append("<tr>" + "".join(f"<td{a}>{c}</td>" for c, a in cells) + "</tr>")
    return "".join(out) + "</table>"


def _fmt(x, spec=".4g"):
    return "-" if x is None or (isinstance(x, float) and not math.isfinite(x)) else format(x, spec)


def _axis_section(folder) -> dict:
    """One axis's part of the page: ``{"axis", "body" (HTML), "flags" (quality flags, to act
    on), "notes" ((what is not validated, the next step) pairs), "summary" (what the page's
    summary shows of it)}``: the sweep, the points, the models, the plots and the
    validation, each as far as the folder holds it."""
    from ..records.manifest import read_manifest
    from ..records.models import read_models_json
    from ..records.points import read_points_csv, read_points_table
    from ..records.validation import read_validation

    manifest = _read(read_manifest, os.path.join(folder, "manifest.json")) or {}
    models = _read(read_models_json, os.path.join(folder, "models.json"))
    validation = _read(read_validation, os.path.join(folder, "validation.json"))
    table = _read(read_points_table, os.path.join(folder, "points_table.csv"))
    points = _read(read_points_csv, os.path.join(folder, "points.csv"))
    axis = manifest.get("axis") or (models or {}).get("axis") or os.path.basename(folder)
    flags, notes = [], []
    parts = [f'<h2 id="axis-{html.escape(str(axis))}">{html.escape(str(axis))}</h2>']
    if manifest:
        parts.append(_sweep_html(manifest, axis, flags))
    if table is not None:
        parts.append(_points_html(table, points, models or {}, axis, flags))
    if models:
        parts.append(_models_html(models, axis, flags))
        parts.append(_checks_html(models, points))
    parts.append(_img(os.path.join(folder, "bode.png"), f"{axis} Bode plot"))
    parts.append(_img(os.path.join(folder, "responses.png"), f"{axis} time responses"))
    if validation:
        parts.append(_validation_html(validation, axis, flags, notes, _loop_hz(manifest)))
        parts.append(_img(os.path.join(folder, "validation.png"), f"{axis} validation"))
    return {"axis": str(axis), "body": "".join(parts), "flags": flags, "notes": notes,
            "summary": _summary(models)}


def _loop_hz(manifest):
    """The control loop's rate of a sweep (freq_hz x period_samples of its frequencies), Hz;
    None when the manifest does not give one."""
    rates = {round(f["freq_hz"] * f["period_samples"], 3) for f in manifest.get("frequencies", [])
             if f.get("freq_hz") and f.get("period_samples")}
    return rates.pop() if len(rates) == 1 else None


def _summary(models) -> dict:
    """What the page's summary says of an axis's models: the recommended model (None when
    there is none), its fit to the points, and its worst error against the simulator's
    truth across the band (None on a board)."""
    rec = (models or {}).get("recommended")
    if rec is None:
        return {"model": None, "fit": None, "truth": None}
    truth = models.get("sil_truth") or {}
    worst = (truth.get("model_worst_db"), truth.get("model_worst_deg"))
    quality = models.get("quality") or {}
    fit = models["models"][rec].get("metrics", {}).get("J")
    return {"model": models["models"][rec],
            "fit": f"{quality.get('level', 'fit')}: J = {_fmt(fit, '.2g')}",
            "truth": worst if None not in worst else None}


def signal_text(manifest) -> str:
    """Which excitation the sweep used, in words (a manifest from before multisines has no
    ``signal``: a dwell)."""
    design = manifest.get("design") or {}
    if manifest.get("signal") != "multisine":
        n = sum(1 for f in manifest.get("frequencies", []) if f.get("status") == "ok")
        return f"dwell, one sine at a time ({n} frequencies measured)"
    return (f"multisine, {len(design.get('orders', []))} lines "
            f"{_fmt(design.get('freqs_hz', [math.nan])[0])}-"
            f"{_fmt(design.get('freqs_hz', [math.nan])[-1])} Hz on harmonics of "
            f"{_fmt(design.get('base_hz'))} Hz, {design.get('periods')} periods, peak "
            f"{_fmt(design.get('peak'))}, crest factor {_fmt(design.get('crest_factor'))}, "
            f"{_fmt(design.get('duration_s'))} s of excitation")


def _sweep_html(manifest, axis, flags):
    """The session's source and the frequencies tried; flags those not measured and an
    early end (not those superseded: measured again with a better amplitude)."""
    text = "<h3>Sweep</h3>" + _table(None, _source_rows(manifest), left=(0, 1), cls="source")
    cut = cut_text(manifest)
    if cut:
        text += f"<p><b>{html.escape(cut[0].upper() + cut[1:])}.</b></p>"
    rows = [(_fmt(f.get("requested_hz")), _fmt(f.get("freq_hz")), f.get("period_samples", "-"),
             f.get("samples", 0), _lost_cell(f), f.get("garbage_bytes", "-"), f.get("status"))
            for f in manifest.get("frequencies", [])]
    text += "<h3>Frequencies</h3>" + _table(
        ["requested (Hz)", "used (Hz)", "period (samples)", "samples", "lost on the link",
         "garbage bytes", "status"], rows, left=(6,))
    for f in manifest.get("frequencies", []):
        if f["status"].startswith("superseded"):
            continue             # the sequential design measured it again: nothing is wrong
        if f["status"] != "ok":
            flags.append(f"{axis}: {f['requested_hz']:.3g} Hz {f['status']}")
        elif saturation_text(f):
            flags.append(f"{axis}: {f['requested_hz']:.3g} Hz:{saturation_text(f)}")
    if manifest.get("aborted"):
        flags.append(f"{axis}: sweep stopped: {manifest['aborted']}")
    return text


#: A simulated sweep's source, in words: its keys (manifest.json ``source``) and how each
#: reads; a key not here is listed as it is.
SIL_SOURCE = (("plant", "plant", lambda v: {"vehicle": "the simulated 6-DoF vehicle on its rig",
                                            "tf": "a transfer function"}.get(v, v)),
              ("num", "numerator", None), ("den", "denominator", None),
              ("params", "vehicle parameters", lambda v: v or "the shipped ones"),
              ("turbulence", "air", lambda v: f"{v} Dryden turbulence" if v else "still"),
              ("ideal_sensor", "sensor", lambda v: "ideal" if v else
               "IMU model (noise, bias, latency)"),
              ("seed", "seed", None), ("collective", "collective", None),
              ("faults", "faults injected", None),
              ("firmware", "firmware in the loop", lambda v: " ".join(
                  str(x) for x in (v.get("name"), v.get("executable")) if x)
               if isinstance(v, dict) else v))


def _source_rows(manifest) -> list:
    """The sweep's settings as (what, value) rows: where it ran, the axis and injection, the
    signal, the gains the board flew, the tool, when, the log."""
    src = manifest.get("source") or {}
    rows = [("axis, injection", f"{manifest.get('axis')}, {manifest.get('inject')} injection")]
    if src.get("kind") == "port":
        rows.append(("source", f"a board on {src.get('port')} at {src.get('baud')} baud"))
    elif src.get("kind") == "sil":
        rows.append(("source", "simulation (SIL)"))
    known = {"kind", "port", "baud"}
    for key, name, text in SIL_SOURCE if src.get("kind") == "sil" else ():
        if key in src and not (key in ("num", "den") and src.get("plant") != "tf"):
            rows.append((name, _value_text(text(src[key]) if text else src[key])))
        known.add(key)
    rows += [(key, _value_text(v)) for key, v in src.items() if key not in known]
    rows += [("signal", signal_text(manifest)), ("gains flown", _gains_text(manifest.get("gains"))),
             ("tool", manifest.get("firmware") or "-"), ("started", manifest.get("started") or "-"),
             ("log", f"{manifest.get('tlog') or '-'}"
              + ("" if manifest.get("complete", True) else " (not complete)"))]
    return rows


def _value_text(value) -> str:
    """A manifest value in words: lists joined, objects as key: value, null as "-"."""
    if value is None:
        return "-"
    if isinstance(value, (list, tuple)):
        return ", ".join(_value_text(v) for v in value) or "-"
    if isinstance(value, dict):
        return "; ".join(f"{k}: {_value_text(v)}" for k, v in value.items()) or "-"
    return f"{value:.6g}" if isinstance(value, float) else str(value)


def _gains_text(gains) -> str:
    """The cascade gains a sweep flew (``{"rate": [Kc, tau_I, tau_D], "angle": [Kc, tau_D]}``)
    in words; "not read" when the board sent none."""
    if not isinstance(gains, dict):
        return "not read from the board (validation assumes the firmware's defaults)"
    names = {"rate": ("Kc", "tau_I", "tau_D"), "angle": ("Kc", "tau_D")}
    out = []
    for loop, values in gains.items():
        if isinstance(values, (list, tuple)) and len(values) == len(names.get(loop, ())):
            out.append(f"{loop} loop " + ", ".join(
                f"{n} {v:g}{' s' if n != 'Kc' else ''}" for n, v in zip(names[loop], values)))
        elif values is not None:
            out.append(f"{loop} loop {_value_text(values)}")
    return "; ".join(out) or "-"


def _lost_cell(entry) -> str:
    """A frequency's samples lost on the link: ``N (x %)``, or "-" where the manifest
    predates the count."""
    if "lost" not in entry:
        return "-"
    total = entry.get("samples", 0) + entry["lost"]
    return f"{entry['lost']} ({100 * entry['lost'] / total:.1f} %)" if total else "0"


def _points_html(table, points, models, axis, flags):
    """The paper-style points table (:func:`~heliquad.host.records.points.read_points_table`, written as identify
    writes it), and beside each point what else the folder knows of it: its coherences with
    the excitation (points.csv), the recommended model's replay error and, for a simulated
    sweep, its error against the simulator's truth (models.json). Flags low coherence, and
    points and a recommended model further from the truth than the accuracy
    (:func:`_truth_flags`)."""
    from ..records.points import TABLE_COLUMNS

    freqs = table["freq_hz"]
    columns = _point_columns(freqs, points, models)
    digits = {"phase_deg": ".4f", "coherence": ".5f"}
    rows = [[format(table[c][i], digits.get(c, ".6g")) for c in TABLE_COLUMNS]
            + [cells[i] for _, cells in columns] for i in range(freqs.size)]
    for i, (f, coherence) in enumerate(zip(freqs, table["coherence"])):
        if coherence < LOW_COHERENCE:
            each = "".join(f", {name} {cells[i]}" for name, cells in columns
                           if name.startswith("coherence "))
            flags.append(f"{axis}: low coherence {coherence:.2f} at {f:.3g} Hz{each}")
    _truth_flags(models, axis, flags)
    return ("<h3>Frequency response (the paper's tables 4-6, then the checks of each point)</h3>"
            + _table(list(TABLE_COLUMNS) + [name for name, _ in columns], rows))


def _point_columns(freqs, points, models):
    """The columns after the paper's: ``(header, cells)`` for what points.csv and
    models.json hold of the points at ``freqs`` (Hz)."""
    columns = []
    if points is not None:
        rows = [{"freq_hz": w / (2 * math.pi), **{k: points[k][i] for k in POINT_COHERENCES
                                                  if points.get(k) is not None}}
                for i, w in enumerate(points["omega"])]
        columns += [(name, _column(freqs, rows, key, ".4f"))
                    for key, name in POINT_COHERENCES.items() if points.get(key) is not None]
    replay = models.get("replay")
    if replay and models.get("recommended") is not None:
        columns.append(("replay error %", _column(freqs, replay["points"], "nrmse", ".3g", 100)))
    truth = models.get("sil_truth")
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
        cells.append(_fmt(None if value is None else factor * float(value), spec))
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
    truth = models.get("sil_truth")
    if not truth:
        return
    far = [p for p in truth["points"] if beyond_accuracy(p.get("error_db"), p.get("error_deg"))]
    if far:
        worst = max(far, key=lambda p: max(abs(p.get("error_db") or 0) / ACCURACY_DB,
                                           abs(p.get("error_deg") or 0) / ACCURACY_DEG))
        flags.append(f"{axis}: {len(far)} of {len(truth['points'])} points are further than "
                     f"{_accuracy_text()} from the simulator's truth (the worst, "
                     f"{worst['freq_hz']:.3g} Hz: {_fmt(worst.get('error_db'), '.2f')} dB, "
                     f"{_fmt(worst.get('error_deg'), '.1f')} deg): those frequencies were "
                     "measured wrongly; look at their coherence, saturation and responses, and "
                     "measure them again")
    db, deg = truth.get("model_worst_db"), truth.get("model_worst_deg")
    if models.get("recommended") is not None and beyond_accuracy(db, deg):
        flags.append(f"{axis}: the recommended model is up to {_fmt(db, '.2f')} dB and "
                     f"{_fmt(deg, '.1f')} deg from the simulator's truth across the band, beyond "
                     f"the {_accuracy_text()} a controller design can take: do not design on it; "
                     "try other orders (or a delay), or measure more frequencies")


def _models_html(models, axis, flags):
    """The models with their metrics and the recommendation; flags a damaged log, unused
    frequencies, unstable models and no recommendation."""
    log = models.get("log") or {}
    if log.get("skipped_bytes") or log.get("stamps_out_of_order") or \
            log.get("stamps_not_loop_time"):
        flags.append(f"{axis}: the log is damaged: {log.get('skipped_bytes', 0)} bytes "
                     f"skipped in {log.get('damaged_regions', 0)} places, "
                     f"{log.get('stamps_out_of_order', 0)} timestamps out of order, "
                     f"{log.get('stamps_not_loop_time', 0)} not their control loop's time")
    for text in models.get("skipped_frequencies") or []:
        flags.append(f"{axis}: {text} (not used)")
    rec = models.get("recommended")
    rows = []
    for i, m in enumerate(models["models"]):
        k = m.get("metrics", {})
        tf = f"[{', '.join(f'{c:.5g}' for c in m['num'])}] / [{', '.join(f'{c:.5g}' for c in m['den'])}]"
        if m.get("delay_s"):
            tf += f" * exp(-{m['delay_s']:.4g} s)"
        rows.append(("*" if i == rec else "", _order(m), _fmt(k.get("J"), ".3g"),
                     _fmt(100 * k["rms"], ".3g") if k.get("rms") is not None else "-",
                     _fmt(k.get("aicc"), ".4g"), _fmt(k.get("max_mag_err_db"), ".3f"),
                     _fmt(k.get("max_phase_err_deg"), ".2f"),
                     "yes" if m.get("stable") else "NO",
                     (m.get("degenerate_why") or "yes") if m.get("degenerate") else "", tf))
        if not m.get("stable"):
            flags.append(f"{axis}: model {m['order'][0]}/{m['order'][1]} is unstable")
    if rec is None:
        flags.append(f"{axis}: no model recommended")
    elif (models.get("quality") or {}).get("level") == "poor":
        flags.append(f"{axis}: the recommended model fits its points poorly "
                     f"({models['quality'].get('why')}); try other orders, or look at the points")
    return ("<h3>Models</h3>" + _table(
        ["", "order", "J", "rms %", "AICc", "max dB", "max deg", "stable", "degenerate", "G(s)"],
        rows, left=(9,)) + f"<p>Recommended: {html.escape(str(models.get('reason')))}</p>")


def _checks_html(models, points=None):
    """How the points were estimated, the recommended model's replay and, for a simulated
    sweep, how far the points and the model are from the simulator's truth, with the
    points' error/sigma statistic (:func:`_sigma_text`)."""
    said = []
    if models.get("estimate"):
        said.append(ESTIMATES[models["estimate"]])
    replay = models.get("replay")
    if models.get("recommended") is None:
        said.append("No model is recommended, so none is replayed.")
    elif replay:
        errors = [100 * p["nrmse"] for p in replay["points"] if p.get("nrmse") is not None]
        said.append(f"Replay: each frequency's measured input (its mean period after "
                    f"{replay.get('discard_periods', 1)} discarded) through the recommended model "
                    f"({_order(models['models'][models['recommended']])}), its periodic steady "
                    f"state against the measured output (dashed in the responses): error "
                    + (f"{min(errors):.2g} to {max(errors):.2g} % of the output's RMS "
                       "(per frequency in the table above)." if errors else "not known."))
    truth = models.get("sil_truth")
    if truth:
        text = (f"Against the simulator's truth: the points within {truth['points_worst_db']:.2f} dB "
                f"and {truth['points_worst_deg']:.1f} deg")
        if truth.get("model_worst_db") is not None and models.get("recommended") is not None:
            text += (f"; the recommended model within {truth['model_worst_db']:.2f} dB and "
                     f"{_fmt(truth.get('model_worst_deg'), '.1f')} deg across the band")
        said.append(text + f" (the report's accuracy: {ACCURACY_DB:g} dB and {ACCURACY_DEG:g} "
                    "deg, an error that would change a controller designed on the model).")
        said.append(_sigma_text(truth, points))
    return "".join(f"<p>{html.escape(t)}</p>" for t in said if t)


def _sigma_text(truth, points) -> str:
    """The points' RMS error/sigma against the truth, as a statistic with what it says: how
    many of their own standard errors the points lie from the truth (about 1 when each
    point's sigma accounts for its whole error). Not read at all when the sigmas are
    round-off (:data:`ROUND_OFF_SIGMA`)."""
    z = truth.get("points_rms_error_over_sigma")
    if z is None:
        return ""
    text = (f"RMS error/sigma of the points: {z:.2f}, how many of their own standard errors "
            "(sigma, from the scatter between periods) the points lie from the truth: ")
    relative = None
    if points is not None and points.get("sigma") is not None:
        with np.errstate(all="ignore"):
            ratio = points["sigma"] / np.abs(points["F"])
        relative = float(np.median(ratio[np.isfinite(ratio)])) if np.any(np.isfinite(ratio)) \
            else None
    if relative is not None and relative < ROUND_OFF_SIGMA:
        return text + (f"not meaningful here, as the sigmas are round-off ({relative:.1g} of the "
                       "magnitude: a noise-free simulation has no scatter to measure).")
    n = len(points["sigma"]) if points is not None and points.get("sigma") is not None else 1
    if z <= honest_sigma_bound(n):
        return text + "about 1, as it should be: sigma accounts for each point's error."
    return text + (f"above 1, so the points carry a bias their scatter does not show (at most "
                   f"{truth['points_worst_db']:.2f} dB and {truth['points_worst_deg']:.1f} deg"
                   + (", within the accuracy" if not beyond_accuracy(
                       truth["points_worst_db"], truth["points_worst_deg"]) else "")
                   + "): weights and confidence bounds built on sigma are that much too "
                   "confident; the model is judged against the accuracy, not against sigma.")


def _order(model) -> str:
    """A models.json model's order, ``0/2``, ``0/2i`` (a pole at the origin) or ``0/2 + delay``."""
    from ..estimate.fit import order_name

    return order_name((*model["order"], int(bool(model.get("integrator"))))) + \
        (" + delay" if model.get("delay_s") else "")


#: The loops of validation.json and where each is broken, for the report.
LOOPS = {"rate": "rate loop: broken at the plant input, the angle loop open",
         "angle": "angle loop: broken at the rate setpoint, the rate loop closed",
         "input": "input loop: broken at the plant input, both loops closed"}
#: The model's margin and the simulator's truth's, in band, further apart than these are
#: flagged (dB, deg): the accuracy the model itself is judged by (a model within it cannot
#: move a margin by more).
TRUTH_MARGIN_DB, TRUTH_MARGIN_DEG = ACCURACY_DB, ACCURACY_DEG
#: A reported margin of a loop: (its name, its key, the key of its crossover, the list of
#: crossovers it is read at, its unit and format).
MARGINS = (("gain margin", "gain_margin_db", "phase_crossover_rad_s", "phase_crossovers",
            "dB", ".1f"),
           ("phase margin", "phase_margin_deg", "gain_crossover_rad_s", "gain_crossovers",
            "deg", ".1f"))


def _validation_html(validation, axis, flags, notes, loop_hz=None):
    """Each loop's margins (the model's, measured through the excitation, the simulator's
    truth) with what is not validated or not measured, then the time responses, or where
    the cascade goes unstable: flagged inside the identified band, a note (not validated)
    outside it. Flags margins in band the truth does not confirm; notes, in one line, the
    margins not validated (:func:`_margin_flags`)."""
    band = validation.get("band_rad_s")
    text = "<h3>Closed-loop validation</h3>"
    if band:
        text += (f"<p>The model was identified over {band[0]:.3g}-{band[1]:.3g} rad/s; a margin "
                 "whose crossover lies outside that band is not validated: the model has no "
                 "data there.</p>")
    text += "".join(_loop_html(name, lp, validation) for name, lp in validation["loops"].items())
    _margin_flags(validation, axis, flags, notes, loop_hz)
    if validation["stable"]:
        return text + _responses_html(validation)
    from ..validate.closed_loop import instability_text

    why = instability_text(validation) if "instability" in validation else \
        "the cascade is unstable with these gains"
    if (validation.get("instability") or {}).get("outside_band"):
        said, _, step = why.partition("; ")
        notes.append((f"{axis}: {said}", step or "check on the rig"))
    else:
        flags.append(f"{axis}: {why}")
    return text + f"<p>{html.escape(why[0].upper() + why[1:])}.</p>"


def _loop_html(name, lp, validation):
    """One loop's table: the model's margins (those read outside the band marked not
    validated), those measured through the excitation when the sweep measured this loop, the
    simulator's truth's when known; then the sentences on what is not measured."""
    note = "stable" if lp["closed_loop_stable"] else "UNSTABLE"
    out = [m for m, *_ in MARGINS if _in_band(lp, m) is False]
    if out:
        note += f"; {' and '.join(out)} not validated (read outside the band)"
    rows = [("model", *_margin_cells(lp), note)]
    said = []
    measured = validation.get("measured_loop")
    if measured and measured.get("loop") == name:
        points = measured.get("points") or []
        hz = [p["freq_hz"] for p in points]
        reach = (f", {len(hz)} points, {2 * math.pi * min(hz):.3g}-{2 * math.pi * max(hz):.3g} "
                 "rad/s" if hz else "")
        rows.append(("measured through the excitation",
                     *_margin_cells(measured, "not measured", "not measured"),
                     f"{measured.get('injection')} injection{reach}"))
        said += [f"not measured: {why}" for why in measured.get("unmeasured", [])]
    truth = validation.get("truth_loops", {}).get(name)
    if truth:
        rows.append(("simulator's truth", *_margin_cells(truth), ""))
    return (f"<h4>{html.escape(LOOPS.get(name, name))}</h4>"
            + _table(["", "gain margin (dB)", "at (rad/s)", "phase margin (deg)", "at (rad/s)",
                      "closed loop / note"], rows, left=(0, 5))
            + "".join(f"<p>{html.escape(s[0].upper() + s[1:])}.</p>" for s in said))


def _margin_cells(lp, no_gm="inf", no_pm="none"):
    """A loop's gain margin (dB; ``no_gm`` without a phase crossover), phase margin (deg;
    ``no_pm`` without a gain crossover) and where each is read (rad/s)."""
    gm, pm = lp.get("gain_margin_db"), lp.get("phase_margin_deg")
    return (no_gm if gm is None else _fmt(gm, ".3g"), _fmt(lp.get("phase_crossover_rad_s"), ".3g"),
            no_pm if pm is None else _fmt(pm, ".3g"), _fmt(lp.get("gain_crossover_rad_s"), ".3g"))


def _in_band(lp, margin):
    """Whether a loop's ``margin`` (a name of :data:`MARGINS`) is read inside the identified
    band, by its crossover's ``in_band``; None when the loop has no such margin or the file
    lists no crossovers."""
    _, _, at_key, list_key, _, _ = next(m for m in MARGINS if m[0] == margin)
    at = lp.get(at_key)
    match = [c for c in lp.get(list_key) or [] if c.get("omega_rad_s") == at]
    return bool(match[0].get("in_band")) if at is not None and match else None


def _margin_flags(validation, axis, flags, notes, loop_hz=None):
    """A flag for each margin read in band that the simulator's truth puts further than
    :data:`TRUTH_MARGIN_DB` or :data:`TRUTH_MARGIN_DEG` away; one note for all the margins
    of the model not validated, naming them by loop and the sweep that would measure
    them."""
    out, truths = {}, validation.get("truth_loops", {})
    for name, lp in validation["loops"].items():
        for margin, key, at_key, _, unit, spec in MARGINS:
            where = _in_band(lp, margin)
            if where is False:
                out.setdefault(name, []).append((margin, lp[at_key]))
            truth = truths.get(name, {}).get(key)
            limit = TRUTH_MARGIN_DB if unit == "dB" else TRUTH_MARGIN_DEG
            if where and truth is not None and abs(lp[key] - truth) > limit:
                flags.append(f"{axis}: the {name} loop's {margin} is {lp[key]:{spec}} {unit} on "
                             f"the model and {truth:{spec}} {unit} on the simulator's truth, "
                             f"more than {limit:g} {unit} apart, inside the identified band")
    if out:
        notes.append(_margins_note(axis, out, validation["band_rad_s"], loop_hz))


def _margins_note(axis, out, band, loop_hz=None) -> tuple:
    """The note on margins read outside the identified band ``band`` (rad/s): ``out``, per
    loop, (margin, rad/s where it is read); and the next step: the sweep that would measure
    them, in Hz as ``--freqs-hz`` takes them, within what the firmware excites at the
    sweep's loop rate ``loop_hz`` (the crossovers above it are for the rig)."""
    at = [w for each in out.values() for _, w in each]
    lo, hi = min(band[0], *at), max(band[1], *at)
    text = (f"{axis}: {len(at)} margin{'s' if len(at) > 1 else ''} not validated, read outside "
            f"the identified band ({band[0]:.3g}-{band[1]:.3g} rad/s) where the model has no "
            "data: " + "; ".join(f"{name} loop " + ", ".join(f"{m} at {w:.3g} rad/s"
                                                              for m, w in each)
                                 for name, each in out.items()))
    return text, _sweep_step(lo, hi, loop_hz)


def _sweep_step(lo, hi, loop_hz) -> str:
    """The sweep that covers ``lo``-``hi`` rad/s, cut at the firmware's highest excitation
    frequency at a ``loop_hz`` loop (what lies above it no sweep can measure)."""
    top = math.inf if loop_hz is None else 2 * math.pi * MAX_FREQ_FRACTION * loop_hz
    step = (f"sweep {lo / (2 * math.pi):.2g}-{min(hi, top) / (2 * math.pi):.2g} Hz "
            f"({lo:.3g}-{min(hi, top):.3g} rad/s) to measure the margins there")
    if hi > top:
        step += (f"; those above {top / (2 * math.pi):.3g} Hz (the most the firmware excites "
                 f"at its {loop_hz:g} Hz loop) only on the rig")
    return step


def _responses_html(validation):
    """The step, the sine tracking and the turbulence rejection, in a paragraph."""
    st, sn = validation["step"], validation["sine"]
    tb = validation.get("turbulence", {})
    return (f"<p>Step {st['size']:g} {html.escape(st['unit'])}: rise "
            f"{_fmt(st.get('rise_time_s'), '.2f')} s, overshoot "
            f"{_fmt(st.get('overshoot_pct'), '.1f')} %, settling "
            f"{_fmt(st.get('settling_time_s'), '.2f')} s. Sine {sn['freq_hz']:g} Hz: "
            f"tracking RMS {_fmt(sn.get('tracking_rms'), '.3g')} {html.escape(st['unit'])} "
            f"({_fmt(sn.get('tracking_rms_pct'), '.0f')} %)."
            + (f" {html.escape(tb['level'])} turbulence: rate RMS "
               f"{tb['rate_rms_deg_s']:.2f} deg/s from gusts of "
               f"{tb['gust_rate_rms_deg_s']:.1f} deg/s." if tb else "") + "</p>")


def _tf_html(model) -> str:
    """A models.json model as HTML: ``num / (den)`` in powers of s, its delay as e^(-T s)."""
    def poly(c):
        n, terms = len(c) - 1, []
        for i, v in enumerate(c):
            p = n - i
            power = f"s<sup>{p}</sup>" if p > 1 else "s" if p == 1 else ""
            coef = "" if (v == 1 and p) else f"{abs(v):.4g}"
            terms.append(("- " if v < 0 else "+ ") + " ".join(t for t in (coef, power) if t))
        return " ".join(terms).lstrip("+ ")
    num, den = poly(model["num"]), poly(model["den"])
    text = (f"({num})" if len(model["num"]) > 1 else num) + f" / ({den})"
    if model.get("delay_s"):
        text += f" e<sup>-{1e3 * model['delay_s']:.3g} ms &middot; s</sup>"
    return text


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
                 f"{_tf_html(s['model'])}<br><span class=\"small\">"
                 f"{html.escape(_order(s['model']))}, {html.escape(s['fit'])}</span>")
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
    return "<h2>Summary</h2>" + _table(header, rows, raw=range(len(header)), cls="summary")


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


def write_report(dir_path: str, out: str | None = None) -> str:
    """Write DIR/report.html (or ``out``); returns its path."""
    from ..records.output import check_output

    if not os.path.isdir(dir_path):
        raise InputError(f"{dir_path}: not a folder")
    out = out or os.path.join(dir_path, "report.html")
    check_output(out, "--out")
    folders = [dir_path] if os.path.exists(os.path.join(dir_path, "models.json")) else sorted(
        os.path.join(dir_path, d) for d in os.listdir(dir_path)
        if os.path.exists(os.path.join(dir_path, d, "models.json")))
    if not folders:
        raise InputError(f"{dir_path}: no models.json here or in its sub-folders (run heliquad identify first)")
    axes = [_axis_section(folder) for folder in folders]
    stamp = datetime.datetime.now(datetime.timezone.utc).strftime("%Y-%m-%d %H:%M UTC")
    page = (f"<!DOCTYPE html><html><head><meta charset='utf-8'><title>heliquad report</title>"
            f"<style>{STYLE}</style></head><body><h1>heliquad identification report</h1>"
            f"<p>{html.escape(os.path.abspath(dir_path))}, written {stamp}.</p>"
            + _summary_html(axes) + _flags_html(axes)
            + "".join(ax["body"] for ax in axes) + "</body></html>")
    with atomic_write(out) as fh:
        fh.write(page)
    return out
