"""One run of a study, as a worker makes it: the commands a user would type (``heliquad sweep
--sil ... --out F`` then ``heliquad identify F``), in this process, into the run's folder;
then the run's record, one flat set of figures read back from the files they wrote.

A run's folder (``DIR/runs/NAME``, docs/studies.md): ``started.json`` (written when an
attempt starts, counting the attempts), ``sweep/`` (the sweep folder, identify's files in
it), ``run.log`` (what the commands printed) and ``record.json``, written last and
atomically: the mark that the run is over (finished or failed), never made again.
"""

from __future__ import annotations

import json
import math
import os
import shutil
import socket
import time

from ...sim.base.errors import InputError
from .. import __version__
from ..records.manifest import excited_seconds
from ..records.output import atomic_write, write_json
from .perturb import VEHICLE_FILE, base_text, perturbed_text

__all__ = ["perform_run", "died_record", "worker_version", "read_record", "run_folder", "outcome", "RECORD", "STARTED",
           "SWEEP", "LOG", "RUNS", "FINISHED", "FAILED"]

#: The run folders' folder, in the study's.
RUNS = "runs"
#: A run folder's files.
RECORD, STARTED, SWEEP, LOG = "record.json", "started.json", "sweep", "run.log"
#: tune's folder in the sweep folder (its outputs: tune.json, tuned.params, tune.png).
TUNED = "tuned"
#: A step's exit codes that are its verdict on the models, not a failure of the run: the
#: run goes on, and its record says them (``verdicts``).
VERDICTS = {("validate", 1): "the cascade is unstable with the model",
            ("tune", 1): "the sweep's band forbids the specification (nothing written)"}
#: A record's status.
FINISHED, FAILED = "finished", "failed"


def worker_version() -> str:
    """The heliquad a worker runs (the client checks every worker has its own)."""
    return __version__


def run_folder(study_dir: str, name: str) -> str:
    return os.path.join(study_dir, RUNS, name)


def read_record(folder: str) -> dict | None:
    """The run's record, or None when it has none (never run, or stopped mid-run)."""
    try:
        with open(os.path.join(folder, RECORD), encoding="utf-8") as f:
            return json.load(f)
    except FileNotFoundError:
        return None
    except (OSError, ValueError) as exc:
        raise InputError(f"{folder}/{RECORD}: unreadable ({exc}); remove the run's folder "
                         "to make it again") from None


def perform_run(run, study_dir: str, command, line) -> dict:
    """Make ``run`` (a :class:`~heliquad.host.study.spec.Run`) in its folder under
    ``study_dir`` and return its record. ``line(step, options, folder)`` is a command's
    words, ``command(words, log)`` runs them (host/commands/study.py). A run already over
    (a retry of a task whose first attempt finished) is not made again: its record returns.
    A run that raises is a failed record with the error, not an exception."""
    folder = run_folder(study_dir, run.name)
    done = read_record(folder)
    if done is not None:
        return done
    attempt = _start(folder)
    sweep_dir = os.path.join(folder, SWEEP)
    words = {step: line(step, options, sweep_dir)
             for step, options in _vehicle(run, folder).items()}
    timing, verdicts, started = {}, [], time.time()
    try:
        with open(os.path.join(folder, LOG), "w", encoding="utf-8") as log:
            for step, argv in words.items():
                t0 = time.perf_counter()
                log.write(f"$ heliquad {' '.join(argv)}\n")
                log.flush()
                code = command(argv, log)
                timing[f"{step}_s"] = time.perf_counter() - t0
                if (step, code) in VERDICTS:
                    verdicts.append(f"{step}: {VERDICTS[step, code]}")
                elif code:
                    raise RuntimeError(f"heliquad {step} ended with exit code {code} "
                                       f"(see {LOG})")
        status, error, result = FINISHED, None, outcome(sweep_dir)
    except Exception as exc:            # noqa: BLE001: a failed run is a row with its error
        status, error, result = FAILED, _one_line(exc), _partial(sweep_dir)
    record = {**_head(run, status, error, attempt, os.getpid(), started), **timing,
              "verdicts": "; ".join(verdicts) or None,
              "perturbed": run.perturb,
              "commands": [" ".join(["heliquad", *w]).replace(sweep_dir, SWEEP)
                           .replace(folder + os.sep, "") for w in words.values()],
              **result}
    write_json(os.path.join(folder, RECORD), record)
    return record


