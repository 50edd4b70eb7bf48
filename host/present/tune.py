"""``heliquad tune``'s figure, tune.png: per axis, the current and the tuned gains' loops
(the rate loop, and for roll and pitch the input loop: magnitude and phase against
frequency, the identified band shaded) and their predicted steps with the axis command.
Drawn from what host/campaign/tune.py computed; tune.json is the record."""

from __future__ import annotations

import numpy as np

from ..records.figures import save_figure
from .figure import new_figure

__all__ = ["plot_tune_axis", "write_tune_figure"]

#: (design, label, line style) as the figure draws them.
DESIGNS = (("current", "current", "--"), ("tuned", "tuned", "-"))
#: The loops drawn, with their colours (validation.png's).
LOOPS = (("rate", "tab:blue"), ("input", "tab:green"))
#: The magnitude axis shows at most this far from 0 dB.
DB_RANGE = 60.0


def _phase_deg(L):
    """The unwrapped phase (deg) on the turn that starts in (-360, 0]."""
    phase = np.degrees(np.unwrap(np.angle(L)))
    return phase - 360 * np.ceil(phase[0] / 360)


def plot_tune_axis(axes, axis, band, traces):
    """One axis onto three Axes (magnitude, phase, step): ``traces`` ``{"current": ...,
    "tuned": ...}``, each with ``loop_gains`` (``omega_rad_s`` and each loop's complex
    gain) and, when stable, ``step`` ``(t, response, command, size)``."""
    ax_mag, ax_ph, ax_step = axes
    for ax in (ax_mag, ax_ph):
        ax.axvspan(*band, color="0.92", zorder=0)
    for key, label, style in DESIGNS:
        gains = traces[key]["loop_gains"]
        w = np.asarray(gains["omega_rad_s"], float)
        for loop, colour in LOOPS:
            if loop in gains:
                with np.errstate(divide="ignore"):
                    ax_mag.semilogx(w, 20 * np.log10(np.abs(gains[loop])), style, color=colour,
                                    label=f"{label} {loop} loop")
                ax_ph.semilogx(w, _phase_deg(gains[loop]), style, color=colour)
        if "step" in traces[key]:
            t, response, command, size = traces[key]["step"]
            ax_step.plot(t, response / size, style, color="k", label=f"{label}: response")
            ax_step.plot(t, command, style, color="tab:red", lw=1, label=f"{label}: command")
    ax_mag.axhline(0, color="k", lw=0.8)
    ax_ph.axhline(-180, color="k", lw=0.8)
    low, high = ax_mag.get_ylim()
    ax_mag.set_ylim(max(low, -DB_RANGE), min(high, DB_RANGE))
    ax_mag.set_title(f"{axis}: loop gains (band shaded)")
    ax_mag.set_ylabel("magnitude (dB)")
    ax_ph.set_ylabel("phase (deg)")
    ax_ph.set_xlabel("frequency (rad/s)")
    ax_step.set_title(f"{axis}: predicted step")
    ax_step.set_xlabel("time (s)")
    ax_step.set_ylabel("response / step, axis command")
    ax_step.set_xlim(0, 3)
    for ax in (ax_mag, ax_ph, ax_step):
        ax.grid(alpha=0.3, which="both")
    ax_mag.legend(fontsize=6, loc="lower left")
    ax_step.legend(fontsize=6, loc="lower right")
    return ax_mag.figure


def write_tune_figure(path, results) -> None:
    """Every axis of ``results`` (``(axis, band, traces)``), one row each, written to
    ``path``."""
    fig, axes = new_figure(len(results), 3, figsize=(14, 3.6 * len(results)), squeeze=False)
    for row, (axis, band, traces) in zip(axes, results):
        plot_tune_axis(row, axis, band, traces)
    fig.suptitle("heliquad tune: current (dashed) and tuned (solid) gains, predicted")
    save_figure(fig, path, dpi=100)
