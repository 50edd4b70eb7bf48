"""The simulator's truth for a simulated sweep: what identification should have found.

A SIL sweep's manifest records its plant (``source``: the transfer function or the vehicle
with its parameter file, collective, turbulence and sensor), so the sampled-data response
that identification should recover at each point's frequency can be computed again: the
plant's ``truth`` (:class:`heliquad.sim.rig.setup.Plant`) for the sweep's injection point. With it,
``heliquad identify`` records how far its points and its recommended model are from the
truth, so anyone can check the method end to end on their own machine.

Nothing here is used to estimate or to choose a model; a board's sweep has no truth.
"""

from __future__ import annotations

import math
import os

import numpy as np

from ...sim.base.errors import InputError
from ...sim.plant.dryden import LEVELS_KT
from ...sim.rig.setup import PLANTS, SilConfig, make_plant
from ..estimate.fit import model_response
from .loops import RAW_PATH, angle_over_rate
from ..records import schema as S

__all__ = ["sil_truth", "sil_truth_loops", "truth_record"]

#: Model errors are measured on this many log-spaced frequencies across the points' band.
BAND_GRID = 100


def _source_schema():
    return S.Obj(required={"kind": S.Str(("sil",)), "plant": S.Str(PLANTS)},
                 optional={"num": S.List(S.Num(), 1, 13), "den": S.List(S.Num(), 2, 13),
                           "params": S.Null(S.Str()), "turbulence": S.Null(S.Str(tuple(LEVELS_KT))),
                           "seed": S.Int(0, 2**63), "ideal_sensor": S.Bool(),
                           "collective": S.Num(0, 1)})


def _sweep_plant(manifest, dir_path):
    """``(plant, None)`` rebuilt from a simulated sweep's manifest, or ``(None, why not)``."""
    source = manifest.get("source") or {}
    if source.get("kind") != "sil":
        return None, "not a simulated sweep"
    try:
        _source_schema().check("manifest.json", "source", source)
        fs = {round(e["freq_hz"] * e["period_samples"], 3) for e in manifest["frequencies"]
              if "period_samples" in e and "freq_hz" in e}
        if len(fs) != 1:
            return None, "the manifest does not give one loop rate"
        return _plant(manifest, source, dir_path, 1.0 / fs.pop()), None
    except InputError as exc:
        return None, str(exc)


def sil_truth_loops(manifest, dir_path: str, imu_path=None):
    """``((h, h_a), None)``: a simulated sweep's plant as the loops see it, the sampled
    responses from the torque command to the logged rate and to the logged angle (functions
    of rad/s; ``h_a`` None for a transfer-function plant, which has no angle of its own);
    or ``(None, why not)``. On the raw IMU path (``imu_path``, else the manifest's) the
    logged angle is the firmware's sum of the logged rates, not the plant's attitude
    (:func:`heliquad.host.validate.loops.angle_over_rate`)."""
    plant, why = _sweep_plant(manifest, dir_path)
    if plant is None:
        return None, why
    if manifest["source"]["plant"] == "tf":
        return ((lambda omega: np.asarray(plant.truth(np.asarray(omega, float), "mixer"))),
                None), None
    if (imu_path or manifest.get("imu_path")) == RAW_PATH:
        # the firmware's logged angle on the raw path is its sum of the logged rates
        integral = angle_over_rate(RAW_PATH, plant.dt_s)
        return ((lambda omega: plant.sampled(omega)[0]),
                (lambda omega: plant.sampled(omega)[0] * integral(omega))), None
    return ((lambda omega: plant.sampled(omega)[0]), (lambda omega: plant.sampled(omega)[1])), None


def sil_truth(manifest, dir_path: str):
    """``(truth(omega) -> complex array, None)`` for a simulated sweep, or ``(None, why
    not)`` (a board's sweep; a plant that cannot be rebuilt)."""
    plant, why = _sweep_plant(manifest, dir_path)
    if plant is None:
        return None, why
    source = manifest["source"]
    # a rate or angle sweep that measured the plant (link.response_fields): the mixer's truth
    inject = "mixer" if manifest.get("response") == "plant" else manifest["inject"]
    if source["plant"] == "tf" and inject != "mixer":
        return None, "a transfer-function plant's truth is for mixer injection only"
    return (lambda omega: np.asarray(plant.truth(np.asarray(omega, float), inject))), None


def _plant(manifest, source, dir_path, dt_s):
    params = source.get("params")
    if params and not os.path.isabs(params):      # relative: to where the sweep ran, or here
        params = next((p for p in (params, os.path.join(dir_path, params))
                       if os.path.exists(p)), params)
    cfg = SilConfig(axis=manifest["axis"], rig=manifest["axis"], inject=manifest["inject"],
                    plant=source["plant"], num=tuple(source.get("num", ())),
                    den=tuple(source.get("den", ())), params=params,
                    turbulence=source.get("turbulence"), seed=source.get("seed", 0),
                    ideal_sensor=source.get("ideal_sensor", False),
                    collective=source.get("collective", SilConfig.collective))
    return make_plant(cfg, dt_s)


def _errors(got, want):
    ratio = np.asarray(got) / np.asarray(want)
    return 20 * np.log10(np.abs(ratio)), np.degrees(np.angle(ratio))


def truth_record(truth, points, model) -> dict:
    """For models.json: the truth at each point's frequency and each point's error against
    it (dB, deg, and in units of its sigma), and the worst errors of the points and of
    ``model`` (the recommended one, or None) across the points' band."""
    omega = np.array([p.omega_rad_s for p in points])
    gain = np.array([p.gain for p in points])
    sigma = np.array([p.sigma for p in points])
    want = truth(omega)
    db, deg = _errors(gain, want)
    z = np.abs(gain - want) / sigma
    rows = [{"freq_hz": float(w / (2 * math.pi)), "truth_db": float(20 * np.log10(abs(t))),
             "truth_deg": float(np.degrees(np.angle(t))), "error_db": float(e_db),
             "error_deg": float(e_deg), "error_over_sigma": float(e_z)}
            for w, t, e_db, e_deg, e_z in zip(omega, want, db, deg, z)]
    out = {"points": rows, "points_worst_db": float(np.max(np.abs(db))),
           "points_worst_deg": float(np.max(np.abs(deg))),
           "points_rms_error_over_sigma": float(np.sqrt(np.mean(z[np.isfinite(z)] ** 2)))
           if np.any(np.isfinite(z)) else None}
    if model is not None:
        grid = np.logspace(math.log10(omega.min()), math.log10(omega.max()), BAND_GRID)
        m_db, m_deg = _errors(model_response(model.num, model.den, model.delay_s, grid),
                              truth(grid))
        out.update(model_worst_db=float(np.max(np.abs(m_db))),
                   model_worst_deg=float(np.max(np.abs(m_deg))))
    return out
