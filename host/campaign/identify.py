"""``heliquad identify DIR``: from a sweep's log to points, models and plots.

Reads ``DIR/manifest.json`` and ``DIR/sweep.tlog`` (or a board's log, a .BIN or a folder
holding one and no manifest: :mod:`.bin_sweep` finds the sweep it flew); for each frequency
the manifest marks as measured, takes the full-amplitude samples (HQ_EXCITATION_STATE_RUNNING) in its window, and runs
the FSF with the exact frequency the firmware reported. Writes, inside DIR (for a .BIN, the
folder that holds it):
``points.csv`` (the POINTS format), ``points_table.csv`` (the paper's tables 4-6: frequency,
omega, magnitude, phase, R, I), ``models.json`` (the axis's default orders, or those given),
``bode.png`` (points, models and the points' coherence) and ``responses.png`` (per
frequency the input and the output on their own axes, with the recommended model's replay of
the output, :mod:`.replay`).
"""

from __future__ import annotations

import math
import os

import numpy as np

from ...sim.base.dialect import AXES, INJECTIONS, dialect
from ...sim.base.errors import InputError
from ..acquire.link import (INPUT_OUTPUT, ROTOR_INPUT_OUTPUT, check_response, input_output,
                            response_fields, response_of)
from ..acquire.measure import saturation_text
from ..acquire.sweep import cut_text
from ..estimate.fit import n_parameters
from ..estimate.fsf import DEFAULT_DISCARD_PERIODS
from ..estimate.models import default_orders, fit_orders
from ..estimate.thresholds import LOW_COHERENCE
from ..present.plot_process import command_plots
from ..records.bin_log import is_ardupilot_log, is_bin_name, open_log
from ..records.manifest import MANIFEST, read_manifest
from ..records.models import fitted_models, write_models_json
from ..records.points import write_points_csv, write_points_table
from ..records.tlog import TlogDamage, imu_path_of, read_tlog_table
from ..validate.closed_loop import margins_record
from ..validate.loops import broken_loop, measured_loop_name
from ..validate.replay import replay_points
from ..validate.truth import sil_truth, truth_record
from .ardupilot_sweep import ardupilot_sweeps, segment_note
from .bin_sweep import bin_sweep
from .linearity import is_linearity, linearity_points
from .record import read_record, record_points
from .sweep_points import estimate_points

__all__ = ["identify_dir", "identify_path", "INPUT_OUTPUT", "load_sweep"]



def load_sweep(dir_path):
    """``(the folder for the outputs, manifest, samples, damage)`` of a sweep folder, a .BIN
    or a folder holding one .BIN and no manifest."""
    log = _log_file(dir_path)
    if log is not None:
        return (os.path.dirname(log) or ".", *bin_sweep(log))
    path = os.path.join(dir_path, MANIFEST)
    manifest = read_manifest(path)
    tlog = os.path.join(dir_path, manifest.get("tlog", "sweep.tlog"))
    if not os.path.exists(tlog):
        raise InputError(f"{dir_path}: the log {os.path.basename(tlog)} is missing")
    damage = TlogDamage()
    try:
        samples = read_tlog_table(tlog, dialect(), "HQ_SYSID_SAMPLE", damage=damage)
    except OSError as exc:
        raise InputError(f"{tlog}: {exc.strerror or exc}") from None
    _check_log_matches(dir_path, manifest, samples)
    # the IMU path the firmware flew, from its status in the same log (how its logged angle
    # follows its rate: host/validate/loops.py); kept with the manifest, not written to it
    return dir_path, {**manifest, "imu_path": imu_path_of(tlog, dialect())}, samples, damage


def _log_file(dir_path) -> str | None:
    """The log DIR is (a .BIN), or the one .BIN a folder without a manifest holds; None for a
    sweep folder."""
    if not os.path.isdir(dir_path):
        return dir_path
    if os.path.lexists(os.path.join(dir_path, MANIFEST)):
        return None
    logs = sorted(n for n in os.listdir(dir_path) if is_bin_name(n))
    if len(logs) > 1:
        raise InputError(f"{dir_path}: no {MANIFEST} and {len(logs)} .BIN logs "
                         f"({', '.join(logs[:3])}{', ...' if len(logs) > 3 else ''}): "
                         "give one of them")
    if not logs:
        raise InputError(f"{dir_path}: no {MANIFEST} (is it a sweep folder?)")
    return os.path.join(dir_path, logs[0])


