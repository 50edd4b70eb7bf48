"""``heliquad tune``'s work: identified models (one MODELS.json per axis) to the gains
designed for them (host/validate/tuning.py), what they and the current gains predict, and
the files: tune.json (host/records/tune.py), tuned.params (QGroundControl's format, as
``heliquad params save`` writes it) and tune.png (host/present/tune.py); docs/tuning.md."""

from __future__ import annotations

import dataclasses
import math
import os

import numpy as np

from ...sim.base.dialect import dialect
from ...sim.base.errors import InputError
from .. import __version__
from ..acquire.param_protocol import Param
from ..acquire.sweep import TUNING_TOP_HZ
from ..records.gains import DERIVATIVE_FILTER_N, Gains, gains_params
from ..records.models import check_plant_models, read_models_json
from ..records.params_file import write_params_file
from ..records.points import read_points_csv
from ..records.tune import TuneFile, write_tune_json
from ..validate import loops as L
from ..validate.closed_loop import (margins_record, model_gains, validate_model,
                                    validation_record)
from ..validate.tune_step import step_traces
from ..validate.tuning import Plant, Spec, Uncertainty, design_axis

__all__ = ["AxisInput", "axis_input", "tune_axis", "tune_models", "spec_record", "write_outputs",
           "TUNE_JSON", "TUNED_PARAMS", "TUNE_FIGURE"]

TUNE_JSON, TUNED_PARAMS, TUNE_FIGURE = "tune.json", "tuned.params", "tune.png"
#: A proposed sweep reaches this factor beyond the crossovers it must measure.
SWEEP_REACH = 1.5


@dataclasses.dataclass(frozen=True)
class AxisInput:
    """One axis's input: its MODELS.json, the models to design on (recommended first, then
    the second-best when there is one), the band, the points' uncertainty, the current
    gains and where they come from, and what was said in choosing them."""

    path: str
    axis: str
    index: int
    plants: tuple
    band: tuple
    rel_sigma: tuple
    current: Gains
    current_from: str
    said: tuple


def _unstable(m) -> bool:
    if m.stable is False:
        return True
    return any(re > 0 for re, _ in (m.poles or ()))


def _name(index, m) -> str:
    return f"models[{index}] ({len(m.num) - 1}/{len(m.den) - 1}, delay {m.delay_s * 1e3:.3g} ms)"


def _second(doc, index):
    """The second-best model: of the others, stable and not degenerate, the lowest AICc."""
    others = [(i, m) for i, m in enumerate(doc.models) if i != index and not _unstable(m)
              and not m.degenerate and m.stable is not None
              and math.isfinite(m.metrics.get("aicc") or math.inf)]
    return min(others, key=lambda im: im[1].metrics["aicc"], default=None)


def _relative_sigma(path, doc) -> tuple:
    """The points' ``(omega, sigma / |G|)`` from the points file beside MODELS.json, or
    ``((), ())`` when there is none or it has no sigma."""
    if not doc.points_file:
        return (), ()
    points_path = os.path.join(os.path.dirname(os.path.abspath(path)), doc.points_file)
    if not os.path.exists(points_path):
        return (), ()
    pts = [p for p in read_points_csv(points_path) if math.isfinite(p.sigma) and abs(p.gain) > 0]
    return (tuple(p.omega_rad_s for p in pts), tuple(p.sigma / abs(p.gain) for p in pts))


def axis_input(path) -> AxisInput:
    """A MODELS.json checked for the design: its axis, a recommended model that is stable
    (by the poles identify recorded), its band; InputError otherwise."""
    doc = read_models_json(path)
    check_plant_models(path, doc, "tune")
    if doc.axis is None:
        raise InputError(f"{path} does not say which axis its models are of (identify writes "
                         "\"axis\")")
    index = doc.recommended
    if index is None:
        raise InputError(f"{path}: no recommended model ({doc.reason or 'none was'}); "
                         "tune designs on the recommended one")
    m = doc.models[index]
    if _unstable(m):
        raise InputError(f"{path}: the recommended model {_name(index, m)} is unstable (poles "
                         f"{', '.join(f'{re:.3g}{im:+.3g}j' for re, im in m.poles or ())})")
    if doc.band_rad_s is None:
        raise InputError(f"{path} does not give the band its models were identified over "
                         "(band_rad_s): the margins could not be measured")
    plants = [Plant(_name(index, m), tuple(m.num), tuple(m.den), float(m.delay_s),
                    doc.imu_path)]
    said = []
    second = _second(doc, index)
    if second is None:
        said.append("no second stable model in the file: the design holds on the recommended "
                    "one alone")
    else:
        plants.append(Plant(_name(*second), tuple(second[1].num), tuple(second[1].den),
                            float(second[1].delay_s), doc.imu_path))
    rel = _relative_sigma(path, doc)
    if not rel[0]:
        said.append("no points with sigma beside the models: the margins carry no "
                    "uncertainty from them")
    current, where = model_gains(doc, doc.axis)
    return AxisInput(path, doc.axis, index, tuple(plants), tuple(doc.band_rad_s), rel,
                     current, where, tuple(said))


