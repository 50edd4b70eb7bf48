"""Plots of frequency-response points and fitted models (compute lives elsewhere)."""

from __future__ import annotations

import numpy as np

from .files import save_figure

__all__ = ["plot_bode"]

#: Dense grid points per plotted model curve.
CURVE_POINTS = 400


def _figure(rows):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt.subplots(rows, 1, sharex=True, figsize=(8, 7), constrained_layout=True)


def plot_bode(path, omega, F, sigma=None, models=(), recommended=None, title=""):
    """Bode plot: the points with their uncertainty and every model, magnitude and phase.

    Magnitude in dB, phase in degrees, frequency in Hz (log scale). ``sigma`` is the
    standard deviation of each complex point; it is drawn as the magnitude band
    ``20 log10(1 +/- sigma/|F|)`` and the phase band ``asin(sigma/|F|)``.
    """
    fig, (ax_mag, ax_ph) = _figure(2)
    f_hz = omega / (2 * np.pi)
    mag_db = 20 * np.log10(np.abs(F))
    phase_deg = np.degrees(np.unwrap(np.angle(F)))
    if sigma is not None:
        rel = np.minimum(np.asarray(sigma) / np.abs(F), 0.999)
        below_db, above_db = -20 * np.log10(1 - rel), 20 * np.log10(1 + rel)
        err_deg = np.degrees(np.arcsin(rel))
        ax_mag.errorbar(f_hz, mag_db, yerr=[below_db, above_db], fmt="o", color="k",
                        capsize=3, label="measured (1 sigma)", zorder=3)
        ax_ph.errorbar(f_hz, phase_deg, yerr=err_deg, fmt="o", color="k", capsize=3, zorder=3)
    else:
        ax_mag.plot(f_hz, mag_db, "o", color="k", label="measured", zorder=3)
        ax_ph.plot(f_hz, phase_deg, "o", color="k", zorder=3)
    dense = np.logspace(np.log10(omega.min() / 1.5), np.log10(omega.max() * 1.5), CURVE_POINTS)
    for i, model in enumerate(models):
        label = _model_label(model, i == recommended)
        resp = model.response(dense)
        ph = np.degrees(np.unwrap(np.angle(resp)))
        ph += 360 * np.round((phase_deg[0] - np.interp(omega[0], dense, ph)) / 360)
        width = 2.5 if i == recommended else 1.3
        ax_mag.semilogx(dense / (2 * np.pi), 20 * np.log10(np.abs(resp)), lw=width, label=label)
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
    save_figure(fig, path, dpi=110)
    import matplotlib.pyplot as plt

    plt.close(fig)


def _model_label(model, recommended):
    m, n = model.order
    j = model.metrics.get("J", float("nan"))
    tag = f"{m}/{n}{' + delay' if model.delay_fitted else ''}  J={j:.1f}"
    if not model.stable:
        tag += " UNSTABLE"
    return tag + (" (recommended)" if recommended else "")