def _check_log_matches(dir_path, manifest, samples) -> None:
    """The log's excitations are the manifest's: same axis and injection (a folder whose
    log comes from another session is refused, not fitted)."""
    idle = dialect().HQ_EXCITATION_STATE_IDLE
    want = (AXES.get(manifest.get("axis")), INJECTIONS.get(manifest.get("inject")))
    other = (samples.exc_state != idle) & ((samples.axis != want[0]) |
                                           (samples.injection != want[1]))
    if other.any():
        first = samples[np.flatnonzero(other)[0]]
        names = {v: k for k, v in AXES.items()}, {v: k for k, v in INJECTIONS.items()}
        axis, injection = int(first.axis), int(first.injection)
        raise InputError(f"{dir_path}: the log excites {names[0].get(axis, axis)} with "
                         f"{names[1].get(injection, injection)} injection, the manifest "
                         f"says {manifest.get('axis')} with {manifest.get('inject')}: the "
                         "log and the manifest are not of one session")


def identify_dir(dir_path: str, orders=None, progress=print, delay: bool = True,
                 estimate: str = "excitation", plots=None, cost: str = "j",
                 from_record: dict | None = None, response: str | None = None) -> dict:
    """``cost``: what the fits minimise (CIFER's J by default, or ``relative``,
    host/estimate/fit.py). ``response``: what a rate or angle sweep's points are
    (``loop`` or ``plant``, :func:`~heliquad.host.acquire.link.response_fields`; None: the
    sweep's own). ``from_record``: read the log as one record
    (:mod:`.record`; a dict of :func:`~.record.record_points`'s options, ``axis``,
    ``fields``, ``band_hz``) instead of its designed excitations. ``plots``: what draws
    the plots (a :mod:`~heliquad.host.present.plot_process` object the caller has started
    and will close); by default :func:`~heliquad.host.present.plot_process.command_plots`'s:
    a process of its own, which draws them while the models are fitted (in this process
    within ``drawing_here``)."""
    if plots is None:
        # The plotting process starts first: its imports overlap reading the log.
        with command_plots() as plots:
            return identify_dir(dir_path, orders, progress, delay, estimate, plots, cost,
                                from_record, response)
    if from_record is not None:
        return _identify_record(dir_path, plots, orders, progress, delay, estimate, cost,
                                from_record)
    out_dir, manifest, samples, damage = load_sweep(dir_path)
    if manifest["inject"] in ROTOR_INPUT_OUTPUT:
        raise InputError(f"{dir_path}: a per-rotor run (motors injection): heliquad "
                         "effectiveness reads it")
    manifest = _with_response(dir_path, manifest, response)
    return _identify(dir_path, out_dir, manifest, samples, damage, plots, orders, progress,
                     delay, estimate, cost)


def _with_response(path, manifest, response):
    """The manifest with ``response`` (identify --response) in place of its own: refused
    where the injection has no other (a mixer sweep measures the plant)."""
    if response is None or response == manifest.get("response"):
        return manifest
    try:
        check_response(manifest["inject"], response)
    except InputError as exc:
        raise InputError(f"{path}: {exc}; this is a {manifest['inject']} sweep") from None
    return {**manifest, "response": response}