@dataclasses.dataclass
class AxisResult:
    """One axis tuned: ``outcome`` ``met`` (the spec holds in prediction), ``band`` (the
    band forbids every design the spec allows) or ``spec`` (the spec allows none), with
    ``message`` saying why for the last two; ``entry`` tune.json's ``axes.AXIS`` and
    ``traces`` the figure's (``current``, ``tuned``), both None unless met."""

    inp: AxisInput
    outcome: str
    message: str = ""
    entry: dict | None = None
    traces: dict | None = None


def spec_record(spec: Spec) -> dict:
    """tune.json's ``spec``: the figures designed to, and the firmware's facts the design
    took (its derivative filter's N, its loop rate)."""
    return {**dataclasses.asdict(spec), "derivative_filter_n": DERIVATIVE_FILTER_N,
            "loop_rate_hz": 1.0 / L.LOOP_DT_S}


def _sensitivity(loops, name, omega):
    """The factor a relative error of the model takes into loop ``name`` at ``omega``: 1 for
    the loops linear in it, ``|1 / (1 + L_r)|`` for the angle loop."""
    if name != "angle" or omega is None:
        return 1.0
    return float(abs(1.0 / (1.0 + loops["rate"](np.array([omega]))[0])))


def _loop_records(plant, axis, gains, band, unc):
    """Per loop of ``gains`` on ``plant``: margins_record with ``uncertainty`` (the
    half-widths at its reported crossovers), and the raw margins."""
    h, h_a = plant.responses()
    loops = L.loop_functions(h, None if axis == "yaw" else h_a, gains)
    out, raw = {}, {}
    for name, f in loops.items():
        raw[name] = lp = L.margins(f, band)
        rec = margins_record(lp)
        u = {}
        if lp["gain_crossover_rad_s"] is not None:
            w = lp["gain_crossover_rad_s"]
            u["phase_margin_deg"] = float(unc.half_widths(w, _sensitivity(loops, name, w))[0][0])
        if lp["phase_crossover_rad_s"] is not None:
            w = lp["phase_crossover_rad_s"]
            gain = float(unc.half_widths(w, _sensitivity(loops, name, w))[1][0])
            if math.isfinite(gain):
                u["gain_margin_db"] = gain
        out[name] = {**rec, "uncertainty": u, "extrapolated": _extrapolated(lp)}
    return out, raw, loops


#: Each reported margin, the key of its crossover and the list it is among.
_READ_AT = {"phase_margin_deg": ("gain_crossover_rad_s", "gain_crossovers"),
            "gain_margin_db": ("phase_crossover_rad_s", "phase_crossovers")}


def _extrapolated(lp) -> list:
    """The reported margins of a loop (:func:`heliquad.host.validate.loops.margins`) read at
    a crossover outside the identified band: the model has no data there, so their
    prediction bounds nothing (tune.json's ``extrapolated``)."""
    return [key for key, (at, among) in _READ_AT.items()
            if lp[at] is not None and not L.crossover_in_band(lp[among], lp[at])]