def died_record(run, study_dir: str, why: str) -> dict:
    """The failed record of ``run`` whose process died mid-run (host/study/runner.py), written
    as :func:`perform_run` writes its own: the run is over, said with why, and the figures
    of the steps that finished. A run whose record was written before the process died
    keeps it."""
    folder = run_folder(study_dir, run.name)
    done = read_record(folder)
    if done is not None:              # it died after the run was over: the run stands
        return done
    started = _start_mark(folder)
    record = {**_head(run, FAILED, why, started.get("attempt", 1),
                      started.get("pid", os.getpid()), started.get("at", time.time())),
              "verdicts": None, "perturbed": run.perturb,
              **_partial(os.path.join(folder, SWEEP))}
    os.makedirs(folder, exist_ok=True)
    write_json(os.path.join(folder, RECORD), record)
    return record


def _head(run, status: str, error, attempt: int, pid: int, started_at: float) -> dict:
    """A record's first fields, the same for a run made and one whose process died: the
    run, how it ended, its attempt, who made it (host:pid), when and for how long."""
    return {"run": run.name, "status": status, "error": error, "factors": run.factors,
            "seed": run.seed, "attempt": attempt, "worker": f"{socket.gethostname()}:{pid}",
            "started_at": started_at, "run_s": time.time() - started_at}


def _start_mark(folder: str) -> dict:
    """The run's start mark (:data:`STARTED`), or {} when it has none or it is unreadable."""
    try:
        with open(os.path.join(folder, STARTED), encoding="utf-8") as f:
            return json.load(f)
    except (OSError, ValueError):
        return {}


def _vehicle(run, folder: str) -> dict:
    """The run's options; with perturbed vehicle numbers, its own vehicle file written into
    its folder and given to its sweep as --params."""
    if not run.perturb:
        return run.options
    path = os.path.join(folder, VEHICLE_FILE)
    with atomic_write(path) as fh:
        fh.write(perturbed_text(base_text(run.options["sweep"].get("params")), run.perturb))
    return {**run.options, "sweep": {**run.options["sweep"], "params": path}}


def _start(folder: str) -> int:
    """Mark an attempt's start (its number, from the earlier ones' mark) and clear what an
    unfinished earlier attempt left; the attempt's number."""
    os.makedirs(folder, exist_ok=True)
    try:
        attempt = int(_start_mark(folder).get("attempt", 0)) + 1
    except ValueError:
        attempt = 1
    shutil.rmtree(os.path.join(folder, SWEEP), ignore_errors=True)
    write_json(os.path.join(folder, STARTED), {"attempt": attempt, "at": time.time(),
                                               "worker": socket.gethostname(),
                                               "pid": os.getpid()})
    return attempt


def _one_line(exc: BaseException) -> str:
    text = " ".join(str(exc).split()) or type(exc).__name__
    return text if isinstance(exc, InputError) else f"{type(exc).__name__}: {text}"


def _partial(sweep_dir: str) -> dict:
    """A failed run's figures of the steps that finished before it failed (a tune that
    could not meet its specification keeps the sweep's and identify's), else none."""
    try:
        return outcome(sweep_dir)
    except Exception:                   # noqa: BLE001: what did not finish has no figures
        return {}


def outcome(sweep_dir: str) -> dict:
    """The figures of a swept and identified folder: errors against the simulator's truth
    (models.json's ``sil_truth``), the sigma's calibration, the recommended model, the
    broken loop's margins, and the rig time (the log's span, and the excitations' own)."""
    # the log's reader, imported when a run reads it: the client plans runs without it
    from ..acquire.log_session import summarise_tlog
    from ..estimate.fit import order_name

    with open(os.path.join(sweep_dir, "models.json"), encoding="utf-8") as f:
        doc = json.load(f)
    with open(os.path.join(sweep_dir, "manifest.json"), encoding="utf-8") as f:
        manifest = json.load(f)
    truth = doc.get("sil_truth") or {}
    points = truth.get("points", [])
    out = {"complete": bool(manifest.get("complete")), "points": len(points),
           "rig_s": summarise_tlog(os.path.join(sweep_dir, manifest.get("tlog", "sweep.tlog")))
           ["span_s"], "excited_s": excited_seconds(manifest), **_point_errors(truth, points)}
    rec = doc.get("recommended")
    model = doc["models"][rec] if rec is not None else None
    out["recommended"] = None if model is None else order_name(
        (*model["order"], int(bool(model.get("integrator")))), bool(model.get("delay_s")))
    out["quality"] = (doc.get("quality") or {}).get("level")
    out["model_num"] = None if model is None else model["num"]
    out["model_den"] = None if model is None else model["den"]
    out["model_delay_s"] = None if model is None else model.get("delay_s", 0.0)
    loop = doc.get("broken_loop") or {}
    out["gain_margin_db"] = loop.get("gain_margin_db")
    out["phase_margin_deg"] = loop.get("phase_margin_deg")
    return {**out, **_validation(sweep_dir), **_tuning(sweep_dir, doc.get("axis"))}