def identify_path(path, orders=None, progress=print, plots=None, **options) -> list:
    """:func:`identify_dir`'s result for each sweep at ``path`` (its ``options`` too): one
    for a sweep folder, a record or a .BIN of heliquad's, one per SystemID segment of an
    ArduPilot log (:mod:`.ardupilot_sweep`), each written into a folder of its own beside the
    log (``LOG-sidK-AXIS``); a segment that cannot be measured is said and skipped."""
    log = None if options.get("from_record") is not None else _log_file(path)
    opened = open_log(log) if log is not None else None
    if opened is None or not is_ardupilot_log(opened[0]):
        return [identify_dir(path, orders, progress, plots=plots, **options)]
    if plots is None:
        with command_plots() as plots:
            return identify_path(path, orders, progress, plots, **options)
    sweeps, skipped, damage = ardupilot_sweeps(log, opened)   # its damage said by _identify
    for line in skipped:
        progress(f"warning: {line}: not identified")
    stem = os.path.splitext(os.path.basename(log))[0]
    results, failed = [], []
    for name, manifest, samples in sweeps:
        out_dir = os.path.join(os.path.dirname(log) or ".", f"{stem}-{name}")
        progress(f"{name}: {segment_note(manifest)}; outputs in {out_dir}")
        try:
            manifest = _with_response(name, manifest, options.get("response"))
            os.makedirs(out_dir, exist_ok=True)
            results.append(_identify(log, out_dir, manifest, samples, damage, plots,
                                     orders, progress, options.get("delay", True),
                                     options.get("estimate", "excitation"),
                                     options.get("cost", "j")))
        except InputError as exc:
            failed.append(f"{name}: {exc}")
            progress(f"warning: {name} not identified: {exc}")
    if not results:
        raise InputError(f"{log}: no SystemID segment identified ({'; '.join(failed)})")
    return results


def _identify(dir_path, out_dir, manifest, samples, damage, plots, orders, progress, delay,
              estimate, cost) -> dict:
    cut = cut_text(manifest)
    if cut:
        progress(f"warning: {cut}; the points are those it measured")
    if damage:
        progress(f"warning: {manifest.get('tlog', 'sweep.tlog')} is damaged: {damage.summary()}; "
                 f"{damage.KEPT}")
    axis = manifest["axis"]
    by_entry = []
    points, segments, firsts, skipped = estimate_points(manifest, samples, estimate, progress,
                                                        by_entry)
    linearity = None
    if is_linearity(manifest):          # the best linear approximation is what is fitted
        points, linearity = linearity_points(manifest, by_entry, progress)
    saturated = _saturated(manifest)
    for text in saturated:
        progress(f"  warning: {text}: the record is not the linear response")
    if len(points) < 2:
        why = f" (skipped {'; '.join(skipped[:2])}{'; ...' if len(skipped) > 2 else ''})" \
            if skipped else ""
        aborted = f"; the sweep ended early: {manifest['aborted']}" if manifest.get("aborted") else ""
        raise InputError(f"{dir_path}: {len(points)} frequency(ies) with a usable excitation; "
                         f"a fit needs at least 2{why}{aborted}")
    plots.records(segments, *response_fields(manifest["inject"], manifest.get("response")))
    result = _points_and_fits(dir_path, out_dir, axis, points, orders, delay, cost)
    loop = _broken_loop(manifest, points, estimate, progress)
    truth = _truth(dir_path, manifest, points, result, progress)
    replays = _replays(result, firsts, segments)
    write_models_json(os.path.join(out_dir, "models.json"), fitted_models(
        result, log=damage.record(), skipped_frequencies=skipped,
        saturated_frequencies=saturated, estimate=estimate,
        signal=manifest.get("signal", "dwell"),
        gains=manifest.get("gains") or None,        # what the board flew, for validate
        broken_loop=loop or None, sil_truth=truth or None,
        replay=None if replays is None else _replay_record(result.recommended, replays),
        axis=axis, points_file="points.csv", imu_path=manifest.get("imu_path"),
        linearity=linearity, response=manifest.get("response")))
    if linearity and linearity["flagged"]:
        progress("warning: the models are fitted where the nonlinear distortion is above the "
                 "noise and above "
                 f"{linearity['distortion_limit_db']:g} dB of the response: a linear model "
                 "does not hold at this amplitude (models.json linearity)")
    _write_plots(plots, out_dir, manifest, points, result, replays,
                 "a chirp's record has no periods to replay"
                 if any(p.method == "composite" for p in firsts) else None)
    return {"out_dir": out_dir, "axis": axis, "points": points, "result": result, "manifest": manifest,
            "damage": damage, "skipped": skipped, "saturated": saturated, "truth": truth,
            "records": segments, "record_points": firsts, "replays": replays,
            "linearity": linearity}