def _failures(plant, axis, gains, band, spec, unc, rate_band=True) -> list:
    """The spec's constraints ``gains`` break on ``plant``, one sentence each (exact
    margins, :func:`heliquad.host.validate.loops.margins`)."""
    _, raw, loops = _loop_records(plant, axis, gains, band, unc)
    out = []
    for name, lp in raw.items():
        for c in lp["gain_crossovers"]:
            w = c["omega_rad_s"]
            pm = math.degrees(c["phase_margin_rad"])
            unc_pm = float(unc.half_widths(w, _sensitivity(loops, name, w))[0][0])
            if pm - unc_pm < spec.phase_margin_deg - 1e-6:
                out.append(f"{name} loop: phase margin {pm:.1f} deg less {unc_pm:.1f} deg of "
                           f"uncertainty at {w:.3g} rad/s, below {spec.phase_margin_deg:g}")
            if rate_band and not c["in_band"]:
                out.append(f"{name} loop: gain crossover at {w:.3g} rad/s outside the "
                           f"identified band ({band[0]:.3g}-{band[1]:.3g} rad/s)")
        for c in lp["phase_crossovers"]:
            w = c["omega_rad_s"]
            gm = 20 * math.log10(c["gain_margin"])
            unc_gm = float(unc.half_widths(w, _sensitivity(loops, name, w))[1][0])
            if abs(gm) - unc_gm < spec.gain_margin_db - 1e-6:
                out.append(f"{name} loop: gain margin {gm:.1f} dB less {unc_gm:.1f} dB of "
                           f"uncertainty at {w:.3g} rad/s, below {spec.gain_margin_db:g}")
    return out


def _step_size(axis, spec):
    """The spec's step: ``(size in rad or rad/s, size as said, unit)``."""
    if axis == "yaw":
        return math.radians(spec.step_rate_deg_s), spec.step_rate_deg_s, "deg/s"
    return math.radians(spec.step_angle_deg), spec.step_angle_deg, "deg"


def _prediction(inp, gains, spec, unc):
    """What ``gains`` predict on the recommended model: tune.json's design (``gains``,
    ``loops``, ``step``, ``disturbance``, ``stable``) and the figure's traces."""
    plant = inp.plants[0]
    loops, _, _ = _loop_records(plant, inp.axis, gains, inp.band, unc)
    report, traces = validate_model(plant.num, plant.den, plant.delay_s, inp.axis, gains,
                                    "moderate", 0, band_rad_s=inp.band,
                                    imu_path=plant.imu_path)
    out = {"gains": {"rate": list(gains.rate),
                     "angle": None if gains.angle is None else list(gains.angle)},
           "loops": loops, "stable": report["stable"]}
    figure = {"loop_gains": traces["loop_gains"]}
    if report["stable"]:
        size, said, unit = _step_size(inp.axis, spec)
        t, response, command = step_traces(plant.num, plant.den, plant.delay_s, gains,
                                           inp.axis, size, imu_path=plant.imu_path)
        rec = validation_record(report)
        out["step"] = {**rec.step, "size": said, "unit": unit,
                       "peak_command": float(np.max(np.abs(command)))}
        out["disturbance"] = dict(rec.turbulence)
        figure["step"] = (t, np.degrees(response), command, said)
    return out, figure


def _design(inp, spec, unc):
    """The design on every plant; when it fails there and the recommended model alone
    allows one, that one, with a sentence on the second-best model: ``(design, the plants
    it holds on, sentences)``."""
    design = design_axis(inp.axis, inp.plants, inp.band, spec, unc)
    if design.gains is not None or len(inp.plants) == 1:
        return design, inp.plants, []
    alone = design_axis(inp.axis, inp.plants[:1], inp.band, spec, unc)
    if alone.gains is None and (alone.free_crossover_rad_s is None
                                or design.free_crossover_rad_s is not None):
        return design, inp.plants, []
    return alone, inp.plants[:1], [f"the spec cannot be held on the second-best model {inp.plants[1].name} as "
                   f"well ({design.limit}): designed on the recommended model alone"]


def _band_message(inp, design, unc, spec) -> str:
    """The band forbids it: where the spec's fastest design crosses, and the sweep band
    that would measure it."""
    raw = _loop_records(inp.plants[0], inp.axis, design.free_gains, inp.band, unc)[1]["rate"]
    gcs = [c["omega_rad_s"] for c in raw["gain_crossovers"]] or [design.free_crossover_rad_s]
    lo = min(inp.band[0], min(gcs) / SWEEP_REACH) / (2 * math.pi)
    hi = max(inp.band[1], max(gcs) * SWEEP_REACH) / (2 * math.pi)
    asked = f" at least {spec.min_crossover_rad_s:g} rad/s" if spec.min_crossover_rad_s else ""
    return (f"{inp.axis}: the band forbids it: no rate crossover{asked} inside the identified "
            f"band ({inp.band[0]:.3g}-{inp.band[1]:.3g} rad/s) keeps the spec; it holds with "
            f"the rate loop crossing at {', '.join(f'{w:.3g}' for w in gcs)} rad/s; sweep "
            f"{lo:.2g}-{hi:.2g} Hz to measure it (--freqs-hz from {lo:.2g} up to {hi:.2g})")


