"""A closed-loop validation drawn: its figure (the loop gains as magnitude over phase with
their margins marked, the step, sine tracking and turbulence rejection), on given Axes or
as ``validation.png`` (:func:`write_validation`). validation.json is its record's
(host/records/validation.py)."""

from __future__ import annotations

import math

import numpy as np

from ..records.figures import save_figure
from ..validate.loops import crossover_in_band
from .figure import new_figure

__all__ = ["plot_validation", "plot_loop_gains", "write_validation"]

#: The loops of a validation report as the loop-gain panel draws them: (key, label, colour).
LOOP_STYLES = (("rate", "rate loop L_r", "tab:blue"), ("angle", "angle loop L_a", "tab:orange"),
               ("input", "input loop L_in", "tab:green"))
#: A margin whose crossover lies outside the identified band: a hollow marker, a grey
#: line to it and its label faded.
NOT_VALIDATED_COLOUR, NOT_VALIDATED_ALPHA = "0.5", 0.6
#: The loop-gain panel's magnitude axis shows at most this far from 0 dB (a loop with
#: integrators runs off to +100 dB at low frequency; the margins live near 0 dB).
LOOP_GAIN_DB_RANGE = 60.0


def plot_validation(axes, report, traces):
    """The paper's figures 12-16 onto the Axes ``axes`` (any shape, in row order): step
    response, sine tracking, Dryden turbulence, and the loop gains with their margins
    (:func:`plot_loop_gains`). Given four Axes, the fourth's place in its grid is split
    into the loop gains' magnitude over their phase (that Axes is removed); given five, the
    last two are those. Returns their figure. ``report`` and ``traces`` as
    :func:`~heliquad.host.validate.closed_loop.validate_model` returns them (SI units); drawn in
    degrees, deg/s and dB."""
    flat = list(np.asarray(axes, dtype=object).ravel())
    ax_step, ax_sine, ax_turb = flat[:3]
    ax_mag, ax_ph = flat[3:5] if len(flat) >= 5 else _split(flat[3])
    t = traces["t"]
    unit = "deg" if report.get("step", {}).get("quantity", "angle") == "angle" else "deg/s"
    sine = report.get("sine")
    sine_title = "sine tracking" + (f", {sine['omega_rad_s'] / (2 * np.pi):g} Hz" if sine else "")
    for ax, key, title in ((ax_step, "step", "step response"), (ax_sine, "sine", sine_title)):
        if key in traces:
            ref, out = traces[key]
            ax.plot(t, np.degrees(ref), "--", color="k", label="reference")
            ax.plot(t, np.degrees(out), label="response")
            ax.set_xlim(0, 10)
        ax.set_title(title)
        ax.set_xlabel("time (s)")
        ax.set_ylabel(f"{report['axis']} ({unit})")
        ax.grid(alpha=0.3)
        ax.legend(fontsize=8)
    _turbulence(ax_turb, report, traces)
    plot_loop_gains((ax_mag, ax_ph), report, traces["loop_gains"])
    return ax_step.figure



def _split(ax):
    """Two Axes, magnitude over phase sharing the frequency axis, in ``ax``'s place in its
    grid (``ax`` removed)."""
    spec = ax.get_subplotspec()
    if spec is None:
        raise ValueError("the loop gains need their Axes in a grid (subplots, add_subplot) "
                         "to split it, or a fifth Axes")
    place, fig = spec.subgridspec(2, 1, hspace=0.05), ax.figure
    ax.remove()
    ax_mag = fig.add_subplot(place[0])
    return ax_mag, fig.add_subplot(place[1], sharex=ax_mag)



def _turbulence(ax, report, traces):
    t = traces["t"]
    if "turbulence" in traces:
        tr = traces["turbulence"]
        ax.plot(t, np.degrees(tr["gust"]), color="0.7", label="gust rate (deg/s)")
        ax.plot(t, np.degrees(tr["rate"]), label="rate, closed loop (deg/s)")
        if "angle" in tr:
            ax.plot(t, np.degrees(tr["angle"]), label="angle, closed loop (deg)")
        ax.set_title(f"Dryden turbulence, {report['turbulence']['level']}")
        ax.legend(fontsize=8)
    else:
        ax.set_title("no turbulence")
    ax.set_xlabel("time (s)")
    ax.set_ylabel("deg/s, deg")
    ax.grid(alpha=0.3)



