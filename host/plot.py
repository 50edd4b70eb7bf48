"""The host tool's plots (compute lives elsewhere; these only draw results).

Each ``plot_*`` function draws onto the matplotlib Axes it is given and returns their
figure, so a notebook can place a plot in a figure of its own::

    fig, axes = plt.subplots(2, 1, sharex=True)
    plot_bode(axes, omega, F, models=result.models)

The ``write_*`` functions are what the command line uses: each makes a figure of its own
(:func:`new_figure`, a bare ``matplotlib.figure.Figure``: no pyplot, no backend chosen or
needed), draws the plot into it and saves it to a file. Nothing here selects a matplotlib
backend.
"""

from __future__ import annotations

import math

import numpy as np

from .files import save_figure

__all__ = ["new_figure", "plot_bode", "plot_responses", "plot_validation", "write_bode",
           "write_responses", "write_validation"]

#: Dense grid points per plotted model curve.
CURVE_POINTS = 400
#: Units of the logged signals of a sweep (tlog HQ_SYSID_SAMPLE fields), for the labels.
SIGNAL_UNITS = {"axis_cmd": "torque cmd", "rate_sp": "rad/s", "angle_sp": "rad",
                "rate": "rad/s", "angle": "rad"}
#: Columns of the per-frequency responses figure.
RESPONSE_COLUMNS = 3


def new_figure(rows=1, cols=1, figsize=(8, 6), **subplots):
    """A figure of ``rows`` x ``cols`` axes with constrained layout, made without pyplot
    (so no backend is involved), and its axes (as ``Figure.subplots`` returns them)."""
    from matplotlib.figure import Figure

    fig = Figure(figsize=figsize, layout="constrained")
    return fig, fig.subplots(rows, cols, **subplots)


# -- Bode plot of points and models --------------------------------------------------------

def plot_bode(axes, omega, F, sigma=None, models=(), recommended=None, title=""):
    """Bode plot of frequency-response points and fitted models onto ``axes``, a pair of
    Axes (magnitude, phase); returns their figure.

    Magnitude in dB, phase in degrees, frequency in Hz (log scale). ``omega`` in rad/s,
    ``F`` complex. ``sigma`` is the standard deviation of each complex point; it is drawn as
    the magnitude band ``20 log10(1 +/- sigma/|F|)`` and the phase band ``asin(sigma/|F|)``.
    ``models``: :class:`~heliquad.host.fit.TfModel`; the one at index ``recommended`` is
    drawn heavier.
    """
    ax_mag, ax_ph = axes
    omega = np.asarray(omega, float)
    f_hz = omega / (2 * np.pi)
    mag_db = 20 * np.log10(np.abs(F))
    phase_deg = np.degrees(np.unwrap(np.angle(F)))
    _bode_points(ax_mag, ax_ph, f_hz, mag_db, phase_deg, F, sigma)
    dense = np.logspace(np.log10(omega.min() / 1.5), np.log10(omega.max() * 1.5), CURVE_POINTS)
    for i, model in enumerate(models):
        label = _model_label(model, i == recommended)
        resp = model.response(dense)
        ph = np.degrees(np.unwrap(np.angle(resp)))
        ph += 360 * np.round((phase_deg[0] - np.interp(omega[0], dense, ph)) / 360)
        width = 2.5 if i == recommended else 1.3
        with np.errstate(divide="ignore"):              # a zero on the axis: -inf dB, not drawn
            model_db = 20 * np.log10(np.abs(resp))
        ax_mag.semilogx(dense / (2 * np.pi), model_db, lw=width, label=label)
        ax_ph.semilogx(dense / (2 * np.pi), ph, lw=width)
    ax_mag.set_xscale("log")
    ax_mag.set_ylabel("magnitude (dB)")
    ax_ph.set_ylabel("phase (deg)")
    ax_ph.set_xlabel("frequency (Hz)")
    for ax in (ax_mag, ax_ph):
        ax.grid(True, which="both", alpha=0.3)
    ax_mag.legend(fontsize=8)
    if title:
        ax_mag.set_title(title)
    return ax_mag.figure


def _bode_points(ax_mag, ax_ph, f_hz, mag_db, phase_deg, F, sigma):
    """The measured points, with their 1-sigma bands when ``sigma`` is given."""
    if sigma is None:
        ax_mag.plot(f_hz, mag_db, "o", color="k", label="measured", zorder=3)
        ax_ph.plot(f_hz, phase_deg, "o", color="k", zorder=3)
        return
    rel = np.minimum(np.asarray(sigma) / np.abs(F), 0.999)
    below_db, above_db = -20 * np.log10(1 - rel), 20 * np.log10(1 + rel)
    err_deg = np.degrees(np.arcsin(rel))
    ax_mag.errorbar(f_hz, mag_db, yerr=[below_db, above_db], fmt="o", color="k",
                    capsize=3, label="measured (1 sigma)", zorder=3)
    ax_ph.errorbar(f_hz, phase_deg, yerr=err_deg, fmt="o", color="k", capsize=3, zorder=3)


