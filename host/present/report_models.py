"""The report's models section: every model with its metrics and the recommendation, and a
model in words (its order) and in HTML (its transfer function); flags a damaged log, unused
frequencies, unstable models and no recommendation."""

from __future__ import annotations

import html

from ..estimate.fit import order_name
from .report_html import number_text, table_html


def models_html(models, axis, flags):
    """The models with their metrics and the recommendation; flags a damaged log, unused
    frequencies, unstable models and no recommendation."""
    log = models.log or {}
    if log.get("skipped_bytes") or log.get("stamps_out_of_order") or \
            log.get("stamps_not_loop_time"):
        flags.append(f"{axis}: the log is damaged: {log.get('skipped_bytes', 0)} bytes "
                     f"skipped in {log.get('damaged_regions', 0)} places, "
                     f"{log.get('stamps_out_of_order', 0)} timestamps out of order, "
                     f"{log.get('stamps_not_loop_time', 0)} not their control loop's time")
    for text in models.skipped_frequencies or []:
        flags.append(f"{axis}: {text} (not used)")
    rec = models.recommended
    rows = []
    for i, m in enumerate(models.models):
        k = m.metrics
        tf = f"[{', '.join(f'{c:.5g}' for c in m.num)}] / [{', '.join(f'{c:.5g}' for c in m.den)}]"
        if m.delay_s:
            tf += f" * exp(-{m.delay_s:.4g} s)"
        rows.append(("*" if i == rec else "", order_text(m), number_text(k.get("J"), ".3g"),
                     number_text(100 * k["rms"], ".3g") if k.get("rms") is not None else "-",
                     number_text(k.get("aicc"), ".4g"), number_text(k.get("max_mag_err_db"), ".3f"),
                     number_text(k.get("max_phase_err_deg"), ".2f"),
                     "yes" if m.stable else "NO",
                     (m.degenerate_why or "yes") if m.degenerate else "", tf))
        if not m.stable:
            flags.append(f"{axis}: model {m.order[0]}/{m.order[1]} is unstable")
    if rec is None:
        flags.append(f"{axis}: no model recommended")
    elif (models.quality or {}).get("level") == "poor":
        flags.append(f"{axis}: the recommended model fits its points poorly "
                     f"({models.quality.get('why')}); try other orders, or look at the points")
    cost = {"j": "CIFER's J", "relative": "the weighted relative error"}.get(models.cost)
    return ("<h3>Models</h3>" + table_html(
        ["", "order", "J", "rms %", "AICc", "max dB", "max deg", "stable", "degenerate", "G(s)"],
        rows, left=(9,)) + f"<p>Recommended: {html.escape(str(models.reason))}</p>"
        + (f"<p>Minimised: {cost}.</p>" if cost else "") + _record_html(models.record)
        + _linearity_html(models.linearity, axis, flags))


def _record_html(record) -> str:
    """What a record read as one (identify --from-record) was: its input, output, length
    and windows."""
    if not record:
        return ""
    return ("<p>From one record: " + html.escape(
        f"{record['output']} over {record['input']}, {record['duration_s']:.1f} s at "
        f"{record['rate_hz']:.4g} Hz, windows {', '.join(f'{w:.3g}' for w in record['windows_s'])}"
        f" s, against {'the excitation' if record['estimate'] == 'excitation' else 'the input'}")
        + ".</p>")


def _linearity_html(linearity, axis, flags) -> str:
    """A linearity campaign's verdicts per amplitude and its amplitude dependence; flags
    models fitted where the distortion is above the noise."""
    if not linearity:
        return ""
    rows = [(number_text(level["peak"], ".3g"), str(level["realisations"]),
             number_text(level["distortion_db"], ".1f"), number_text(level["noise_db"], ".1f"),
             f"{level['above_noise']} of {level['count']}",
             "FLAGGED" if level["flagged"] else "no") for level in linearity["levels"]]
    if linearity["flagged"]:
        flags.append(f"{axis}: the models are fitted where the nonlinear distortion is above "
                     f"the noise and above {linearity['distortion_limit_db']:g} dB of the "
                     "response: a linear model does not hold at this amplitude")
    dep = linearity.get("amplitude_dependence")
    said = "" if not dep else (
        f"<p>Amplitude dependence: up to {dep['max_db']:.2f} dB and {dep['max_deg']:.1f} deg "
        f"between the two amplitudes, {'significant' if dep['significant'] else 'within the scatter'}"
        ".</p>")
    return ("<h4>Linearity (best linear approximation of random-phase realisations)</h4>"
            + table_html(["peak", "realisations", "distortion dB", "noise dB",
                          "lines above the noise", "flagged"], rows) + said)


def order_text(model) -> str:
    """A models.json model's order (a :class:`~heliquad.host.records.models.StoredModel`),
    ``0/2``, ``0/2i`` (a pole at the origin) or ``0/2 + delay``."""
    return order_name((*model.order, int(bool(model.integrator)))) + \
        (" + delay" if model.delay_s else "")


def tf_html(model) -> str:
    """A models.json model (a :class:`~heliquad.host.records.models.StoredModel`) as HTML:
    ``num / (den)`` in powers of s, its delay as e^(-T s)."""
    def poly(c):
        n, terms = len(c) - 1, []
        for i, v in enumerate(c):
            p = n - i
            power = f"s<sup>{p}</sup>" if p > 1 else "s" if p == 1 else ""
            coef = "" if (v == 1 and p) else f"{abs(v):.4g}"
            terms.append(("- " if v < 0 else "+ ") + " ".join(t for t in (coef, power) if t))
        return " ".join(terms).lstrip("+ ")
    num, den = poly(model.num), poly(model.den)
    text = (f"({num})" if len(model.num) > 1 else num) + f" / ({den})"
    if model.delay_s:
        text += f" e<sup>-{1e3 * model.delay_s:.3g} ms &middot; s</sup>"
    return text