def plot_loop_gains(axes, report, gains):
    """Every loop of ``report`` (:func:`~heliquad.host.validate.closed_loop.validate_model`'s) onto a
    pair of Axes, magnitude (dB) over phase (deg) against rad/s (log scale); returns their
    figure. ``gains``: its traces' ``loop_gains``.

    The identified band shaded, the 0 dB and -180 deg lines; each reported margin marked
    at its crossover and labelled (the phase margin on the phase at the gain crossover, the
    gain margin on the magnitude at the phase crossover), hollow and grey, "not validated",
    when its crossover lies outside the band; the simulator's truth dashed when ``gains``
    has it; the points of the loop measured through the excitation (``measured_loop``) on
    their loop, each phase (known modulo 360 deg) on the turn of the model's curve there.
    """
    ax_mag, ax_ph = axes
    w = np.asarray(gains["omega_rad_s"], float)
    for ax, label in ((ax_mag, "identified band"), (ax_ph, "_band")):
        ax.axvspan(*report["band_rad_s"], color="0.92", zorder=0, label=label)
    levels = {-180.0}
    for n, (key, label, colour) in enumerate(LOOP_STYLES):
        if key not in gains:
            continue
        lp = report["loops"][key]
        phase = _phase_deg(gains[key], w, lp)
        ax_mag.semilogx(w, _db(gains[key]), color=colour, label=label)
        ax_ph.semilogx(w, phase, color=colour)
        truth = gains.get("truth", {}).get(key)
        if truth is not None:
            first = not any(line.get_label() == "simulator's truth" for line in ax_mag.lines)
            ax_mag.semilogx(w, _db(truth), "--", color=colour, lw=1,
                            label="simulator's truth" if first else "_truth")
            ax_ph.semilogx(w, _phase_deg(truth, w, report["truth"][key]), "--", color=colour,
                           lw=1)
        levels |= _mark_margins(ax_mag, ax_ph, w, phase, lp, colour, n)
        _measured_points(ax_mag, ax_ph, w, phase, report.get("measured_loop"), key, colour)
    _loop_axes(ax_mag, ax_ph, w, levels)
    return ax_mag.figure



def _db(L):
    with np.errstate(divide="ignore"):          # a zero on the axis: -inf dB, not drawn
        return 20 * np.log10(np.abs(L))



def _phase_deg(L, w, lp):
    """The unwrapped phase of the loop gain ``L`` (deg) on the turn where its margins
    (``lp``, :func:`~heliquad.host.validate.loops.margins`'s) read off -180 deg: at the gain
    crossover of its phase margin it is ``-180 + PM``; without one, -180 at the phase
    crossover of its gain margin; without either, it starts in (-360, 0]."""
    phase = np.degrees(np.unwrap(np.angle(L)))
    if lp.get("gain_crossover_rad_s") is not None:
        at, want = lp["gain_crossover_rad_s"], -180 + math.degrees(lp["phase_margin_rad"])
    elif lp.get("phase_crossover_rad_s") is not None:
        at, want = lp["phase_crossover_rad_s"], -180.0
    else:
        return phase - 360 * math.ceil(phase[0] / 360)
    there = np.interp(math.log(at), np.log(w), phase)
    return phase + 360 * round((want - there) / 360)



