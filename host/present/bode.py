"""Bode plots of frequency-response points and models, and the points' coherence
(``bode.png`` of ``heliquad fit`` and ``identify``)."""

from __future__ import annotations

import numpy as np

from ..records.figures import save_figure
from ..records.points import known_column
from .figure import CURVE_POINTS, fixed_layout, log_ticks, new_figure

#: The Bode figure's fixed layout, inches: margins (the y labels, the title, the frequency
#: axis) and the gap between its panels (constrained layout took 40 % of its drawing).
BODE_MARGINS_IN = {"left": 0.8, "right": 0.25, "top": 0.4, "bottom": 0.6}


BODE_GAP_IN = 0.25


#: The coherence panel's series: the coherence of the excitation r with the output and with
#: the input (points estimated against the excitation), as (key, label, marker style); the
#: second hollow and larger, so that equal values show both.
EXCITATION_COHERENCES = (("coherence_ry", "r -> y", {"marker": "o", "ms": 5}),
                         ("coherence_ru", "r -> u", {"marker": "s", "ms": 8, "mfc": "none"}))


#: Every coherence a points table may hold.
COHERENCE_KEYS = ("coherence", *(key for key, _, _ in EXCITATION_COHERENCES))



def plot_bode(axes, points, models=(), recommended=None, title="", gate=None):
    """Bode plot of frequency-response points and fitted models onto ``axes``: a pair of
    Axes (magnitude, phase), or three with the points' coherence in the third; returns
    their figure.

    Magnitude in dB, phase in degrees, frequency in Hz (log scale). ``points``:
    :class:`~heliquad.host.records.points.FrequencyPoint` (as the estimator returns them or
    :func:`~heliquad.host.records.points.read_points_csv` reads them); each point's sigma,
    where known, is drawn as the magnitude band ``20 log10(1 +/- sigma/|F|)`` and the phase
    band ``asin(sigma/|F|)``. ``models``: :class:`~heliquad.host.estimate.fit.TfModel`; the
    one at index ``recommended`` is drawn heavier. The coherence panel is drawn with the
    quality ``gate`` by :func:`plot_coherence`.
    """
    points = sorted(points, key=lambda p: p.omega_rad_s)
    omega, F = known_column(points, "omega_rad_s"), known_column(points, "gain")
    sigma = known_column(points, "sigma")
    ax_mag, ax_ph, *rest = axes
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
    if rest:
        plot_coherence(rest[0], points, gate)
    ax_mag.set_ylabel("magnitude (dB)")
    ax_ph.set_ylabel("phase (deg)")
    for ax in (ax_mag, ax_ph, *rest):
        log_ticks(ax)
        ax.grid(True, which="both", alpha=0.3)
    (rest or [ax_ph])[0].set_xlabel("frequency (Hz)")
    ax_mag.legend(fontsize=8)
    if title:
        ax_mag.set_title(title, y=1.0)      # where it goes: no search for a place
    return ax_mag.figure



def plot_coherence(ax, points, gate=None):
    """Each point's coherence onto ``ax`` against frequency (Hz), and the quality ``gate``
    (the tool's is :data:`heliquad.host.estimate.thresholds.LOW_COHERENCE`) as a line when
    given; returns its figure.

    With ``coherence_ry`` and ``coherence_ru`` known (points estimated against the
    excitation) those two are drawn, else the single ``coherence``; with none the panel says
    so.
    """
    f_hz = known_column(points, "omega_rad_s") / (2 * np.pi) if points else np.array([])
    known = {key: known_column(points, key) for key in COHERENCE_KEYS} if points else {}
    series = [(known[key], label, style) for key, label, style in EXCITATION_COHERENCES
              if known.get(key) is not None]
    if not series and known.get("coherence") is not None:
        series = [(known["coherence"], "coherence", {"marker": "o", "ms": 5})]
    for values, label, style in series:
        ax.plot(f_hz, values, ls="none", label=label, **style)
    if gate is not None:
        ax.axhline(gate, color="tab:red", ls="--", lw=1, label=f"quality gate {gate:g}")
    if not series:
        ax.text(0.5, 0.5, "no coherence in the points", transform=ax.transAxes, ha="center",
                va="center", fontsize=8)
    ax.set_ylim(0, 1.05)
    ax.set_ylabel("coherence")
    ax.legend(fontsize=7, loc="lower left", ncol=3)
    return ax.figure



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



def write_bode(path, points, models=(), recommended=None, title="", gate=None):
    """:func:`plot_bode` in a figure of its own, with the coherence panel under it when
    any point knows a coherence, written to ``path`` (format from its extension)."""
    if any(known_column(points, key) is not None for key in COHERENCE_KEYS):
        fig, axes = new_figure(3, 1, figsize=(8, 8.5), layout=None, sharex=True,
                               gridspec_kw={"height_ratios": [3, 3, 1.6]})
    else:
        fig, axes = new_figure(2, 1, figsize=(8, 7), layout=None, sharex=True)
    fixed_layout(fig, len(axes), 1, BODE_MARGINS_IN, (0.0, BODE_GAP_IN))
    plot_bode(axes, points, models, recommended, title, gate)
    save_figure(fig, path, dpi=110)
