"""The report's closed-loop validation section: each loop's margins (the model's, those
measured through the excitation, the simulator's truth's), the time responses, or where the
cascade goes unstable. Flags what the identified band shows wrong; notes, with the sweep
that would check them, the margins and instabilities outside it (not validated)."""

from __future__ import annotations

import html
import math

from ...sim.base.firmware_facts import MAX_FREQ_FRACTION
from ..estimate.thresholds import ACCURACY_DB, ACCURACY_DEG
from ..validate.closed_loop import instability_text
from .report_html import number_text, table_html

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


def validation_html(validation, axis, flags, notes, loop_hz=None):
    """Each loop's margins (the model's, measured through the excitation, the simulator's
    truth) with what is not validated or not measured, then the time responses, or where
    the cascade goes unstable: flagged inside the identified band, a note (not validated)
    outside it. Flags margins in band the truth does not confirm; notes, in one line, the
    margins not validated (:func:`_margin_flags`)."""
    band = validation.band_rad_s
    text = "<h3>Closed-loop validation</h3>"
    if band:
        text += (f"<p>The model was identified over {band[0]:.3g}-{band[1]:.3g} rad/s; a margin "
                 "whose crossover lies outside that band is not validated: the model has no "
                 "data there.</p>")
    text += "".join(_loop_html(name, lp, validation) for name, lp in validation.loops.items())
    _margin_flags(validation, axis, flags, notes, loop_hz)
    if validation.stable:
        return text + _responses_html(validation)
    why = instability_text(validation.instability) if validation.instability is not None \
        else "the cascade is unstable with these gains"
    if (validation.instability or {}).get("outside_band"):
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
    measured = validation.measured_loop
    if measured and measured.get("loop") == name:
        points = measured.get("points") or []
        hz = [p["freq_hz"] for p in points]
        reach = (f", {len(hz)} points, {2 * math.pi * min(hz):.3g}-{2 * math.pi * max(hz):.3g} "
                 "rad/s" if hz else "")
        rows.append(("measured through the excitation",
                     *_margin_cells(measured, "not measured", "not measured"),
                     f"{measured.get('injection')} injection{reach}"))
        said += [f"not measured: {why}" for why in measured.get("unmeasured", [])]
    truth = (validation.truth_loops or {}).get(name)
    if truth:
        rows.append(("simulator's truth", *_margin_cells(truth), ""))
    return (f"<h4>{html.escape(LOOPS.get(name, name))}</h4>"
            + table_html(["", "gain margin (dB)", "at (rad/s)", "phase margin (deg)", "at (rad/s)",
                      "closed loop / note"], rows, left=(0, 5))
            + "".join(f"<p>{html.escape(s[0].upper() + s[1:])}.</p>" for s in said))


def _margin_cells(lp, no_gm="inf", no_pm="none"):
    """A loop's gain margin (dB; ``no_gm`` without a phase crossover), phase margin (deg;
    ``no_pm`` without a gain crossover) and where each is read (rad/s)."""
    gm, pm = lp.get("gain_margin_db"), lp.get("phase_margin_deg")
    return (no_gm if gm is None else number_text(gm, ".3g"),
            number_text(lp.get("phase_crossover_rad_s"), ".3g"),
            no_pm if pm is None else number_text(pm, ".3g"),
            number_text(lp.get("gain_crossover_rad_s"), ".3g"))


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
    out, truths = {}, validation.truth_loops or {}
    for name, lp in validation.loops.items():
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
        notes.append(_margins_note(axis, out, validation.band_rad_s, loop_hz))


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
    st, sn = validation.step, validation.sine
    tb = validation.turbulence or {}
    return (f"<p>Step {st['size']:g} {html.escape(st['unit'])}: rise "
            f"{number_text(st.get('rise_time_s'), '.2f')} s, overshoot "
            f"{number_text(st.get('overshoot_pct'), '.1f')} %, settling "
            f"{number_text(st.get('settling_time_s'), '.2f')} s. Sine {sn['freq_hz']:g} Hz: "
            f"tracking RMS {number_text(sn.get('tracking_rms'), '.3g')} {html.escape(st['unit'])} "
            f"({number_text(sn.get('tracking_rms_pct'), '.0f')} %)."
            + (f" {html.escape(tb['level'])} turbulence: rate RMS "
               f"{tb['rate_rms_deg_s']:.2f} deg/s from gusts of "
               f"{tb['gust_rate_rms_deg_s']:.1f} deg/s." if tb else "") + "</p>")