def _mark_margins(ax_mag, ax_ph, w, phase, lp, colour, n):
    """The loop's reported margins at their crossovers, labelled (staggered by the loop's
    index ``n``); returns the -180 + k 360 deg levels its gain margin reads off."""
    marks, levels = [], set()
    if lp.get("gain_crossover_rad_s") is not None:
        wc, pm = lp["gain_crossover_rad_s"], math.degrees(lp["phase_margin_rad"])
        marks.append((ax_ph, wc, -180 + pm, -180.0, f"PM {pm:.0f} deg",
                      crossover_in_band(lp["gain_crossovers"], wc)))
    if lp.get("phase_crossover_rad_s") is not None:
        wp, gm = lp["phase_crossover_rad_s"], 20 * math.log10(lp["gain_margin"])
        level = -180 + 360 * round((np.interp(math.log(wp), np.log(w), phase) + 180) / 360)
        levels.add(float(level))
        marks.append((ax_mag, wp, -gm, 0.0, f"GM {gm:.1f} dB",
                      crossover_in_band(lp["phase_crossovers"], wp)))
    for ax, at, value, reference, text, in_band in marks:
        ax.plot([at, at], [reference, value], color=colour if in_band else NOT_VALIDATED_COLOUR,
                lw=1, ls=":")
        ax.plot([at], [value], "o", ms=6, color=colour, mfc=colour if in_band else "none",
                gid="margin" if in_band else "margin not validated", label="_margin")
        right = math.log(at / w[0]) > 0.7 * math.log(w[-1] / w[0])    # label to its left
        ax.annotate(text + ("" if in_band else " not validated"), (at, value),
                    xytext=(-4 if right else 4, 3 + 8 * n), textcoords="offset points",
                    ha="right" if right else "left", fontsize=6, color=colour,
                    alpha=1 if in_band else NOT_VALIDATED_ALPHA, clip_on=True, in_layout=False,
                    bbox={"fc": "white", "ec": "none", "alpha": 0.7, "pad": 0.5})
    return levels


def _measured_points(ax_mag, ax_ph, w, phase, measured, key, colour):
    """The points of the loop measured through the excitation, when it is loop ``key``:
    each phase on the turn nearest the model's curve ``phase`` at its frequency."""
    if not measured or measured.get("loop") != key or not measured.get("points"):
        return
    pts = measured["points"]
    at = 2 * np.pi * np.array([p["freq_hz"] for p in pts], float)
    db = np.array([p["magnitude_db"] for p in pts], float)
    deg = np.array([p["phase_deg"] for p in pts], float)
    deg += 360 * np.round((np.interp(np.log(at), np.log(w), phase) - deg) / 360)
    style = {"ls": "none", "marker": "D", "ms": 4, "color": colour, "mec": "k", "mew": 0.6}
    ax_mag.plot(at, db, label=f"measured through the excitation ({key})", **style)
    ax_ph.plot(at, deg, **style)



def _loop_axes(ax_mag, ax_ph, w, levels):
    """The loop-gain panel's lines (0 dB; -180 deg and each other turn a gain margin reads
    off), limits, labels and legend."""
    ax_mag.axhline(0, color="k", lw=0.8)
    for level in sorted(levels):
        ax_ph.axhline(level, color="k", lw=0.8)
    low, high = ax_mag.get_ylim()
    ax_mag.set_ylim(max(low, -LOOP_GAIN_DB_RANGE), min(high, LOOP_GAIN_DB_RANGE))
    low, high = ax_ph.get_ylim()
    ax_ph.set_ylim(max(low, min(levels) - 180), high + 20)
    ax_mag.set_xlim(w[0], w[-1])
    ax_mag.set_title("loop gains")
    ax_mag.set_ylabel("magnitude (dB)")
    ax_ph.set_ylabel("phase (deg)")
    ax_ph.set_xlabel("frequency (rad/s)")
    ax_mag.tick_params(labelbottom=False)
    for ax in (ax_mag, ax_ph):
        ax.set_xscale("log")
        ax.grid(alpha=0.3, which="both")
    ax_mag.legend(fontsize=6, loc="lower left", ncol=2)



def write_validation(path, report, traces):
    """:func:`plot_validation` in a figure of its own, titled, written to ``path``."""
    fig, axes = new_figure(2, 2, figsize=(12, 9.5))
    plot_validation(axes, report, traces)
    fig.suptitle(f"{report['axis']}: closed-loop validation of the identified model")
    save_figure(fig, path, dpi=100)