def tune_axis(inp: AxisInput, spec: Spec) -> AxisResult:
    """Design ``inp``'s axis to ``spec`` and predict what the current and tuned gains do."""
    unc = Uncertainty(*inp.rel_sigma, k=spec.coverage_k)
    design, plants, said = _design(inp, spec, unc)
    if design.gains is None and design.free_crossover_rad_s is None:
        return AxisResult(inp, "spec", f"{inp.axis}: the spec cannot be met on "
                          f"{inp.plants[0].name} at any rate crossover ({design.limit})")
    if design.gains is None and design.crossover_rad_s is None:
        return AxisResult(inp, "band", _band_message(inp, design, unc, spec))
    if design.gains is None:
        return AxisResult(inp, "spec", f"{inp.axis}: the spec cannot be met on "
                          f"{inp.plants[0].name}: {design.limit}")
    said = list(inp.said) + said + [_limit_sentence(inp, design)]
    current, current_fig = _prediction(inp, inp.current, spec, unc)
    tuned, tuned_fig = _prediction(inp, design.gains, spec, unc)
    failures = [f"{p.name}: {f}" for p in plants
                for f in _failures(p, inp.axis, design.gains, inp.band, spec, unc, p is plants[0])]
    if not tuned["stable"]:
        failures.append("the tuned cascade is unstable")
    elif tuned["step"]["peak_command"] > spec.command_max:
        failures.append(f"the step's peak command {tuned['step']['peak_command']:.2f} exceeds "
                        f"{spec.command_max:g}")
    said += failures
    extrapolated = [f"{name} loop: {why} (the model is extrapolated there)"
                    for name, lp in tuned["loops"].items() for why in lp["not_validated"]]
    if extrapolated:
        extrapolated.append(f"a tuning sweep (heliquad sweep --axis {inp.axis} --tuning-band, "
                            f"up to {TUNING_TOP_HZ:g} Hz) measures the model where these are read")
    said += extrapolated
    entry = {"models": os.path.abspath(inp.path), "model_index": inp.index,
             "band_rad_s": list(inp.band), "current": current, "tuned": tuned,
             "params": gains_params(inp.axis, design.gains), "meets_spec": not failures,
             "said": said, "current_from": inp.current_from,
             "current_meets_spec": _current_meets(inp, current, spec, unc),
             "crossover_limit": design.limit, "design_models": [p.name for p in plants]}
    return AxisResult(inp, "met" if not failures else "spec",
                      f"{inp.axis}: the designed gains fail the exact check: "
                      + "; ".join(failures), entry, {"current": current_fig, "tuned": tuned_fig})


def _current_meets(inp, current, spec, unc) -> bool:
    """The current gains meet the spec on the recommended model: stable, every margin, the
    rate loop in the band, the step's command within its limit."""
    if not current["stable"] or current["step"]["peak_command"] > spec.command_max:
        return False
    return not _failures(inp.plants[0], inp.axis, inp.current, inp.band, spec, unc)


def _limit_sentence(inp, design) -> str:
    wc, free = design.crossover_rad_s, design.free_crossover_rad_s
    text = f"the rate crossover ({wc:.3g} rad/s) is limited by {design.limit}"
    if design.limit == "the identified band" and free is not None and free > wc * 1.01:
        text += (f"; with a sweep up to {free * SWEEP_REACH / (2 * math.pi):.2g} Hz the spec "
                 f"would allow {free:.3g} rad/s")
    return text


def write_outputs(out, spec: Spec, results, layout="qgc") -> list:
    """tune.json and tuned.params (the tuned axes' gains only, in ``layout``:
    :func:`~heliquad.host.records.params_file.write_params_file`'s) into ``out``; the
    names."""
    axes = {r.inp.axis: r.entry for r in results}
    write_tune_json(os.path.join(out, TUNE_JSON), TuneFile(spec=spec_record(spec), axes=axes))
    mav = dialect()
    params = [Param(name, value, mav.MAV_PARAM_TYPE_REAL32, i)
              for i, (name, value) in enumerate(
                  (n, v) for r in results for n, v in r.entry["params"].items())]
    write_params_file(os.path.join(out, TUNED_PARAMS), params,
                      header=f"heliquad {__version__}, gains designed by heliquad tune for "
                             f"{', '.join(axes)} (tune.json beside it)", layout=layout)
    return [TUNE_JSON, TUNED_PARAMS]


