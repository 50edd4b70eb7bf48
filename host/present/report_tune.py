"""The report's tuning section: a ``heliquad tune`` folder (tune.json, and once ``heliquad
verify`` ran, verify.json) shown as before and after, per axis: the gains, each loop's
crossover and margins as the model predicts them with the current gains and with the tuned
ones, then, where the gains were flown, the margins measured on the rig through the
excitation (and the simulator's truth on the simulated rig), each loop's verdict and what
the board holds; the predicted step and turbulence; the sentences the tuner and the
verification said; the figure. Reads the two documents; computes nothing it does not show."""

from __future__ import annotations

import html
import math
import os

from ..records.tune import LOOP_KEYS, read_tune
from ..records.verify import read_verify
from .report_html import image_html, number_text, table_html

__all__ = ["tune_html", "TUNE", "VERIFY"]

#: The files of a tune folder.
TUNE, VERIFY = "tune.json", "verify.json"


def _gains_text(g) -> str:
    rate = ", ".join(number_text(v) for v in g["rate"])
    angle = g.get("angle")
    return f"rate [{rate}]" + ("" if angle is None else
                               f", angle [{', '.join(number_text(v) for v in angle)}]")


def _margins(lp) -> str:
    """``crossover rad/s: PM deg / GM dB`` of a loop record (``-`` where there is none)."""
    if not lp:
        return "-"
    return (f"{number_text(lp.get('gain_crossover_rad_s'), '.3g')} rad/s: "
            f"{number_text(lp.get('phase_margin_deg'), '.1f')} deg / "
            f"{number_text(lp.get('gain_margin_db'), '.1f')} dB")


def _measured(check, key) -> str:
    """A verified loop's measured (or truth's) margins, or what kept them from being read."""
    if check is None:
        return "not flown"
    lp = check.get(key)
    if lp is None:
        return "not measured"
    text = _margins(lp)
    if lp.get("unmeasured"):
        text += " (" + "; ".join(lp["unmeasured"]) + ")"
    return text


def _verdict(check) -> str:
    if check is None:
        return ""
    if check["passed"]:
        return "<span class='good'>passed</span>"
    return ("<span class='bad'>failed</span>: "
            + html.escape("; ".join(check["failures"]) or "see verify.json"))


def _step_rows(axis_tune) -> list:
    """The predicted step and turbulence rejection, current against tuned."""
    rows = []
    cur, tun = axis_tune["current"].get("step") or {}, axis_tune["tuned"].get("step") or {}
    if cur or tun:
        unit = tun.get("unit") or cur.get("unit") or ""
        size = tun.get("size") or cur.get("size")
        rows += [[f"step of {number_text(size, 'g')} {unit}: rise 10-90 % (s)",
                  number_text(cur.get("rise_time_s"), ".3f"), number_text(tun.get("rise_time_s"), ".3f")],
                 ["step: overshoot (%)", number_text(cur.get("overshoot_pct"), ".1f"),
                  number_text(tun.get("overshoot_pct"), ".1f")],
                 ["step: peak axis command", number_text(cur.get("peak_command"), ".2f"),
                  number_text(tun.get("peak_command"), ".2f")]]
    cur, tun = (axis_tune["current"].get("disturbance") or {},
                axis_tune["tuned"].get("disturbance") or {})
    if cur or tun:
        rows.append([f"{tun.get('level') or cur.get('level')} turbulence: rate RMS (deg/s)",
                     number_text(cur.get("rate_rms_deg_s"), ".3g"),
                     number_text(tun.get("rate_rms_deg_s"), ".3g")])
    return rows


