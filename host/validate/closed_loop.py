"""Closed-loop validation of an identified model (``heliquad validate``; docs/paper.md, step 4).

The cascade of the paper as the firmware flies it (:mod:`.loops`): the firmware's discrete
PID rate loop at its loop rate around the identified model ``G`` (rate in, rate out; the
model's own sampled response, delay exact), and for roll and pitch the discrete PD angle
loop around it (the angle is the integral of the rate). Yaw is rate-only. The gains default
to those the firmware flies (read from its bindings: the paper's).

Reported: for each loop (``rate``, and for roll and pitch ``angle`` and ``input``, the loop
broken at the plant input with both closed) every crossover up to the Nyquist frequency,
the smallest phase margin and the gain margin nearest 0 dB, each marked not validated when
its crossover lies outside the band the model was identified over (the model says nothing
there); closed-loop stability from the discrete closed loop's poles (and, when unstable,
how far above the identified band they lie), the step response (rise time 10-90 %,
overshoot, 2 % settling), sine tracking (0.5 Hz), and disturbance rejection under Dryden
turbulence: the gust rate of the axis (sim/plant/dryden.py) entering at the model's input, with
the closed loop's rate and angle RMS against the gust's. With ``truth`` (the simulator's
sampled responses of a simulated sweep), the same margins of the truth's loops beside
them.

Everything here is computed in SI units: angles in rad, rates and frequencies in rad/s,
times in s, gain margins as ratios. Degrees, deg/s, dB and Hz are for people: they appear
only in validation.json (:func:`validation_record`, docs/file-formats.md), in what
``heliquad validate`` prints (from that record) and in the plot.
"""

from __future__ import annotations

import math
import os

import numpy as np

from ...sim.base import dialect as names
from ...sim.base.errors import InputError
from ...sim.plant.dryden import Dryden
from ...sim.plant.pid_model import pid_s_coeffs
from ...sim.plant.vehicle_params import load_params
from ..records import paper
from ..records.gains import DERIVATIVE_FILTER_N, Gains, load_gains, recorded_gains
from ..records.manifest import MANIFEST, read_manifest
from ..records.validation import ValidationFile
from . import loops as L
from .truth import sil_truth_loops

# Gains and load_gains are host/records/gains.py's, here for the validation's callers.
__all__ = ["Gains", "load_gains", "model_gains", "pid_tf", "validate_model", "validation_record", "margins_record",
           "instability_text", "paper_band", "sweep_inputs"]

DT_S = L.LOOP_DT_S
SINE_OMEGA_RAD_S = math.pi                      # 0.5 Hz
STEP_ANGLE_RAD = math.radians(10.0)
STEP_RATE_RAD_S = math.radians(30.0)
DURATION_S = 30.0
#: The sine's tracking error is measured over its last this many periods.
SINE_MEASURED_PERIODS = 5
#: Where the loop gains' frequency responses are evaluated (for the plot): up to Nyquist.
LOOP_GAIN_OMEGA_RAD_S = np.logspace(-1, math.log10(math.pi / DT_S * 0.999), 400)
#: An instability this many times above the identified band's top is flagged as outside it.
OUT_OF_BAND_FACTOR = 3.0


def pid_tf(kc, tau_i, tau_d):
    """The firmware's PID in continuous time, on the error as the paper writes it, as a
    python-control transfer function (:func:`heliquad.sim.plant.pid_model.pid_s_coeffs`,
    with the firmware's derivative filter). What the firmware flies is its Tustin form at
    the loop rate, :mod:`.loops`; this is the continuous form it approximates."""
    # python-control (1 s) only when a loop is analysed: identify imports this module
    import control

    return control.tf(*pid_s_coeffs(kc, tau_i, tau_d, DERIVATIVE_FILTER_N))


def paper_band(axis) -> tuple:
    """The paper's identification band of ``axis`` (its Table 1), rad/s: the band assumed
    for a model whose file does not give its own."""
    lo, hi = paper.BANDS_HZ[axis]
    return (2 * math.pi * lo, 2 * math.pi * hi)


def _unstable_pole(poles):
    """The fastest closed-loop pole on or outside the unit circle, as an s-plane magnitude
    (rad/s), or None."""
    out = poles[np.abs(poles) >= 1 - 1e-9]
    if not out.size:
        return None
    return float(np.max(np.abs(np.log(out.astype(complex))))) / DT_S