def _plant_loop(loops: dict) -> dict:
    """The loop broken at the plant's input (roll and pitch: ``input``; yaw, whose cascade
    is the rate loop alone: ``rate``), or {}."""
    return (loops or {}).get("input") or (loops or {}).get("rate") or {}


def _written(path: str) -> dict | None:
    """The JSON document a step wrote at ``path``, None when it wrote none."""
    try:
        with open(path, encoding="utf-8") as f:
            return json.load(f)
    except FileNotFoundError:
        return None


def _validation(sweep_dir: str) -> dict:
    """validate's figures (validation.json beside models.json), {} without it: the margins
    at the plant's input predicted from the model and the simulator's truth's, the closed
    loop's stability, its step and its angle under turbulence."""
    doc = _written(os.path.join(sweep_dir, "validation.json"))
    if doc is None:
        return {}
    model, truth = _plant_loop(doc.get("loops")), _plant_loop(doc.get("truth_loops"))
    return {"validated_stable": doc.get("stable"),
            "validated_gain_margin_db": model.get("gain_margin_db"),
            "validated_phase_margin_deg": model.get("phase_margin_deg"),
            "truth_gain_margin_db": truth.get("gain_margin_db"),
            "truth_phase_margin_deg": truth.get("phase_margin_deg"),
            "step_overshoot_pct": (doc.get("step") or {}).get("overshoot_pct"),
            "step_settling_s": (doc.get("step") or {}).get("settling_time_s"),
            "turbulence_angle_rms_deg": (doc.get("turbulence") or {}).get("angle_rms_deg")}


def _tuning(sweep_dir: str, axis) -> dict:
    """tune's figures (TUNED/tune.json), {} without it: whether the tuned gains meet the
    specification, the gains, and the predicted margins at the plant's input."""
    doc = _written(os.path.join(sweep_dir, TUNED, "tune.json"))
    if doc is None:
        return {}
    tuned = (doc.get("axes") or {}).get(axis) or {}
    loop = _plant_loop((tuned.get("tuned") or {}).get("loops"))
    return {"tuned_meets_spec": tuned.get("meets_spec"),
            "tuned_gains": (tuned.get("tuned") or {}).get("gains"),
            "tuned_gain_margin_db": loop.get("gain_margin_db"),
            "tuned_phase_margin_deg": loop.get("phase_margin_deg")}


def _point_errors(truth: dict, points: list) -> dict:
    """The points' errors against the truth: worst and RMS (dB, deg), RMS of error/sigma,
    and the share of points within one and two sigmas; the model's worst."""
    z = [p["error_over_sigma"] for p in points if p.get("error_over_sigma") is not None]
    rms = (lambda xs: math.sqrt(sum(x * x for x in xs) / len(xs)) if xs else None)
    return {"points_worst_db": truth.get("points_worst_db"),
            "points_worst_deg": truth.get("points_worst_deg"),
            "points_rms_db": rms([p["error_db"] for p in points if p.get("error_db") is not None]),
            "points_rms_deg": rms([p["error_deg"] for p in points
                                   if p.get("error_deg") is not None]),
            "points_rms_error_over_sigma": truth.get("points_rms_error_over_sigma"),
            "within_1_sigma": sum(v <= 1 for v in z) / len(z) if z else None,
            "within_2_sigma": sum(v <= 2 for v in z) / len(z) if z else None,
            "model_worst_db": truth.get("model_worst_db"),
            "model_worst_deg": truth.get("model_worst_deg")}
