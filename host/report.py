"""``heliquad report DIR``: one self-contained HTML page of an identification session.

DIR is a sweep folder (manifest.json, after ``heliquad identify`` and optionally
``heliquad validate``), or a folder of such folders (one per axis). The page holds every
table (frequencies, the paper-style points table, models and their metrics, validation),
every plot (embedded as PNG data, so the file stands alone), and the quality flags:
low-coherence points, unstable or degenerate models, no recommended model, aborted
frequencies, an unstable cascade.
"""

from __future__ import annotations

import base64
import datetime
import html
import json
import math
import os

from .errors import InputError
from .files import atomic_write
from .sweep import saturation_text

__all__ = ["write_report", "LOW_COHERENCE"]

LOW_COHERENCE = 0.6
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
    from .files import read_manifest, read_models_json, read_points_table, read_validation

    manifest = _read(read_manifest, os.path.join(folder, "manifest.json")) or {}
    models = _read(read_models_json, os.path.join(folder, "models.json"))
    validation = _read(read_validation, os.path.join(folder, "validation.json"))
    table = _read(read_points_table, os.path.join(folder, "points_table.csv"))
    axis = manifest.get("axis") or (models or {}).get("axis") or os.path.basename(folder)
    flags, parts = [], [f"<h2>{html.escape(str(axis))}</h2>"]
    if manifest:
        parts.append(_sweep_html(manifest, axis, flags))
    if table is not None:
        parts.append(_points_html(table, axis, flags))
    if models:
        parts.append(_models_html(models, axis, flags))
    parts.append(_img(os.path.join(folder, "bode.png"), f"{axis} Bode plot"))
    parts.append(_img(os.path.join(folder, "responses.png"), f"{axis} time responses"))
    if validation:
        parts.append(_validation_html(validation, axis, flags))
        parts.append(_img(os.path.join(folder, "validation.png"), f"{axis} validation"))
    return "".join(parts), flags


def _sweep_html(manifest, axis, flags):
    """The session's source and the frequencies tried; flags those not measured and an
    early end."""
    src = manifest.get("source", {})
    text = (f"<p>Injection: <b>{html.escape(str(manifest.get('inject')))}</b>; source: "
            f"{html.escape(json.dumps(src))}; firmware {html.escape(str(manifest.get('firmware')))}; "
            f"started {html.escape(str(manifest.get('started')))}; gains "
            f"{html.escape(json.dumps(manifest.get('gains')))}.</p>")
    rows = [(_fmt(f.get("requested_hz")), _fmt(f.get("freq_hz")), f.get("period_samples", "-"),
             f.get("samples", 0), f.get("status")) for f in manifest.get("frequencies", [])]
    text += "<h3>Frequencies</h3>" + _table(
        ["requested (Hz)", "used (Hz)", "period (samples)", "samples", "status"], rows, left=(4,))
    for f in manifest.get("frequencies", []):
        if f["status"] != "ok":
            flags.append(f"{axis}: {f['requested_hz']:.3g} Hz {f['status']}")
        elif saturation_text(f):
            flags.append(f"{axis}: {f['requested_hz']:.3g} Hz:{saturation_text(f)}")
    if manifest.get("aborted"):
        flags.append(f"{axis}: sweep stopped: {manifest['aborted']}")
    return text


def _points_html(table, axis, flags):
    """The paper-style points table (:func:`.files.read_points_table`, written as identify
    writes it); flags low coherence."""
    from .files import TABLE_COLUMNS

    digits = {"phase_deg": ".4f", "coherence": ".5f"}
    rows = [[format(table[c][i], digits.get(c, ".6g")) for c in TABLE_COLUMNS]
            for i in range(table["freq_hz"].size)]
    for f, coherence in zip(table["freq_hz"], table["coherence"]):
        if coherence < LOW_COHERENCE:
            flags.append(f"{axis}: low coherence {coherence:.2f} at {f:.3g} Hz")
    return ("<h3>Frequency response (the paper's tables 4-6)</h3>"
            + _table(list(TABLE_COLUMNS), rows))


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
        rows.append(("*" if i == rec else "", f"{m['order'][0]}/{m['order'][1]}", _fmt(k.get("J"), ".3g"),
                     _fmt(100 * k["rms"], ".3g") if k.get("rms") is not None else "-",
                     _fmt(k.get("aicc"), ".4g"), _fmt(k.get("max_mag_err_db"), ".3f"),
                     _fmt(k.get("max_phase_err_deg"), ".2f"),
                     "yes" if m.get("stable") else "NO", "yes" if m.get("degenerate") else "", tf))
        if not m.get("stable"):
            flags.append(f"{axis}: model {m['order'][0]}/{m['order'][1]} is unstable")
    if rec is None:
        flags.append(f"{axis}: no model recommended")
    return ("<h3>Models</h3>" + _table(
        ["", "order", "J", "rms %", "AICc", "max dB", "max deg", "stable", "degenerate", "G(s)"],
        rows, left=(9,)) + f"<p>Recommended: {html.escape(str(models.get('reason')))}</p>")


def _validation_html(validation, axis, flags):
    """The loops' margins, then the time responses, or where the cascade goes unstable
    (flagged)."""
    rows = [(name, _fmt(lp.get("gain_margin_db"), ".3g"), _fmt(lp.get("phase_margin_deg"), ".3g"),
             _fmt(lp.get("gain_crossover_rad_s"), ".3g"), "stable" if lp["closed_loop_stable"] else "UNSTABLE")
            for name, lp in validation["loops"].items()]
    text = "<h3>Closed-loop validation</h3>" + _table(
        ["loop", "gain margin (dB)", "phase margin (deg)", "crossover (rad/s)", "closed loop"], rows)
    if validation["stable"]:
        st, sn = validation["step"], validation["sine"]
        tb = validation.get("turbulence", {})
        return text + (f"<p>Step {st['size']:g} {html.escape(st['unit'])}: rise "
                       f"{_fmt(st.get('rise_time_s'), '.2f')} s, overshoot "
                       f"{_fmt(st.get('overshoot_pct'), '.1f')} %, settling "
                       f"{_fmt(st.get('settling_time_s'), '.2f')} s. Sine {sn['freq_hz']:g} Hz: "
                       f"tracking RMS {_fmt(sn.get('tracking_rms'), '.3g')} "
                       f"({_fmt(sn.get('tracking_rms_pct'), '.0f')} %)."
                       + (f" {html.escape(tb['level'])} turbulence: rate RMS "
                          f"{tb['rate_rms_deg_s']:.2f} deg/s from gusts of "
                          f"{tb['gust_rate_rms_deg_s']:.1f} deg/s." if tb else "") + "</p>")
    from .validate import instability_text

    why = instability_text(validation) if "instability" in validation else \
        "the cascade is unstable with these gains"
    flags.append(f"{axis}: {why}")
    return text + f"<p>{html.escape(why[0].upper() + why[1:])}.</p>"


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