def _loops_report(functions, band, closed):
    """Each loop's margins (:func:`heliquad.host.validate.loops.margins`) and its closed loop's
    stability from the discrete poles ``closed`` (``{"rate": poles, "cascade": poles}``)."""
    out = {}
    for name, f in functions.items():
        poles = closed["rate" if name == "rate" else "cascade"]
        fast = _unstable_pole(poles)
        out[name] = {**L.margins(f, band, DT_S), "closed_loop_stable": fast is None,
                     "unstable_pole_rad_s": fast}
    return out


def truth_functions(truth, axis, gains):
    """The truth's loops (:func:`heliquad.host.validate.loops.loop_functions`): ``truth`` is
    ``(h, h_a)``, the simulator's sampled rate and angle responses (functions of rad/s;
    ``h_a`` None when not known, and then only the rate loop)."""
    h, h_a = truth
    return L.loop_functions(h, None if axis == "yaw" else h_a, gains, DT_S)


def _instability(report, band):
    """Where the cascade goes unstable, against the band the model was identified over:
    far above it, the model is extrapolated and says little."""
    freq = max(lp["unstable_pole_rad_s"] for lp in report["loops"].values()
               if lp["unstable_pole_rad_s"] is not None)
    top = band[1]
    return {"pole_rad_s": freq, "band_top_rad_s": top, "band_bottom_rad_s": band[0],
            "outside_band": bool(freq > OUT_OF_BAND_FACTOR * top
                                 or freq < band[0] / OUT_OF_BAND_FACTOR)}


def instability_text(inst) -> str:
    """One line on where an unstable cascade goes unstable (``inst``, a report's
    ``instability``) and what that means."""
    where = (f"closed-loop poles at {inst['pole_rad_s']:.3g} rad/s, "
             f"{inst['pole_rad_s'] / inst['band_top_rad_s']:.2g}x the identified band's top "
             f"({inst['band_top_rad_s']:.3g} rad/s)")
    if inst["pole_rad_s"] < inst.get("band_bottom_rad_s", 0.0):
        where = (f"closed-loop poles at {inst['pole_rad_s']:.3g} rad/s, below the identified "
                 f"band's bottom ({inst['band_bottom_rad_s']:.3g} rad/s)")
    if inst["outside_band"]:
        return (f"the cascade is unstable with these gains: {where}, where the model has no data; "
                "check with a model that rolls off there, or on the rig")
    return f"the cascade is unstable with these gains: {where}, inside what was identified"


def model_gains(doc, axis: str):
    """The gains to validate a MODELS.json ``doc``'s models with (a
    :class:`~heliquad.host.records.models.ModelsFile`), and where they come from: those its
    sweep read from the board it flew (``gains``, recorded by identify), else the firmware's
    defaults."""
    recorded = recorded_gains(doc.gains)
    if recorded is not None:
        return recorded, "the board's, as its sweep read them"
    return load_gains(axis), "the firmware's defaults (the models' file records none)"


def sweep_inputs(models_path, doc) -> dict:
    """:func:`validate_model`'s keywords for a model of the MODELS.json ``doc`` (a
    :class:`~heliquad.host.records.models.ModelsFile`) read from ``models_path``: the band its models were identified over (``band_rad_s``, None when
    the file does not say), the loop measured through the excitation (``measured``, its
    ``broken_loop``) and, when the file sits in a simulated sweep's folder (identify writes
    it there), the simulator's loop responses (``truth``)."""
    return {"band_rad_s": doc.band_rad_s, "measured": doc.broken_loop,
            "truth": _sweep_truth(models_path, doc.imu_path), "imu_path": doc.imu_path}


def _sweep_truth(models_path, imu_path):
    """The simulator's loop responses when MODELS.json sits in a simulated sweep's folder,
    else None."""
    folder = os.path.dirname(os.path.abspath(models_path))
    path = os.path.join(folder, MANIFEST)
    if not os.path.exists(path):
        return None
    try:
        truth, _ = sil_truth_loops(read_manifest(path), folder, imu_path)
    except InputError:                  # a damaged manifest beside: no truth, not an error
        return None
    return truth


