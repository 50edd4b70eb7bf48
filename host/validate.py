"""Closed-loop validation of an identified model (``heliquad validate``; docs/paper.md, step 4).

The cascade of the paper, in continuous time as the paper's validation does: an inner PID
rate loop ``C_r = Kc (1 + 1/(tau_I s) + tau_D s / (tau_D/N s + 1))`` around the identified
model ``G`` (rate in, rate out), and for roll and pitch an outer PD angle loop
``C_a = Kc (1 + tau_D s / (tau_D/N s + 1))`` around ``T_r / s`` (angle is the integral of the
rate). Yaw is rate-only. N is the firmware's derivative filter. The gains default to those
the firmware flies (read from its bindings: the paper's). A model's delay enters as a
3rd-order Pade approximant.

Reported: gain and phase margins and crossovers of each loop, closed-loop stability (and,
when unstable, how far above the identified band the unstable poles lie), the
step response (rise time 10-90 %, overshoot, 2 % settling), sine tracking (0.5 Hz), and
disturbance rejection under Dryden turbulence: the gust rate of the axis (sim/dryden.py)
entering at the model's input, with the closed loop's rate and angle RMS against the gust's.
"""

from __future__ import annotations

import math
import os

import control
import numpy as np

from . import paper
from .files import save_figure, write_json
from .gains import DERIVATIVE_FILTER_N, Gains, load_gains
from ..sim import dialect as names

# Gains and load_gains are host/gains.py's, here for the validation's callers.
__all__ = ["Gains", "load_gains", "pid_tf", "build_loops", "validate_model", "plot_validation",
           "save_validation", "instability_text"]

PADE_ORDER = 3
DT_S = 0.005
SINE_FREQ_HZ = 0.5
STEP_ANGLE_DEG = 10.0
STEP_RATE_DEG_S = 30.0
DURATION_S = 30.0
#: An instability this many times above the identified band's top is flagged as outside it.
OUT_OF_BAND_FACTOR = 3.0


def pid_tf(kc, tau_i, tau_d):
    """The firmware's PID (firmware/core/pid.hpp) in continuous time, on the error as the
    paper writes it: ``Kc (1 + 1/(tau_I s) + tau_D s / (tau_D/N s + 1))``; no integral for
    tau_I <= 0, no derivative for tau_D <= 0. (The firmware differentiates the measurement
    only, which spares a setpoint step the derivative kick and leaves the loop the same.)"""
    s = control.tf("s")
    c = kc * (1 + (1 / (tau_i * s) if tau_i > 0 else 0))
    if tau_d > 0:
        c = c + kc * tau_d * s / (tau_d / DERIVATIVE_FILTER_N * s + 1)
    return c


def build_loops(num, den, delay_s, axis, gains: Gains):
    """Transfer functions: plant G, inner loop L_r and T_r, outer loop L_a and T_a (or None)."""
    G = control.tf(list(num), list(den))
    if delay_s > 0:
        G = G * control.tf(*control.pade(delay_s, PADE_ORDER))
    C_r = pid_tf(*gains.rate)
    L_r = C_r * G
    T_r = control.feedback(L_r, 1)
    if axis == "yaw" or gains.angle is None:
        return {"G": G, "C_r": C_r, "L_r": L_r, "T_r": T_r, "L_a": None, "T_a": None, "C_a": None}
    C_a = pid_tf(gains.angle[0], 0.0, gains.angle[1])
    L_a = C_a * T_r * control.tf([1], [1, 0])
    T_a = control.feedback(L_a, 1)
    return {"G": G, "C_r": C_r, "L_r": L_r, "T_r": T_r, "L_a": L_a, "T_a": T_a, "C_a": C_a}


def _margins(L, T):
    gm, pm, _, wcg, wcp, _ = control.stability_margins(L, returnall=False)
    poles = control.poles(T)
    unstable = poles[np.real(poles) >= 0]
    return {"gain_margin_db": None if not np.isfinite(gm) else float(20 * math.log10(gm)),
            "phase_margin_deg": None if not np.isfinite(pm) else float(pm),
            "gain_crossover_rad_s": None if not np.isfinite(wcp) else float(wcp),
            "phase_crossover_rad_s": None if not np.isfinite(wcg) else float(wcg),
            "closed_loop_stable": bool(unstable.size == 0),
            "unstable_pole_rad_s": float(np.max(np.abs(unstable))) if unstable.size else None}