def _axis_html(axis, entry, checked, folder) -> str:
    """One axis: the models it was designed on, gains and predicted loops, current against
    tuned, and the verification."""
    loops = [k for k in LOOP_KEYS if k in entry["tuned"]["loops"]]
    rows = [["gains", _gains_text(entry["current"]["gains"]), _gains_text(entry["tuned"]["gains"])]]
    rows += [[f"{name} loop (crossover: phase / gain margin)",
              _margins(entry["current"]["loops"].get(name)),
              _margins(entry["tuned"]["loops"].get(name))] for name in loops]
    rows += _step_rows(entry)
    meets = entry.get("meets_spec")
    text = (f"<h3>{html.escape(axis)}</h3>" + _models_html(entry, folder)
            + table_html(["predicted by the model", "current", "tuned"], rows, left=(0,))
            + ("" if meets is None else
               f"<p class='{'ok' if meets else 'flag'}'>The tuned gains "
               f"{'meet' if meets else 'do not meet'} the specification in prediction.</p>"))
    if checked is not None:
        text += _verification_html(checked, loops)
    said = entry.get("said") or []
    if said:
        text += "<ul>" + "".join(f"<li class='note'>{html.escape(s)}</li>" for s in said) + "</ul>"
    return text


def _models_html(entry, folder) -> str:
    """Which models the axis was designed on and the band they were identified over."""
    path, band = entry.get("models"), entry.get("band_rad_s")
    if not path or not band:
        return ""
    where = os.path.relpath(os.path.join(folder, path), os.path.dirname(os.path.abspath(folder)))
    lo, hi = band
    return (f"<p>Designed on {html.escape(where)}, identified over {lo:.3g}-{hi:.3g} rad/s "
            f"({lo / (2 * math.pi):.3g}-{hi / (2 * math.pi):.3g} Hz).</p>")


def _verification_html(v, loops) -> str:
    """The verification of one axis: per loop predicted, measured and truth, its verdict."""
    rows = []
    for name in loops:
        check = v["loops"].get(name)
        if check is None:
            continue
        allowed, extrapolated = check["allowed"], check["predicted"].get("extrapolated", ())
        held = [("extrapolated: the spec only" if key in extrapolated else
                 f"{number_text(allowed[key], '.1f')} {unit}")
                for key, unit in (("phase_margin_deg", "deg"), ("gain_margin_db", "dB"))]
        rows.append([name, _margins(check["predicted"]), " / ".join(held),
                     _measured(check, "measured"),
                     _measured(check, "truth") if "truth" in check else "-", _verdict(check)])
    verdict = v["verdict"]
    cls = {"accepted": "ok", "rejected": "flag"}.get(verdict, "note")
    holds = {"tuned": "the tuned gains", "previous": "its previous gains",
             "unknown": "gains not known (the link was lost while they were set)"}[v["board_holds"]]
    text = (f"<p class='{cls}'>On the rig ({html.escape(v['board'])}, {html.escape(v['started'])})"
            f": {html.escape(verdict)}; the board holds {holds}.</p>")
    if rows:
        text += table_html(["loop", "predicted", "allowed difference", "measured",
                            "simulator's truth", "verdict"], rows, left=(0, 5), raw=(5,))
    said = v.get("said") or []
    if said:
        text += "<ul>" + "".join(f"<li class='note'>{html.escape(s)}</li>" for s in said) + "</ul>"
    return text


def tune_html(folder: str) -> str:
    """The section of a folder holding tune.json (and verify.json once verified)."""
    tune = read_tune(os.path.join(folder, TUNE))
    verify_path = os.path.join(folder, VERIFY)
    verified = read_verify(verify_path).axes if os.path.exists(verify_path) else {}
    spec = tune.spec
    head = (f"<h2>Tuning: {html.escape(os.path.basename(os.path.abspath(folder)))}</h2>"
            f"<p>Gains designed from the identified models (heliquad tune) to a phase margin of "
            f"at least {number_text(spec.get('phase_margin_deg'), 'g')} deg and a gain margin of "
            f"at least {number_text(spec.get('gain_margin_db'), 'g')} dB at every crossover"
            + (", then flown on the rig and measured through the excitation (heliquad verify)"
               if verified else "; not yet flown (heliquad verify proves them on the rig)")
            + ".</p>")
    body = "".join(_axis_html(axis, entry, verified.get(axis), folder)
                   for axis, entry in tune.axes.items())
    return head + body + image_html(os.path.join(folder, "tune.png"), "current and tuned loops")