def validate_model(num, den, delay_s, axis, gains: Gains, turbulence="moderate", seed=0,
                   band_rad_s=None, truth=None, measured=None, imu_path=None):
    """Margins, step, sine tracking and turbulence rejection, in SI units.

    ``band_rad_s``: the band the model was identified over (default the paper's for the
    axis). ``truth``: ``(h, h_a)``, the simulator's sampled responses, for
    :func:`truth_functions`. ``measured``: models.json's ``broken_loop`` (the loop measured
    through the excitation), carried into the report as ``measured_loop`` for a second
    opinion. ``imu_path``: the IMU path the sweep flew, how the logged angle follows the
    rate (:func:`heliquad.host.validate.loops.angle_over_rate`). Returns ``(report, traces)``. ``report``: ``axis``, the model
    (``num``, ``den``, ``delay_s``), ``gains``, ``band_rad_s``; ``loops``: per loop
    (``rate``; ``angle`` and ``input`` for roll and pitch) the margins of
    :func:`heliquad.host.validate.loops.margins` (``gain_margin`` a ratio, ``phase_margin_rad``,
    their crossovers, every crossover, ``not_validated``), ``closed_loop_stable``,
    ``unstable_pole_rad_s``; ``stable``; with ``truth``, ``truth`` (per loop, the same
    margins); when unstable ``instability`` (:func:`instability_text`), else ``step``
    (``quantity`` angle or rate, ``size`` in rad or rad/s, ``rise_time_s``,
    ``overshoot_pct``, ``settling_time_s``), ``sine`` (``omega_rad_s``, ``amplitude``,
    ``tracking_rms`` in the step's unit, ``tracking_rms_pct``) and, with ``turbulence``,
    ``turbulence`` (``level``, ``seed``, ``gust_rate_rms_rad_s``, ``rate_rms_rad_s``,
    ``angle_rms_rad``, ``angle_max_rad``). ``traces``: ``t`` (s), ``loop_gains``
    (``omega_rad_s``, each loop's complex gain there and, with ``truth``, ``truth``: each
    of the truth's loops' complex gain), and when stable ``step`` and ``sine``
    (reference, response) and ``turbulence`` (``gust``, ``rate``, ``angle``) in rad and
    rad/s. :func:`validation_record` turns the report into validation.json.
    """
    band = tuple(band_rad_s) if band_rad_s is not None else paper_band(axis)
    h, h_a = L.model_responses(num, den, delay_s, imu_path)
    outer = axis != "yaw" and gains.angle is not None
    functions = L.loop_functions(h, h_a if outer else None, gains, DT_S)
    cascade = L.discrete_cascade(num, den, delay_s, gains, DT_S, outer=outer, imu_path=imu_path)
    closed = {"rate": L.discrete_cascade(num, den, delay_s, gains, DT_S, outer=False).poles(),
              "cascade": cascade.poles()}
    report = {"axis": axis, "num": list(map(float, num)), "den": list(map(float, den)),
              "delay_s": float(delay_s), "band_rad_s": [float(b) for b in band],
              "gains": {"rate": list(gains.rate),
                        "angle": None if gains.angle is None else list(gains.angle)},
              "loops": _loops_report(functions, band, closed)}
    w = LOOP_GAIN_OMEGA_RAD_S
    traces = {"t": np.arange(0.0, DURATION_S, DT_S),
              "loop_gains": {"omega_rad_s": w, **{k: f(w) for k, f in functions.items()}}}
    if truth is not None:
        truths = truth_functions(truth, axis, gains)
        report["truth"] = {name: L.margins(f, band, DT_S) for name, f in truths.items()}
        traces["loop_gains"]["truth"] = {name: f(w) for name, f in truths.items()}
    if measured is not None and measured.get("loop") in functions:
        report["measured_loop"] = dict(measured)
    report["stable"] = all(lp["closed_loop_stable"] for lp in report["loops"].values())
    if not report["stable"]:
        report["instability"] = _instability(report, band)
        return report, traces
    t = traces["t"]
    report["step"], traces["step"] = _step(cascade, t, outer)
    report["sine"], traces["sine"] = _sine(cascade, t, report["step"]["size"], outer)
    if turbulence:
        report["turbulence"], traces["turbulence"] = _turbulence(cascade, axis, outer, t,
                                                                 turbulence, seed)
    return report, traces


def _rms(x):
    return float(np.sqrt(np.mean(np.square(x))))


def _respond(cascade, t, ref=None, d=None):
    """The discrete closed loop's outputs (rate, and angle with the outer loop) for a
    reference and a disturbance sequence on the loop's time grid ``t``."""
    # python-control (1 s) only when a loop is analysed: identify imports this module
    import control

    zero = np.zeros(t.size)
    u = np.vstack([zero if ref is None else ref, zero if d is None else d])
    return np.atleast_2d(control.forced_response(cascade, t, u).outputs)