def _instability(report, axis):
    """Where the cascade goes unstable, against the band the model was identified over
    (the paper's Table 1): far above it, the model is extrapolated and says little."""
    freq = max(lp["unstable_pole_rad_s"] for lp in report["loops"].values()
               if lp["unstable_pole_rad_s"] is not None)
    top = 2 * math.pi * paper.BANDS_HZ[axis][1]
    return {"pole_rad_s": freq, "band_top_rad_s": top,
            "outside_band": bool(freq > OUT_OF_BAND_FACTOR * top)}


def instability_text(report) -> str:
    """One line on where an unstable cascade goes unstable and what that means."""
    inst = report["instability"]
    where = (f"closed-loop poles at {inst['pole_rad_s']:.3g} rad/s, "
             f"{inst['pole_rad_s'] / inst['band_top_rad_s']:.2g}x the identified band's top "
             f"({inst['band_top_rad_s']:.3g} rad/s)")
    if inst["outside_band"]:
        return (f"the cascade is unstable with these gains: {where}, where the model has no data; "
                "check with a model that rolls off there, or on the rig")
    return f"the cascade is unstable with these gains: {where}, inside what was identified"


def validate_model(num, den, delay_s, axis, gains: Gains, turbulence="moderate", seed=0):
    """Margins, step, sine tracking and turbulence rejection. Returns (report, traces)."""
    loops = build_loops(num, den, delay_s, axis, gains)
    report = {"axis": axis, "num": list(map(float, num)), "den": list(map(float, den)),
              "delay_s": float(delay_s), "gains": {"rate": list(gains.rate),
                                                   "angle": None if gains.angle is None else list(gains.angle)},
              "loops": {"rate": _margins(loops["L_r"], loops["T_r"])}}
    outer = loops["T_a"] is not None
    if outer:
        report["loops"]["angle"] = _margins(loops["L_a"], loops["T_a"])
    T = loops["T_a"] if outer else loops["T_r"]
    t = np.arange(0.0, DURATION_S, DT_S)
    traces = {"t": t}
    stable = all(l["closed_loop_stable"] for l in report["loops"].values())
    report["stable"] = stable
    if not stable:
        report["instability"] = _instability(report, axis)
        return report, traces
    size = STEP_ANGLE_DEG if outer else STEP_RATE_DEG_S
    step = control.forced_response(T, t, np.full(t.size, size)).outputs
    info = control.step_info(T)
    traces["step"] = (np.full(t.size, size), step)
    report["step"] = {"size": size, "unit": "deg" if outer else "deg/s",
                      "rise_time_s": float(info["RiseTime"]),
                      "overshoot_pct": float(info["Overshoot"]),
                      "settling_time_s": float(info["SettlingTime"])}
    ref = size * np.sin(2 * math.pi * SINE_FREQ_HZ * t)
    sine = control.forced_response(T, t, ref).outputs
    last = t >= t[-1] - 5 / SINE_FREQ_HZ
    traces["sine"] = (ref, sine)
    report["sine"] = {"freq_hz": SINE_FREQ_HZ, "amplitude": size,
                      "tracking_rms": float(np.sqrt(np.mean((sine - ref)[last] ** 2))),
                      "tracking_rms_pct": float(100 * np.sqrt(np.mean((sine - ref)[last] ** 2)) / (size / math.sqrt(2)))}
    if turbulence:
        report["turbulence"], traces["turbulence"] = _turbulence(loops, axis, outer, t, turbulence, seed)
    return report, traces