def _model_label(model, recommended):
    m, n = model.order
    j = model.metrics.get("J", float("nan"))
    tag = f"{m}/{n}{' + delay' if model.delay_fitted else ''}  J={j:.1f}"
    if not model.stable:
        tag += " UNSTABLE"
    return tag + (" (recommended)" if recommended else "")


def write_bode(path, omega, F, sigma=None, models=(), recommended=None, title=""):
    """:func:`plot_bode` in a figure of its own, written to ``path`` (format from its
    extension)."""
    fig, axes = new_figure(2, 1, figsize=(8, 7), sharex=True)
    plot_bode(axes, omega, F, sigma, models, recommended, title)
    save_figure(fig, path, dpi=110)


# -- a sweep's time responses --------------------------------------------------------------

def plot_responses(axes, segments, input_name, output_name):
    """The measured cycles of each frequency, input dashed and output solid, one frequency
    per Axes of ``axes`` (any shape, taken in row order; Axes left over are hidden);
    returns their figure.

    ``segments``: ``(freq_hz, t_s, u, y)`` per frequency; ``input_name``, ``output_name``:
    the logged signals ``u`` and ``y`` are (``axis_cmd``, ``rate_sp``, ``angle_sp``;
    ``rate``, ``angle``), for the labels.
    """
    flat = np.asarray(axes, dtype=object).ravel()
    if len(flat) < len(segments):
        raise ValueError(f"{len(segments)} frequencies need as many axes, got {len(flat)}")
    u_unit, y_unit = SIGNAL_UNITS[input_name], SIGNAL_UNITS[output_name]
    for ax, (f, t, u, y) in zip(flat, segments):
        t = np.asarray(t) - t[0]
        ax.plot(t, u, "--", lw=1, label=f"input: {input_name} ({u_unit})")
        ax.plot(t, y, lw=1, label=f"output: {output_name} ({y_unit})")
        ax.set_title(f"{f:.3g} Hz", fontsize=9)
        ax.set_xlabel("time (s)", fontsize=8)
        ax.set_ylabel(f"{u_unit} | {y_unit}", fontsize=7)
        ax.tick_params(labelsize=7)
        ax.grid(alpha=0.3)
    for ax in flat[len(segments):]:
        ax.axis("off")
    flat[0].legend(fontsize=7)
    return flat[0].figure


def write_responses(path, segments, input_name, output_name, title=""):
    """:func:`plot_responses` in a figure of its own (three frequencies a row), written to
    ``path``."""
    rows = max(1, math.ceil(len(segments) / RESPONSE_COLUMNS))
    fig, axes = new_figure(rows, RESPONSE_COLUMNS, figsize=(12, 2.4 * rows), squeeze=False)
    plot_responses(axes, segments, input_name, output_name)
    if title:
        fig.suptitle(title)
    save_figure(fig, path, dpi=90)


# -- closed-loop validation ----------------------------------------------------------------

def plot_validation(axes, report, traces):
    """The paper's figures 12-16 onto four Axes (``axes`` of any shape, in row order): step
    response, sine tracking, Dryden turbulence, and the loop gains' magnitude; returns
    their figure. ``report`` and ``traces`` as :func:`~heliquad.host.validate.validate_model`
    returns them (SI units); drawn in degrees, deg/s and dB."""
    ax_step, ax_sine, ax_turb, ax_loops = np.asarray(axes, dtype=object).ravel()[:4]
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
    _loop_gains(ax_loops, report, traces["loop_gains"])
    return ax_step.figure


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


def _loop_gains(ax, report, gains):
    w = gains["omega_rad_s"]
    for name, key in (("rate loop L_r", "rate"), ("angle loop L_a", "angle")):
        if key not in gains:
            continue
        pm = report["loops"][key]["phase_margin_rad"]
        with np.errstate(divide="ignore"):      # a zero on the axis: -inf dB, not drawn
            gain_db = 20 * np.log10(np.abs(gains[key]))
        ax.semilogx(w, gain_db,
                    label=f"{name}: PM {float('nan') if pm is None else np.degrees(pm):.0f} deg")
    ax.axhline(0, color="k", lw=0.8)
    ax.set_title("loop gains")
    ax.set_xlabel("frequency (rad/s)")
    ax.set_ylabel("magnitude (dB)")
    ax.grid(alpha=0.3, which="both")
    ax.legend(fontsize=8)


def write_validation(path, report, traces):
    """:func:`plot_validation` in a figure of its own, titled, written to ``path``."""
    fig, axes = new_figure(2, 2, figsize=(11, 7.5))
    plot_validation(axes, report, traces)
    fig.suptitle(f"{report['axis']}: closed-loop validation of the identified model")
    save_figure(fig, path, dpi=100)
