"""The figure of ``heliquad effectiveness``: per axis (roll, pitch, yaw) each rotor's estimated
effectiveness with its two-sigma bar, beside what the geometry the runs flew predicts and
what the fitted geometry does; and each rotor's time constant. Draws effectiveness.json's
document; computes nothing.
"""

from __future__ import annotations

import numpy as np

from .figure import new_figure

__all__ = ["plot_effectiveness", "write_effectiveness"]

#: The bars' half-width in sigmas.
BAR_SIGMAS = 2.0


def plot_effectiveness(axes, doc: dict):
    """Draw ``doc`` (effectiveness.json's document) onto four axes: the three rows, then the
    time constants. Returns their figure."""
    rotors = np.arange(1, doc["rotors"] + 1)
    as_array = lambda key: np.array(doc[key], dtype=float)      # noqa: E731 - null is NaN
    est, sigma = as_array("effectiveness_rad_s2"), as_array("effectiveness_sigma_rad_s2")
    flown, fitted = as_array("flown_geometry_rad_s2"), as_array("fitted_geometry_rad_s2")
    for ax, row, name in zip(axes[:3], range(3), doc["rows"]):
        ax.axhline(0.0, color="0.8", lw=0.8)
        ax.errorbar(rotors, est[row], yerr=BAR_SIGMAS * sigma[row], fmt="o", capsize=4,
                    label=f"estimate ({BAR_SIGMAS:g} sigma)")
        ax.plot(rotors, flown[row], "x", ms=9, label="the geometry flown (CA_*)")
        ax.plot(rotors, fitted[row], "+", ms=11, label="the fitted geometry")
        ax.set_ylabel(f"{name}, rad/s^2")
        ax.set_xticks(rotors)
    axes[0].legend(loc="best", fontsize="small")
    axes[0].set_title(f"each rotor's effectiveness per unit of thrust command "
                      f"(chi2/dof {doc['chi2_dof']:.2f})")
    t, t_sigma = as_array("time_constant_s"), as_array("time_constant_sigma_s")
    axes[3].errorbar(rotors, 1e3 * t, yerr=1e3 * BAR_SIGMAS * t_sigma, fmt="o", capsize=4)
    axes[3].set_ylabel("time constant, ms")
    axes[3].set_xlabel("rotor (1: the central one)")
    axes[3].set_xticks(rotors)
    return axes[0].figure


def write_effectiveness(path, doc: dict) -> None:
    """The figure of ``doc`` into the PNG ``path``."""
    fig, axes = new_figure(4, 1, figsize=(8, 10), sharex=True)
    plot_effectiveness(axes, doc)
    fig.savefig(path, dpi=100)