def _turbulence(loops, axis, outer, t, level, seed):
    """The axis's Dryden gust rate entering at the model's input, references zero.

    The identified models map a rate (command) to a rate, so the gust rate enters where the
    command does: the plant filters it, as the rotors' aerodynamics filter a gust. Added to
    the measured rate instead, the gust's whole spectrum, up to the Dryden filters' 14 rad/s
    corner, would pass unfiltered."""
    from ..sim.dryden import Dryden
    from ..sim.params import load_params

    tp = load_params().turbulence
    d = Dryden(level, tp.altitude_m, tp.span_m, DT_S, seed)
    gust = np.degrees(d.block(t.size)[:, 3 + names.AXES[axis]])        # gust rates p, q, r
    s = control.tf("s")
    G, C_r = loops["G"], loops["C_r"]
    outer_gain = (1 + loops["C_a"] / s) if outer else 1
    to_rate = control.feedback(G, C_r * outer_gain)          # rate / d, d at the plant input
    rate = control.forced_response(to_rate, t, gust).outputs
    out = {"level": level, "seed": seed, "gust_rate_rms_deg_s": float(np.std(gust)),
           "rate_rms_deg_s": float(np.sqrt(np.mean(rate ** 2)))}
    trace = {"gust": gust, "rate": rate}
    if outer:
        angle = control.forced_response(to_rate / s, t, gust).outputs
        out["angle_rms_deg"] = float(np.sqrt(np.mean(angle ** 2)))
        out["angle_max_deg"] = float(np.max(np.abs(angle)))
        trace["angle"] = angle
    return out, trace


def save_validation(folder, report, traces, num, den, delay_s, axis, gains) -> list:
    """Write ``validation.json`` (and ``validation.png`` when the cascade is stable) into
    ``folder``; returns the file names written."""
    os.makedirs(folder, exist_ok=True)
    write_json(os.path.join(folder, "validation.json"), report)
    if not report["stable"]:
        return ["validation.json"]
    plot_validation(report, traces, build_loops(num, den, delay_s, axis, gains),
                    os.path.join(folder, "validation.png"))
    return ["validation.json", "validation.png"]


def plot_validation(report, traces, loops, path) -> None:
    """The paper's figures 12-16 in one page: step, sine tracking, turbulence, loop Bode."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(2, 2, figsize=(11, 7.5), constrained_layout=True)
    t = traces["t"]
    unit = report.get("step", {}).get("unit", "deg")
    for ax, key, title in ((axes[0, 0], "step", "step response"),
                           (axes[0, 1], "sine", f"sine tracking, {SINE_FREQ_HZ:g} Hz")):
        if key in traces:
            ref, out = traces[key]
            ax.plot(t, ref, "--", color="k", label="reference")
            ax.plot(t, out, label="response")
            ax.set_xlim(0, 10)
        ax.set_title(title)
        ax.set_xlabel("time (s)")
        ax.set_ylabel(f"{report['axis']} ({unit})")
        ax.grid(alpha=0.3)
        ax.legend(fontsize=8)
    ax = axes[1, 0]
    if "turbulence" in traces:
        tr = traces["turbulence"]
        ax.plot(t, tr["gust"], color="0.7", label="gust rate (deg/s)")
        ax.plot(t, tr["rate"], label="rate, closed loop (deg/s)")
        if "angle" in tr:
            ax.plot(t, tr["angle"], label="angle, closed loop (deg)")
        ax.set_title(f"Dryden turbulence, {report['turbulence']['level']}")
    ax.set_xlabel("time (s)")
    ax.set_ylabel("deg/s, deg")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    ax = axes[1, 1]
    w = np.logspace(-1, 3, 400)
    for name, L in (("rate loop L_r", loops["L_r"]), ("angle loop L_a", loops["L_a"])):
        if L is None:
            continue
        resp = L(1j * w)
        ax.semilogx(w, 20 * np.log10(np.abs(resp)), label=f"{name}: PM "
                    f"{report['loops']['rate' if 'rate' in name else 'angle']['phase_margin_deg'] or float('nan'):.0f} deg")
    ax.axhline(0, color="k", lw=0.8)
    ax.set_title("loop gains")
    ax.set_xlabel("frequency (rad/s)")
    ax.set_ylabel("magnitude (dB)")
    ax.grid(alpha=0.3, which="both")
    ax.legend(fontsize=8)
    fig.suptitle(f"{report['axis']}: closed-loop validation of the identified model")
    save_figure(fig, path, dpi=100)
    plt.close(fig)