def tune_models(inputs, spec: Spec, out: str, layout: str = "qgc", progress=print) -> int:
    """``heliquad tune``'s work: each axis of ``inputs`` (:func:`axis_input`, one per axis) tuned to
    ``spec``, current against tuned said per axis, and, when every axis met it, tune.json,
    tuned.params (in ``layout``) and tune.png written into ``out``. Returns 0, or 1 when a
    band forbids the spec (said, with the sweep that would allow it; nothing written);
    InputError when the spec cannot be met or the input is bad."""
    # the figure's drawing (matplotlib) only when a tune runs
    from ..present.tune import write_tune_figure
    from ..records.figures import check_figure_output
    from ..records.output import check_output_folder

    seen = {}
    for inp in inputs:
        if inp.axis in seen:
            raise InputError(f"{inp.path} and {seen[inp.axis]} are both of {inp.axis}: give one "
                             "MODELS.json per axis")
        seen[inp.axis] = inp.path
    check_output_folder(out, "--out")
    results = [tune_axis(inp, spec) for inp in inputs]
    for r in results:
        if r.entry is not None:
            _print_axis(r.entry, r.inp.axis, progress)
    failed = [r.message for r in results if r.outcome == "spec"]
    if failed:
        raise InputError("; ".join(failed))
    forbidden = [r.message for r in results if r.outcome == "band"]
    if forbidden:
        for message in forbidden:
            progress(message)
        progress("nothing written")
        return 1
    os.makedirs(out, exist_ok=True)
    figure = os.path.join(out, TUNE_FIGURE)
    check_figure_output(figure, "--out")
    written = write_outputs(out, spec, results, layout=layout)
    write_tune_figure(figure, [(r.inp.axis, r.inp.band, r.traces) for r in results])
    progress(f"wrote {', '.join(os.path.join(out, n) for n in written + [TUNE_FIGURE])}")
    return 0


def _cell(design) -> dict:
    """The figures a design's column shows."""
    rate = design["loops"]["rate"]
    step = design.get("step")
    fmt = lambda v, f: "-" if v is None else format(v, f)             # noqa: E731
    return {"rate crossover (rad/s)": fmt(rate["gain_crossover_rad_s"], ".3g"),
            "rate PM (deg)": fmt(rate["phase_margin_deg"], ".1f"),
            "rate GM (dB)": fmt(rate["gain_margin_db"], ".1f"),
            **{f"{n} PM/GM": f"{fmt(lp['phase_margin_deg'], '.1f')} / "
                             f"{fmt(lp['gain_margin_db'], '.1f')}"
               for n, lp in design["loops"].items() if n != "rate"},
            "step rise 10-90 % (s)": fmt(step and step["rise_time_s"], ".3f"),
            "step overshoot (%)": fmt(step and step["overshoot_pct"], ".1f"),
            "step peak command": fmt(step and step["peak_command"], ".2f"),
            "turbulence rate RMS (deg/s)": fmt(design.get("disturbance", {}).get(
                "rate_rms_deg_s"), ".2f")}


def _print_axis(entry, axis, progress) -> None:
    """Current against tuned, side by side, and what limited the design."""
    cur, tun = _cell(entry["current"]), _cell(entry["tuned"])
    gains = lambda d: ", ".join(f"[{', '.join(f'{v:.4g}' for v in loop)}]"  # noqa: E731
                                for loop in d["gains"].values() if loop is not None)
    progress(f"{axis}: current gains {gains(entry['current'])} ({entry['current_from']}; "
          f"{'meets' if entry['current_meets_spec'] else 'does not meet'} the spec); tuned "
          f"{gains(entry['tuned'])} ({'meets' if entry['meets_spec'] else 'DOES NOT MEET'} it)")
    width = max(map(len, cur))
    progress(f"  {'':{width}}  {'current':>12}  {'tuned':>12}")
    for key in cur:
        progress(f"  {key:{width}}  {cur[key]:>12}  {tun[key]:>12}")
    for line in entry["said"]:
        progress(f"  {line}")
