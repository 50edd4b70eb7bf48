"""``heliquad report DIR``: one self-contained HTML page of an identification session.

DIR is a sweep folder (manifest.json, after ``heliquad identify`` and optionally
``heliquad validate``), or a folder of such folders (one per axis). The page holds every
table (frequencies, the paper-style points table with each point's coherences with the
excitation, the recommended model's replay error and, for a simulated sweep, its error
against the simulator's truth; models and their metrics, how the points were estimated, the
replay and the truth in a line each; validation: each loop's margins, the model's beside those
measured through the excitation and the simulator's truth's), every plot (embedded as PNG
data, so the file stands alone), and the quality flags: low-coherence points, points further
than 3 sigma from the simulator's truth, unstable models, no recommended model, a damaged
log, frequencies not measured, not used or saturated, an unstable cascade, margins read
outside the identified band (not validated), and margins read inside it that the simulator's
truth puts more than 1 dB or 3 deg away.
"""

from __future__ import annotations

import base64
import datetime
import html
import json
import math
import os

import numpy as np

from .errors import InputError
from .files import atomic_write
from .sweep import cut_text, saturation_text

__all__ = ["write_report", "LOW_COHERENCE"]

#: A point whose coherence is below this is flagged (and drawn as the gate in bode.png).
LOW_COHERENCE = 0.6
#: A simulated sweep's point further than this many of its sigmas from the truth is flagged.
TRUTH_SIGMAS = 3.0
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
td.l{text-align:left}.flag{color:#a00;font-weight:bold}.ok{color:#070}
img{max-width:100%;border:1px solid #ddd;margin:0.5em 0}h2{border-bottom:2px solid #ccc}"""


def _read(reader, path):
    """A folder's file through its reader (:mod:`.files`): None when it is not there; a
    damaged one is an InputError (a report must not quietly leave out what it cannot read)."""
    return reader(path) if os.path.lexists(path) else None


def _img(path, alt):
    if not os.path.exists(path):
        return ""
    with open(path, "rb") as fh:
        data = base64.b64encode(fh.read()).decode()
    return f'<img alt="{html.escape(alt)}" src="data:image/png;base64,{data}">'


def _table(header, rows, left=()):
    out = ["<table><tr>" + "".join(f"<th>{html.escape(h)}</th>" for h in header) + "</tr>"]
    for row in rows:
        cells = [f'<td class="l">{html.escape(str(c))}</td>' if i in left else f"<td>{html.escape(str(c))}</td>"
                 for i, c in enumerate(row)]
        out.append("<tr>" + "".join(cells) + "</tr>")
    return "".join(out) + "</table>"


def _fmt(x, spec=".4g"):
    return "-" if x is None or (isinstance(x, float) and not math.isfinite(x)) else format(x, spec)


def _axis_section(folder):
    """One axis's part of the page and its quality flags: the sweep, the points, the models,
    the plots and the validation, each as far as the folder holds it."""
    from .files import (read_manifest, read_models_json, read_points_csv, read_points_table,
                        read_validation)

    manifest = _read(read_manifest, os.path.join(folder, "manifest.json")) or {}
    models = _read(read_models_json, os.path.join(folder, "models.json"))
    validation = _read(read_validation, os.path.join(folder, "validation.json"))
    table = _read(read_points_table, os.path.join(folder, "points_table.csv"))
    points = _read(read_points_csv, os.path.join(folder, "points.csv"))
    axis = manifest.get("axis") or (models or {}).get("axis") or os.path.basename(folder)
    flags, parts = [], [f"<h2>{html.escape(str(axis))}</h2>"]
    if manifest:
        parts.append(_sweep_html(manifest, axis, flags))
    if table is not None:
        parts.append(_points_html(table, points, models or {}, axis, flags))
    if models:
        parts.append(_models_html(models, axis, flags))
        parts.append(_checks_html(models))
    parts.append(_img(os.path.join(folder, "bode.png"), f"{axis} Bode plot"))
    parts.append(_img(os.path.join(folder, "responses.png"), f"{axis} time responses"))
    if validation:
        parts.append(_validation_html(validation, axis, flags))
        parts.append(_img(os.path.join(folder, "validation.png"), f"{axis} validation"))
    return "".join(parts), flags


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
    src = manifest.get("source", {})
    text = (f"<p>Injection: <b>{html.escape(str(manifest.get('inject')))}</b>; source: "
            f"{html.escape(json.dumps(src))}; firmware {html.escape(str(manifest.get('firmware')))}; "
            f"started {html.escape(str(manifest.get('started')))}; gains "
            f"{html.escape(json.dumps(manifest.get('gains')))}.</p>")
    text += f"<p>Signal: {html.escape(signal_text(manifest))}.</p>"
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


def _lost_cell(entry) -> str:
    """A frequency's samples lost on the link: ``N (x %)``, or "-" where the manifest
    predates the count."""
    if "lost" not in entry:
        return "-"
    total = entry.get("samples", 0) + entry["lost"]
    return f"{entry['lost']} ({100 * entry['lost'] / total:.1f} %)" if total else "0"


def _points_html(table, points, models, axis, flags):
    """The paper-style points table (:func:`.files.read_points_table`, written as identify
    writes it), and beside each point what else the folder knows of it: its coherences with
    the excitation (points.csv), the recommended model's replay error and, for a simulated
    sweep, its error against the simulator's truth (models.json). Flags low coherence and
    points further than :data:`TRUTH_SIGMAS` sigma from the truth."""
    from .files import TABLE_COLUMNS

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
    _truth_flags(models.get("sil_truth"), axis, flags)
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


def _truth_flags(truth, axis, flags):
    """One flag for the points further than :data:`TRUTH_SIGMAS` of their sigma from the
    simulator's truth (a simulated sweep's ``sil_truth`` only: a board has no truth)."""
    if not truth:
        return
    far = [p for p in truth["points"] if (p.get("error_over_sigma") or 0) > TRUTH_SIGMAS]
    if far:
        worst = max(far, key=lambda p: p["error_over_sigma"])
        flags.append(f"{axis}: {len(far)} of {len(truth['points'])} points are more than "
                     f"{TRUTH_SIGMAS:g} sigma from the simulator's truth (the worst, "
                     f"{worst['freq_hz']:.3g} Hz: "
                     f"{worst['error_over_sigma']:.1f} sigma, {_fmt(worst.get('error_db'), '.3f')} dB, "
                     f"{_fmt(worst.get('error_deg'), '.2f')} deg)")


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
    return ("<h3>Models</h3>" + _table(
        ["", "order", "J", "rms %", "AICc", "max dB", "max deg", "stable", "degenerate", "G(s)"],
        rows, left=(9,)) + f"<p>Recommended: {html.escape(str(models.get('reason')))}</p>")


def _checks_html(models):
    """How the points were estimated, the recommended model's replay and, for a simulated
    sweep, how far the points and the model are from the simulator's truth."""
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
        z = truth.get("points_rms_error_over_sigma")
        text = (f"Against the simulator's truth: the points within {truth['points_worst_db']:.2f} dB "
                f"and {truth['points_worst_deg']:.1f} deg"
                + (f" (RMS error/sigma {z:.2f}, about 1 when sigma is honest)" if z is not None else ""))
        if truth.get("model_worst_db") is not None and models.get("recommended") is not None:
            text += (f"; the recommended model within {truth['model_worst_db']:.2f} dB and "
                     f"{_fmt(truth.get('model_worst_deg'), '.1f')} deg across the band")
        said.append(text + ".")
    return "".join(f"<p>{html.escape(t)}</p>" for t in said)


def _order(model) -> str:
    """A models.json model's order, ``0/2``, ``0/2i`` (a pole at the origin) or ``0/2 + delay``."""
    from .fit import order_name

    return order_name((*model["order"], int(bool(model.get("integrator"))))) + \
        (" + delay" if model.get("delay_s") else "")


#: The loops of validation.json and where each is broken, for the report.
LOOPS = {"rate": "rate loop: broken at the plant input, the angle loop open",
         "angle": "angle loop: broken at the rate setpoint, the rate loop closed",
         "input": "input loop: broken at the plant input, both loops closed"}
#: The model's margin and the simulator's truth's, in band, further apart than these are
#: flagged (dB, deg).
TRUTH_MARGIN_DB, TRUTH_MARGIN_DEG = 1.0, 3.0
#: A reported margin of a loop: (its name, its key, the key of its crossover, the list of
#: crossovers it is read at, its unit and format).
MARGINS = (("gain margin", "gain_margin_db", "phase_crossover_rad_s", "phase_crossovers",
            "dB", ".1f"),
           ("phase margin", "phase_margin_deg", "gain_crossover_rad_s", "gain_crossovers",
            "deg", ".1f"))


def _validation_html(validation, axis, flags):
    """Each loop's margins (the model's, measured through the excitation, the simulator's
    truth) with what is not validated or not measured, then the time responses, or where
    the cascade goes unstable (flagged); flags margins not validated and, in band, margins
    the truth does not confirm."""
    band = validation.get("band_rad_s")
    text = "<h3>Closed-loop validation</h3>"
    if band:
        text += (f"<p>The model was identified over {band[0]:.3g}-{band[1]:.3g} rad/s; a margin "
                 "whose crossover lies outside that band is not validated: the model has no "
                 "data there.</p>")
    text += "".join(_loop_html(name, lp, validation) for name, lp in validation["loops"].items())
    _margin_flags(validation, axis, flags)
    if validation["stable"]:
        return text + _responses_html(validation)
    from .validate import instability_text

    why = instability_text(validation) if "instability" in validation else \
        "the cascade is unstable with these gains"
    flags.append(f"{axis}: {why}")
    return text + f"<p>{html.escape(why[0].upper() + why[1:])}.</p>"


def _loop_html(name, lp, validation):
    """One loop's table: the model's margins, those measured through the excitation when
    the sweep measured this loop, the simulator's truth's when known; then the sentences
    on what is not validated or not measured."""
    note = "stable" if lp["closed_loop_stable"] else "UNSTABLE"
    out = [m for m, *_ in MARGINS if _in_band(lp, m) is False]
    if out:
        note += f"; {' and '.join(out)} not validated"
    rows = [("model", *_margin_cells(lp), note)]
    said = [f"not validated: {why}" for why in lp.get("not_validated", [])]
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


def _margin_flags(validation, axis, flags):
    """One flag when any margin of the model is not validated, naming them and where their
    crossovers lie; one for each margin read in band that the simulator's truth puts
    further than :data:`TRUTH_MARGIN_DB` or :data:`TRUTH_MARGIN_DEG` away."""
    out, truths = [], validation.get("truth_loops", {})
    for name, lp in validation["loops"].items():
        for margin, key, at_key, _, unit, spec in MARGINS:
            where = _in_band(lp, margin)
            if where is False:
                out.append((name, margin, lp[at_key]))
            truth = truths.get(name, {}).get(key)
            limit = TRUTH_MARGIN_DB if unit == "dB" else TRUTH_MARGIN_DEG
            if where and truth is not None and abs(lp[key] - truth) > limit:
                flags.append(f"{axis}: the {name} loop's {margin} is {lp[key]:{spec}} {unit} on "
                             f"the model and {truth:{spec}} {unit} on the simulator's truth, "
                             f"more than {limit:g} {unit} apart, inside the identified band")
    if out:
        lo, hi = validation["band_rad_s"]
        at = [w for _, _, w in out]
        each = ", ".join(f"the {name} loop's {margin} at {w:.3g} rad/s" for name, margin, w in out)
        flags.append(f"{axis}: {len(out)} margin{'s' if len(out) > 1 else ''} not validated, read "
                     f"outside the identified band ({lo:.3g}-{hi:.3g} rad/s) where the model has "
                     f"no data: {each}; a sweep covering {min(lo, *at):.3g}-{max(hi, *at):.3g} "
                     "rad/s would measure the model there")


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


def write_report(dir_path: str, out: str | None = None) -> str:
    """Write DIR/report.html (or ``out``); returns its path."""
    from .files import check_output

    if not os.path.isdir(dir_path):
        raise InputError(f"{dir_path}: not a folder")
    out = out or os.path.join(dir_path, "report.html")
    check_output(out, "--out")
    folders = [dir_path] if os.path.exists(os.path.join(dir_path, "models.json")) else sorted(
        os.path.join(dir_path, d) for d in os.listdir(dir_path)
        if os.path.exists(os.path.join(dir_path, d, "models.json")))
    if not folders:
        raise InputError(f"{dir_path}: no models.json here or in its sub-folders (run heliquad identify first)")
    sections, flags = [], []
    for folder in folders:
        body, f = _axis_section(folder)
        sections.append(body)
        flags += f
    flag_html = ("<ul>" + "".join(f'<li class="flag">{html.escape(f)}</li>' for f in flags) + "</ul>"
                 if flags else '<p class="ok">No quality flags: coherence, stability and the sweeps are all fine.</p>')
    stamp = datetime.datetime.now(datetime.timezone.utc).strftime("%Y-%m-%d %H:%M UTC")
    page = (f"<!DOCTYPE html><html><head><meta charset='utf-8'><title>heliquad report</title>"
            f"<style>{STYLE}</style></head><body><h1>heliquad identification report</h1>"
            f"<p>{html.escape(os.path.abspath(dir_path))}, written {stamp}.</p><h2>Quality flags</h2>{flag_html}"
            + "".join(sections) + "</body></html>")
    with atomic_write(out) as fh:
        fh.write(page)
    return out