def _points_and_fits(path, out_dir, axis, points, orders, delay, cost):
    """points.csv and points_table.csv written, and the fits of the orders asked for (by
    default the axis's, :func:`~..estimate.models.default_orders`) that the points support."""
    write_points_csv(os.path.join(out_dir, "points.csv"), points)
    write_points_table(os.path.join(out_dir, "points_table.csv"), points)
    wanted = orders or default_orders(axis, max(p.omega_rad_s for p in points) / (2 * math.pi))
    orders = [o for o in wanted if 2 * len(points) >= n_parameters(o, delay) + 1]
    if not orders:
        raise InputError(f"{path}: {len(points)} points are too few for orders {wanted}")
    return fit_orders(points, orders, delay=delay, cost=cost)


def _identify_record(path, plots, orders, progress, delay, estimate, cost, options) -> dict:
    """identify's work on a record read as one (:mod:`.record`): the composite's points, the
    fits, the broken loop and the simulator's truth where they apply; no replay (a record
    has no periods to replay)."""
    if os.path.isdir(path):             # a sweep folder: its manifest names axis and injection
        out_dir, manifest, samples, damage = load_sweep(path)
    else:
        manifest, (samples, damage, out_dir) = None, read_record(path)
    if damage:
        progress(f"warning: the log is damaged: {damage.summary()}; {damage.KEPT}")
    found = record_points(manifest, samples, estimate, progress, **options)
    points, skipped, axis = found["points"], found["skipped"], found["axis"]
    for text in skipped:
        progress(f"  {text}: left out")
    if len(points) < 2:
        raise InputError(f"{path}: {len(points)} point(s) with coherence enough for a fit, "
                         "at least 2 are needed (a longer record, or more excitation)")
    inject = found["inject"]
    u_name, y_name = found["record"]["input"], found["record"]["output"]
    plots.records([found["segment"]], u_name, y_name)
    result = _points_and_fits(path, out_dir, axis, points, orders, delay, cost)
    said = {"axis": axis, "inject": inject}
    loop = _broken_loop(said, points, found["record"]["estimate"], progress) \
        if (u_name, y_name) == input_output(inject) else None
    response = response_of(inject, (u_name, y_name))   # the truth there is, if any
    truth = _truth(out_dir, {**manifest, "response": response}, points, result, progress) \
        if manifest and response else None
    write_models_json(os.path.join(out_dir, "models.json"), fitted_models(
        result, log=damage.record(), skipped_frequencies=skipped,
        estimate=found["record"]["estimate"], record=found["record"],
        gains=(manifest or {}).get("gains") or None, broken_loop=loop or None,
        sil_truth=truth or None, axis=axis, points_file="points.csv",
        imu_path=(manifest or {}).get("imu_path")))
    _write_plots(plots, out_dir, said, points, result, None,
                 "a record read as one: no periods to replay")
    return {"out_dir": out_dir, "axis": axis, "points": points, "result": result,
            "manifest": manifest, "damage": damage, "skipped": skipped, "saturated": [],
            "truth": truth, "records": [found["segment"]], "record_points": [],
            "replays": None, "record": found["record"]}


def _replays(result, points, segments):
    """The recommended model's replay of each record (:mod:`.replay`; ``points``: each
    record's first point), or None when no model is recommended or a record is a chirp's
    (no periods to replay)."""
    if result.recommended is None or any(p.method == "composite" for p in points):
        return None
    return replay_points(result.models[result.recommended], points, segments,
                         DEFAULT_DISCARD_PERIODS)


def _replay_record(recommended, replays) -> dict:
    """models.json's ``replay``: the replayed model's index and, per frequency, the whole
    periods replayed and the replay's error."""
    return {"model": recommended, "discard_periods": DEFAULT_DISCARD_PERIODS,
            "points": [{"freq_hz": r.freq_hz, "periods": r.periods, "nrmse": r.nrmse}
                       for r in sorted(replays, key=lambda r: r.freq_hz)]}


