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

Everything here is computed in SI units: angles in rad, rates and frequencies in rad/s,
times in s, gain margins as ratios. Degrees, deg/s, dB and Hz are for people: they appear
only in validation.json (:func:`validation_record`, docs/file-formats.md), in what
``heliquad validate`` prints (from that record) and in the plot.
"""

from __future__ import annotations

import math
import os

import control
import numpy as np

from . import paper
from ..sim import dialect as names
from .files import write_json
from .gains import DERIVATIVE_FILTER_N, Gains, load_gains

# Gains and load_gains are host/gains.py's, here for the validation's callers.
__all__ = ["Gains", "load_gains", "pid_tf", "build_loops", "validate_model", "validation_record",
           "save_validation", "instability_text"]

PADE_ORDER = 3
DT_S = 0.005
SINE_OMEGA_RAD_S = math.pi                      # 0.5 Hz
STEP_ANGLE_RAD = math.radians(10.0)
STEP_RATE_RAD_S = math.radians(30.0)
DURATION_S = 30.0
#: The sine's tracking error is measured over its last this many periods.
SINE_MEASURED_PERIODS = 5
#: Where the loop gains' frequency responses are evaluated (for the plot).
LOOP_GAIN_OMEGA_RAD_S = np.logspace(-1, 3, 400)
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
    """Margins and crossovers of the loop gain ``L``, and whether its closed loop ``T`` is
    stable; None where a margin or crossover does not exist."""
    # For some loops (a zero at the origin) python-control meets NaN responses, which its
    # comparisons drop; numpy need not warn about them
    with np.errstate(invalid="ignore"):
        gm, pm_deg, _, wcg, wcp, _ = control.stability_margins(L, returnall=False)
    poles = control.poles(T)
    unstable = poles[np.real(poles) >= 0]
    finite = lambda x: float(x) if np.isfinite(x) else None      # noqa: E731
    return {"gain_margin": finite(gm) if gm > 0 else None,
            "phase_margin_rad": None if not np.isfinite(pm_deg) else math.radians(pm_deg),
            "gain_crossover_rad_s": finite(wcp),
            "phase_crossover_rad_s": finite(wcg),
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
    """Margins, step, sine tracking and turbulence rejection, in SI units.

    Returns ``(report, traces)``. ``report``: ``axis``, the model (``num``, ``den``,
    ``delay_s``), ``gains``; ``loops``: per loop (``rate``, and ``angle`` for roll and
    pitch) ``gain_margin`` (a ratio), ``phase_margin_rad``, ``gain_crossover_rad_s``,
    ``phase_crossover_rad_s``, ``closed_loop_stable``, ``unstable_pole_rad_s``;
    ``stable``; when unstable ``instability`` (:func:`instability_text`), else ``step``
    (``quantity`` angle or rate, ``size`` in rad or rad/s, ``rise_time_s``,
    ``overshoot_pct``, ``settling_time_s``), ``sine`` (``omega_rad_s``, ``amplitude``,
    ``tracking_rms`` in the step's unit, ``tracking_rms_pct``) and, with ``turbulence``,
    ``turbulence`` (``level``, ``seed``, ``gust_rate_rms_rad_s``, ``rate_rms_rad_s``,
    ``angle_rms_rad``, ``angle_max_rad``). ``traces``: ``t`` (s), ``loop_gains``
    (``omega_rad_s`` and each loop's complex gain), and when stable ``step`` and ``sine``
    (reference, response) and ``turbulence`` (``gust``, ``rate``, ``angle``) in rad and
    rad/s. :func:`validation_record` turns the report into validation.json.
    """
    loops = build_loops(num, den, delay_s, axis, gains)
    outer = loops["T_a"] is not None
    report = {"axis": axis, "num": list(map(float, num)), "den": list(map(float, den)),
              "delay_s": float(delay_s), "gains": {"rate": list(gains.rate),
                                                   "angle": None if gains.angle is None else list(gains.angle)},
              "loops": {"rate": _margins(loops["L_r"], loops["T_r"])}}
    w = LOOP_GAIN_OMEGA_RAD_S
    traces = {"t": np.arange(0.0, DURATION_S, DT_S),
              "loop_gains": {"omega_rad_s": w, "rate": loops["L_r"](1j * w)}}
    if outer:
        report["loops"]["angle"] = _margins(loops["L_a"], loops["T_a"])
        traces["loop_gains"]["angle"] = loops["L_a"](1j * w)
    report["stable"] = all(lp["closed_loop_stable"] for lp in report["loops"].values())
    if not report["stable"]:
        report["instability"] = _instability(report, axis)
        return report, traces
    T, t = (loops["T_a"] if outer else loops["T_r"]), traces["t"]
    report["step"], traces["step"] = _step(T, t, outer)
    report["sine"], traces["sine"] = _sine(T, t, report["step"]["size"])
    if turbulence:
        report["turbulence"], traces["turbulence"] = _turbulence(loops, axis, outer, t, turbulence, seed)
    return report, traces


def _rms(x):
    return float(np.sqrt(np.mean(np.square(x))))


def _step(T, t, outer):
    """The closed loop's response to a step of the reference: 10 deg of angle with the
    outer loop, else 30 deg/s of rate (in rad, rad/s)."""
    size = STEP_ANGLE_RAD if outer else STEP_RATE_RAD_S
    ref = np.full(t.size, size)
    out = control.forced_response(T, t, ref).outputs
    info = _step_info(T, t, out)
    return ({"quantity": "angle" if outer else "rate", "size": size,
             "rise_time_s": float(info["RiseTime"]), "overshoot_pct": float(info["Overshoot"]),
             "settling_time_s": float(info["SettlingTime"])},
            (ref, out))


def _step_info(T, t, step):
    """python-control's step figures of ``T``; from the simulated ``step`` when its own time
    grid fails (poles decades apart, or a very slow loop)."""
    with np.errstate(divide="ignore", invalid="ignore"):    # final value 0: NaN times
        try:
            return control.step_info(T)
        except (IndexError, ValueError, np.linalg.LinAlgError):
            return control.step_info(step, T=t)


def _sine(T, t, amplitude):
    """Tracking of a sine reference of ``amplitude`` at SINE_OMEGA_RAD_S, measured over its
    last periods (the start-up transient gone)."""
    ref = amplitude * np.sin(SINE_OMEGA_RAD_S * t)
    out = control.forced_response(T, t, ref).outputs
    last = t >= t[-1] - SINE_MEASURED_PERIODS * 2 * math.pi / SINE_OMEGA_RAD_S
    rms = _rms((out - ref)[last])
    return ({"omega_rad_s": SINE_OMEGA_RAD_S, "amplitude": amplitude, "tracking_rms": rms,
             "tracking_rms_pct": 100 * rms / (amplitude / math.sqrt(2))},
            (ref, out))


def _turbulence(loops, axis, outer, t, level, seed):
    """The axis's Dryden gust rate (rad/s) entering at the model's input, references zero.

    The identified models map a rate (command) to a rate, so the gust rate enters where the
    command does: the plant filters it, as the rotors' aerodynamics filter a gust. Added to
    the measured rate instead, the gust's whole spectrum, up to the Dryden filters' 14 rad/s
    corner, would pass unfiltered."""
    from ..sim.dryden import Dryden
    from ..sim.params import load_params

    tp = load_params().turbulence
    d = Dryden(level, tp.altitude_m, tp.span_m, DT_S, seed)
    gust = d.block(t.size)[:, 3 + names.AXES[axis]]             # gust rates p, q, r, rad/s
    s = control.tf("s")
    G, C_r = loops["G"], loops["C_r"]
    outer_gain = (1 + loops["C_a"] / s) if outer else 1
    to_rate = control.feedback(G, C_r * outer_gain)          # rate / d, d at the plant input
    rate = control.forced_response(to_rate, t, gust).outputs
    out = {"level": level, "seed": seed, "gust_rate_rms_rad_s": float(np.std(gust)),
           "rate_rms_rad_s": _rms(rate)}
    trace = {"gust": gust, "rate": rate}
    if outer:
        angle = control.forced_response(to_rate / s, t, gust).outputs
        out["angle_rms_rad"] = _rms(angle)
        out["angle_max_rad"] = float(np.max(np.abs(angle)))
        trace["angle"] = angle
    return out, trace


def validation_record(report) -> dict:
    """validation.json's content (docs/file-formats.md): the report of :func:`validate_model`
    in the units people read: gain margins in dB, phase margins, angles and rates in deg
    and deg/s, the sine's frequency in Hz; crossovers and poles stay in rad/s."""
    doc = {key: report[key] for key in ("axis", "num", "den", "delay_s", "gains")}
    doc["loops"] = {name: _loop_record(lp) for name, lp in report["loops"].items()}
    doc["stable"] = report["stable"]
    if "instability" in report:
        doc["instability"] = dict(report["instability"])
    if "step" in report:
        st, sn = report["step"], report["sine"]
        doc["step"] = {"size": math.degrees(st["size"]),
                       "unit": "deg" if st["quantity"] == "angle" else "deg/s",
                       **{k: st[k] for k in ("rise_time_s", "overshoot_pct", "settling_time_s")}}
        doc["sine"] = {"freq_hz": sn["omega_rad_s"] / (2 * math.pi),
                       "amplitude": math.degrees(sn["amplitude"]),
                       "tracking_rms": math.degrees(sn["tracking_rms"]),
                       "tracking_rms_pct": sn["tracking_rms_pct"]}
    if "turbulence" in report:
        tb = report["turbulence"]
        doc["turbulence"] = {"level": tb["level"], "seed": tb["seed"],
                             "gust_rate_rms_deg_s": math.degrees(tb["gust_rate_rms_rad_s"]),
                             "rate_rms_deg_s": math.degrees(tb["rate_rms_rad_s"])}
        if "angle_rms_rad" in tb:
            doc["turbulence"]["angle_rms_deg"] = math.degrees(tb["angle_rms_rad"])
            doc["turbulence"]["angle_max_deg"] = math.degrees(tb["angle_max_rad"])
    return doc


def _loop_record(lp) -> dict:
    gm, pm = lp["gain_margin"], lp["phase_margin_rad"]
    return {"gain_margin_db": None if gm is None else 20 * math.log10(gm),
            "phase_margin_deg": None if pm is None else math.degrees(pm),
            **{k: lp[k] for k in ("gain_crossover_rad_s", "phase_crossover_rad_s",
                                  "closed_loop_stable", "unstable_pole_rad_s")}}


def save_validation(folder, report, traces) -> list:
    """Write ``validation.json`` (:func:`validation_record`) and, when the cascade is
    stable, ``validation.png`` into ``folder``; returns the file names written."""
    os.makedirs(folder, exist_ok=True)
    write_json(os.path.join(folder, "validation.json"), validation_record(report))
    if not report["stable"]:
        return ["validation.json"]
    from .plot import write_validation

    write_validation(os.path.join(folder, "validation.png"), report, traces)
    return ["validation.json", "validation.png"]