def _step(cascade, t, outer):
    """The closed loop's response to a step of the reference: 10 deg of angle with the
    outer loop, else 30 deg/s of rate (in rad, rad/s)."""
    # python-control (1 s) only when a loop is analysed: identify imports this module
    import control

    size = STEP_ANGLE_RAD if outer else STEP_RATE_RAD_S
    ref = np.full(t.size, size)
    out = _respond(cascade, t, ref=ref)[1 if outer else 0]
    with np.errstate(divide="ignore", invalid="ignore"):    # final value 0: NaN times
        info = control.step_info(out, T=t)
    return ({"quantity": "angle" if outer else "rate", "size": size,
             "rise_time_s": float(info["RiseTime"]), "overshoot_pct": float(info["Overshoot"]),
             "settling_time_s": float(info["SettlingTime"])},
            (ref, out))


def _sine(cascade, t, amplitude, outer):
    """Tracking of a sine reference of ``amplitude`` at SINE_OMEGA_RAD_S, measured over its
    last periods (the start-up transient gone)."""
    ref = amplitude * np.sin(SINE_OMEGA_RAD_S * t)
    out = _respond(cascade, t, ref=ref)[1 if outer else 0]
    last = t >= t[-1] - SINE_MEASURED_PERIODS * 2 * math.pi / SINE_OMEGA_RAD_S
    rms = _rms((out - ref)[last])
    return ({"omega_rad_s": SINE_OMEGA_RAD_S, "amplitude": amplitude, "tracking_rms": rms,
             "tracking_rms_pct": 100 * rms / (amplitude / math.sqrt(2))},
            (ref, out))


def _turbulence(cascade, axis, outer, t, level, seed):
    """The axis's Dryden gust rate (rad/s) entering at the model's input, references zero.

    The identified models map a rate (command) to a rate, so the gust rate enters where the
    command does: the plant filters it, as the rotors' aerodynamics filter a gust. Added to
    the measured rate instead, the gust's whole spectrum, up to the Dryden filters' 14 rad/s
    corner, would pass unfiltered."""
    tp = load_params().turbulence
    d = Dryden(level, tp.altitude_m, tp.span_m, DT_S, seed)
    gust = d.block(t.size)[:, 3 + names.AXES[axis]]             # gust rates p, q, r, rad/s
    outputs = _respond(cascade, t, d=gust)
    rate = outputs[0]
    out = {"level": level, "seed": seed, "gust_rate_rms_rad_s": float(np.std(gust)),
           "rate_rms_rad_s": _rms(rate)}
    trace = {"gust": gust, "rate": rate}
    if outer:
        angle = outputs[1]
        out["angle_rms_rad"] = _rms(angle)
        out["angle_max_rad"] = float(np.max(np.abs(angle)))
        trace["angle"] = angle
    return out, trace


def validation_record(report) -> ValidationFile:
    """validation.json's record (docs/file-formats.md): the report of :func:`validate_model`
    in the units people read: gain margins in dB, phase margins, angles and rates in deg
    and deg/s, the sine's frequency in Hz; crossovers and poles stay in rad/s."""
    doc = {key: report[key] for key in ("axis", "num", "den", "delay_s", "gains", "band_rad_s")}
    doc["loops"] = {name: _loop_record(lp) for name, lp in report["loops"].items()}
    if "measured_loop" in report:
        doc["measured_loop"] = report["measured_loop"]
    if "truth" in report:
        doc["truth_loops"] = {name: margins_record(lp) for name, lp in report["truth"].items()}
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
    return ValidationFile(**doc)


def margins_record(lp) -> dict:
    """A loop's margins (:func:`heliquad.host.validate.loops.margins`) in dB and degrees, every
    crossover with them, for validation.json and models.json."""
    gm, pm = lp["gain_margin"], lp["phase_margin_rad"]
    return {"gain_margin_db": None if gm is None else 20 * math.log10(gm),
            "phase_margin_deg": None if pm is None else math.degrees(pm),
            **{k: lp[k] for k in ("gain_crossover_rad_s", "phase_crossover_rad_s")},
            "gain_crossovers": [{"omega_rad_s": c["omega_rad_s"],
                                 "phase_margin_deg": math.degrees(c["phase_margin_rad"]),
                                 "in_band": c["in_band"]} for c in lp["gain_crossovers"]],
            "phase_crossovers": [{"omega_rad_s": c["omega_rad_s"],
                                  "gain_margin_db": 20 * math.log10(c["gain_margin"]),
                                  "in_band": c["in_band"]} for c in lp["phase_crossovers"]],
            "not_validated": list(lp["not_validated"])}


def _loop_record(lp) -> dict:
    return {**margins_record(lp), "closed_loop_stable": lp["closed_loop_stable"],
            "unstable_pole_rad_s": lp["unstable_pole_rad_s"]}