def _write_plots(plots, dir_path, manifest, points, result, replays, no_replay=None) -> None:
    """bode.png (the points with their coherence, and the models) and responses.png (each
    record, with the recommended model's replay), by the plotting process ``plots``."""
    axis, inject = manifest["axis"], manifest["inject"]
    bode = {"path": os.path.join(dir_path, "bode.png"), "points": points,
            "models": result.models, "recommended": result.recommended,
            "title": f"{axis}, {inject} injection: points, models and coherence",
            "gate": LOW_COHERENCE}
    said = "dashed: the recommended model's replay" if replays is not None else \
        no_replay or "no model recommended, so no replay"
    plots.finish(bode, {"path": os.path.join(dir_path, "responses.png"), "replays": replays,
                        "title": f"{axis}: measured cycles, input (left axis) and output "
                                 f"(right axis); {said}"})


def _truth(dir_path, manifest, points, result, progress) -> dict | None:
    """A simulated sweep: the points' and the recommended model's errors against the
    simulator's truth (:mod:`.truth`), said and returned for models.json."""
    truth, why = sil_truth(manifest, dir_path)
    if truth is None:
        if manifest.get("source", {}).get("kind") == "sil":
            progress(f"  no simulator truth: {why}")
        return None
    model = None if result.recommended is None else result.models[result.recommended]
    record = truth_record(truth, points, model)
    z = record["points_rms_error_over_sigma"]
    said = (f"against the simulator's truth: points within {record['points_worst_db']:.2f} dB "
            f"and {record['points_worst_deg']:.1f} deg"
            + (f" (RMS error/sigma {z:.2f})" if z is not None else ""))
    if model is not None:
        said += (f"; the recommended model within {record['model_worst_db']:.2f} dB and "
                 f"{record['model_worst_deg']:.1f} deg across the band")
    progress(said)
    return record


def _broken_loop(manifest, points, estimate, progress) -> dict | None:
    """The loop broken where the excitation enters, measured from the points' ``U/R``
    (``L = R/U - 1``), its margins where the points reach its crossovers; said, and
    returned for models.json (None when no loop closes there or the points were not
    estimated against the excitation)."""
    name = measured_loop_name(manifest["inject"], manifest["axis"])
    if manifest.get("response") == "plant":
        name = None     # the plant measured through a rate or angle loop: U is not R's sum
    pts = sorted(points, key=lambda p: p.omega_rad_s)
    t_u = np.array([p.input_gain for p in pts])
    if estimate != "excitation" or name is None or len(pts) < 2 or \
            not np.all(np.isfinite(t_u)) or np.any(t_u == 0):
        return None
    m = broken_loop([p.omega_rad_s for p in pts], t_u)
    record = {"loop": name, "injection": manifest["inject"], **margins_record(m),
              "unmeasured": m["unmeasured"],
              "points": [{"freq_hz": p.freq_hz, "magnitude_db": float(20 * np.log10(abs(v))),
                          "phase_deg": float(np.degrees(np.angle(v)))}
                         for p, v in zip(pts, m["L"])]}
    del record["not_validated"]
    said = []
    if record["gain_margin_db"] is not None:
        said.append(f"gain margin {record['gain_margin_db']:.1f} dB at "
                    f"{record['phase_crossover_rad_s']:.3g} rad/s")
    if record["phase_margin_deg"] is not None:
        said.append(f"phase margin {record['phase_margin_deg']:.1f} deg at "
                    f"{record['gain_crossover_rad_s']:.3g} rad/s")
    said += [f"no {why}" for why in record["unmeasured"]]
    progress(f"the {name} loop broken at the excitation, measured: {'; '.join(said)}")
    return record


def _saturated(manifest) -> list:
    """The measured frequencies during which something saturated, in words."""
    return [f"{e['freq_hz']:.4g} Hz{said}" for e in manifest["frequencies"]
            if e.get("status") == "ok" and "freq_hz" in e and (said := saturation_text(e))]
