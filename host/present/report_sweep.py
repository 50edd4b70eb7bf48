"""The report's sweep section: where and how a sweep ran (its source and settings, the
signal, the gains flown, the log) and the frequencies it tried; flags those not measured or
saturated and a sweep stopped early."""

from __future__ import annotations

import html
import math

from ..acquire.measure import saturation_text
from ..acquire.redesign import passes_sigmas
from ..acquire.sweep import cut_text
from .report_html import number_text, table_html


def signal_text(manifest) -> str:
    """Which excitation the sweep used, in words (a manifest from before multisines has no
    ``signal``: a dwell)."""
    design = manifest.get("design") or {}
    if manifest.get("signal") != "multisine":
        n = sum(1 for f in manifest.get("frequencies", []) if f.get("status") == "ok")
        return f"dwell, one sine at a time ({n} frequencies measured)"
    return (f"multisine, {len(design.get('orders', []))} lines "
            f"{number_text(design.get('freqs_hz', [math.nan])[0])}-"
            f"{number_text(design.get('freqs_hz', [math.nan])[-1])} Hz on harmonics of "
            f"{number_text(design.get('base_hz'))} Hz, {design.get('periods')} periods, peak "
            f"{number_text(design.get('peak'))}, crest factor "
            f"{number_text(design.get('crest_factor'))}, "
            f"{number_text(design.get('duration_s'))} s of excitation")


def sweep_html(manifest, axis, flags):
    """The session's source and the frequencies tried; flags those not measured and an
    early end (not those superseded: measured again with a better amplitude)."""
    text = "<h3>Sweep</h3>" + table_html(None, _source_rows(manifest), left=(0, 1), cls="source")
    cut = cut_text(manifest)
    if cut:
        text += f"<p><b>{html.escape(cut[0].upper() + cut[1:])}.</b></p>"
    rows = [(number_text(f.get("requested_hz")), number_text(f.get("freq_hz")),
             f.get("period_samples", "-"), f.get("samples", 0), _lost_cell(f),
             f.get("garbage_bytes", "-"), f.get("status"))
            for f in manifest.get("frequencies", [])]
    text += "<h3>Frequencies</h3>" + table_html(
        ["requested (Hz)", "used (Hz)", "period (samples)", "samples", "lost on the link",
         "garbage bytes", "status"], rows, left=(6,))
    text += "".join(_lines_html(f, manifest)
                    for f in manifest.get("frequencies", []) if f.get("line_sdr"))
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


def _lines_html(entry, manifest) -> str:
    """A sequential multisine's lines: each one's frequency, its point's sigma (share of its
    magnitude) and its signal-to-disturbance ratio in the output, and how many lines the
    rig-time cap left above the target (said, not flagged: the points' sigmas carry it to
    the fit, and the model's checks say whether it matters). A redesigned second pass also
    gives each line's relative amplitude and its sigma with the first pass's combined."""
    target = ((manifest.get("design") or {}).get("sequential") or {}).get("target_sigma")
    sigmas, sdrs = entry.get("line_sigma") or [None] * len(entry["line_sdr"]), entry["line_sdr"]
    first = entry.get("redesign_of")
    judged = sigmas if first is None else passes_sigmas([manifest["frequencies"][first], entry])
    pct = lambda v: "-" if v is None else f"{100 * v:.2g} %"        # noqa: E731
    rows = [(number_text(h * entry["freq_hz"]), h, pct(sigma), "-" if sdr is None else f"{sdr:.3g}")
            for h, sigma, sdr in zip(entry.get("orders", []), sigmas, sdrs)]
    head = ["line (Hz)", "harmonic", "sigma / magnitude", "signal / disturbance (output)"]
    if first is not None:
        rows = [(*row, f"{w:.2g}", pct(c)) for row, w, c in zip(rows, entry["weights"], judged)]
        head += ["amplitude (of the median)", "sigma, both passes"]
    above = [s for s in judged if s is not None and target is not None and s > target]
    end = {"cap": "the rig-time cap", "target": "every line at its target"}.get(
        entry.get("multisine_end"), entry.get("multisine_end") or "-")
    said = (f"<p>{entry.get('periods', '-')} base periods; ended by {html.escape(end)}"
            + (f"; {len(above)} of {len(judged)} lines above the target sigma "
               f"({100 * target:g} %)" if above else "") + ".</p>")
    title = "Multisine lines" + ("" if not _redesigned(manifest) else
                                 " (second pass, redesigned)" if first is not None else
                                 " (first pass)")
    return f"<h3>{title}</h3>" + said + table_html(head, rows)


def _redesigned(manifest) -> bool:
    return bool(((manifest.get("design") or {}).get("redesign")))


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


#: What a rate or angle sweep measured (manifest.json ``response``), in words.
RESPONSE_TEXT = {"plant": "; measured: the plant, the mixer's input to the rate, both "
                          "against the excitation",
                 "loop": "; measured: the loop, the setpoint to its response"}


def _source_rows(manifest) -> list:
    """The sweep's settings as (what, value) rows: where it ran, the axis and injection, the
    signal, the gains the board flew, the tool, when, the log."""
    src = manifest.get("source") or {}
    rows = [("axis, injection", f"{manifest.get('axis')}, {manifest.get('inject')} injection"
             + RESPONSE_TEXT.get(manifest.get("response"), ""))]
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


def loop_rate_hz(manifest):
    """The control loop's rate of a sweep (freq_hz x period_samples of its frequencies), Hz;
    None when the manifest does not give one."""
    rates = {round(f["freq_hz"] * f["period_samples"], 3) for f in manifest.get("frequencies", [])
             if f.get("freq_hz") and f.get("period_samples")}
    return rates.pop() if len(rates) == 1 else None
