"""``heliquad effectiveness DIR...``: each rotor's control effectiveness from per-rotor runs.

Reads the per-rotor run folders (``heliquad sweep --inject motors``: a sweep folder whose one
multisine gives every rotor lines of its own, docs/file-formats.md) of the roll, pitch and yaw
rigs, one or more each, and feeds the estimator (host/estimate/effectiveness.py,
docs/effectiveness.md) what it needs from each: the injections' sum, the rate and the
axis's torque command per sample with the samples that arrived (:func:`rig_points`), each
rotor's lines (the manifest's ``design.rotor_orders``), the allocation's column from the
geometry parameters (``CA_*``) the board flew (the firmware's own allocation, through its
bindings: linear in the torque command, so the column is the allocation matrix's), the rig's
hinge from the axis sweep's model (``--axis-models``; without one, a free hinge) as the start
of its damping, which the estimate fits, and the loop period the commands were held for. Then fits the rotor geometry that explains the
estimate (host/estimate/rotor_geometry.py) from the flown one, with the rig's inertia from a
vehicle file.

Writes, in the output folder: ``effectiveness.json`` (the estimate with its sigmas, the
flown geometry's prediction and the fitted geometry's beside it), ``effectiveness.png`` and
``geometry.params`` (the fitted geometry as the firmware's CA_* parameters, QGroundControl's
format, for ``heliquad params load``).
"""

from __future__ import annotations

import math
import os

import numpy as np

from heliquad import _firmware

from ...sim.base.dialect import AXES, dialect
from ...sim.base.errors import InputError
from ...sim.plant.vehicle_params import load_params
from .. import __version__
from ..acquire.link import ROTOR_INPUT_OUTPUT
from ..acquire.measure import MAX_LOST_SHARE
from ..acquire.param_protocol import Param
from ..estimate.effectiveness import (Rig, estimate_effectiveness, rig_from_poles,
                                      rig_points)
from ..estimate.rotor_geometry import fit_rotor_geometry
from ..records.models import read_models_json
from ..records.output import write_json
from ..records.params_file import write_params_file
from .identify import load_sweep
from .sweep_points import sweep_segments

__all__ = ["RotorRun", "read_rotor_run", "estimate_from_runs", "write_outputs",
           "geometry_params", "allocation_of", "hinge_rigs", "EFFECTIVENESS_JSON",
           "GEOMETRY_PARAMS", "FIGURE"]

EFFECTIVENESS_JSON, GEOMETRY_PARAMS, FIGURE = ("effectiveness.json", "geometry.params",
                                               "effectiveness.png")
#: The geometry parameters' names and whether each is a whole number, the firmware's table.
_GEOMETRY = {p.name: bool(p.integer) for p in _firmware.param_table()
             if p.name.startswith("CA_")}


class RotorRun:
    """One per-rotor run folder, read: its axis, rotor count, the CA_* it flew, its
    records (:class:`~heliquad.host.estimate.effectiveness.RotorPoints`) and loop period."""

    def __init__(self, folder, axis, geometry, records, hold_s, source):
        self.folder, self.axis, self.geometry = folder, axis, geometry
        self.records, self.hold_s, self.source = records, hold_s, source

    @property
    def rotors(self) -> int:
        return int(self.geometry["CA_ROTOR_COUNT"])


def read_rotor_run(folder: str, progress=print) -> RotorRun:
    """A per-rotor run folder's records; one InputError for a folder that is not one, or
    whose every excitation is unusable."""
    _, manifest, samples, _ = load_sweep(folder)
    if manifest.get("inject") not in ROTOR_INPUT_OUTPUT or \
            "rotor_orders" not in manifest.get("design", {}):
        raise InputError(f"{folder}: not a per-rotor run (its injection is "
                         f"{manifest.get('inject')}; heliquad sweep --inject motors makes one)")
    params = manifest.get("params") or {}
    geometry = {k: v for k, v in params.items() if k in _GEOMETRY}
    if "CA_ROTOR_COUNT" not in geometry:
        raise InputError(f"{folder}: the manifest holds no geometry parameters (CA_*): the "
                         "allocation the run flew is not known")
    orders = manifest["design"]["rotor_orders"]
    if len(orders) != int(geometry["CA_ROTOR_COUNT"]):
        raise InputError(f"{folder}: its lines are shared among {len(orders)} rotors, the "
                         f"board flew {int(geometry['CA_ROTOR_COUNT'])}")
    records, hold_s = [], None
    for entry, _, r, u, y, present in sweep_segments(manifest, samples):
        lost = entry.get("lost", 0) / max(entry["samples"] + entry.get("lost", 0), 1)
        if lost > MAX_LOST_SHARE or not r.size:
            progress(f"  {folder}: an excitation skipped: {100 * lost:.1f} % of its samples "
                     "lost on the link")
            continue
        fs_hz = entry["freq_hz"] * entry["period_samples"]
        records += rig_points(r, y, u, fs_hz, entry["period_samples"], orders,
                              manifest["axis"], present)
        hold_s = 1.0 / fs_hz
    if not records:
        raise InputError(f"{folder}: no excitation of the run was measured in full "
                         f"({manifest.get('aborted') or 'none is ok'})")
    return RotorRun(folder, manifest["axis"], geometry, records, hold_s,
                    manifest.get("source") or {})


def allocation_of(geometry: dict):
    """The firmware's allocation of the geometry parameters ``geometry`` (its bindings)."""
    try:
        allocation = _firmware.Allocation(_firmware.params_geometry(geometry))
    except ValueError as exc:
        raise InputError(f"the runs' geometry parameters: {exc}") from None
    if not allocation.ok:
        raise InputError(f"the firmware cannot fly the runs' geometry ({allocation.reason})")
    return allocation


def hinge_rigs(models_paths, allocation) -> dict:
    """Each rig (``axis -> Rig``) with its allocation's column and its hinge: the slowest
    pole of the recommended model of the axis sweep's models.json (a complex one with its
    pair: damping and stiffness), else a free hinge (``R(s) = 1/s``); the estimate fits the
    damping from there."""
    columns = np.asarray(allocation.allocation, dtype=float)
    rigs = {axis: Rig(axis, tuple(columns[:, 1 + row])) for axis, row in AXES.items()}
    for path in models_paths or ():
        doc = read_models_json(path)
        if doc.axis not in AXES or doc.recommended is None:
            raise InputError(f"{path}: no axis or no recommended model to take the rig's "
                             "hinge from")
        poles = np.roots(doc.models[doc.recommended].den)
        slowest = poles[np.argmin(np.abs(poles))]
        hinge = [slowest, np.conj(slowest)] if abs(slowest.imag) > 0 else [slowest.real]
        rigs[doc.axis] = rig_from_poles(doc.axis, rigs[doc.axis].allocation, hinge)
    return rigs


def _built(vehicle, runs) -> tuple:
    """(the vehicle file's parameters, its name): what the builder knows (the rotors' places
    and spins, the body's inertia, which the rigs' is taken to be), from the file given, else
    the simulated runs' own."""
    if vehicle is None:
        kinds = {run.source.get("kind") for run in runs}
        files = {run.source.get("params") for run in runs}
        if kinds != {"sil"} or len(files) != 1:
            raise InputError("the rotors' places and spins and the rigs' inertia: give "
                             "--vehicle FILE (the runs are not all simulated runs of one "
                             "vehicle)")
        vehicle = files.pop()
    params = load_params(vehicle)
    if len(params.rotors) != runs[0].rotors:
        raise InputError(f"{params.source} has {len(params.rotors)} rotors, the runs flew "
                         f"{runs[0].rotors}")
    return params, vehicle or "the shipped vehicle"


def _checked_runs(runs) -> None:
    """The runs together: one geometry flown, and every axis covered."""
    first = runs[0]
    for run in runs[1:]:
        if run.geometry != first.geometry:
            raise InputError(f"{run.folder} flew other geometry parameters than "
                             f"{first.folder}: one vehicle's runs, please")
    missing = [a for a in AXES if a not in {run.axis for run in runs}]
    if missing:
        raise InputError(f"no run on the {' and '.join(missing)} rig: the estimate needs a "
                         "per-rotor run on every rig (roll, pitch and yaw)")


def estimate_from_runs(folders, models_paths=None, vehicle=None, progress=print) -> tuple:
    """The estimate, the geometry fit and what they are compared with, from the run
    ``folders`` (module docstring): (the document effectiveness.json holds, the fitted
    geometry's parameters for geometry.params)."""
    if len(folders) < 2:
        raise InputError(f"{len(folders)} run folder: the estimate needs a per-rotor run on "
                         "every rig (roll, pitch and yaw)")
    runs = [read_rotor_run(f, progress) for f in folders]
    _checked_runs(runs)
    allocation = allocation_of(runs[0].geometry)
    rigs = hinge_rigs(models_paths, allocation)
    rotors = runs[0].rotors
    est = estimate_effectiveness([r for run in runs for r in run.records], rigs, rotors,
                                 runs[0].hold_s, fit_hinges=True)
    built, built_from = _built(vehicle, runs)
    inertia = np.array(built.body.inertia_kg_m2, dtype=float)
    flown = np.asarray(allocation.effectiveness, dtype=float)[1:] / inertia[:, None]
    fit = _fit_geometry(est, runs[0].geometry, built)
    spins = [r.spin for r in built.rotors]
    return (_document(runs, rigs, est, flown, fit, (inertia, built_from), models_paths),
            geometry_params(runs[0].geometry, fit, spins))


def _flown_rotors(geometry: dict, rotors: int) -> tuple:
    """(thrust axes, largest thrusts, moment ratios) of the flown CA_*."""
    def values(key):
        return np.array([geometry[f"CA_ROTOR{i}_{key}"] for i in range(rotors)], dtype=float)

    return np.column_stack([values(k) for k in ("AX", "AY", "AZ")]), values("CT"), values("KM")


def _fit_geometry(est, geometry: dict, built):
    """The geometry fit (host/estimate/rotor_geometry.py) with the vehicle file's places,
    spins and inertia and the flown central rotor's largest thrust, started from the flown
    geometry: its cant from rotor 2's axis (the first arm rotor), its ratios and arm
    thrusts."""
    rotors = int(geometry["CA_ROTOR_COUNT"])
    axes, thrust, km = _flown_rotors(geometry, rotors)
    positions = np.array([r.position_m for r in built.rotors], dtype=float)
    spins = np.array([r.spin for r in built.rotors], dtype=float)
    psi = math.atan2(positions[1, 1], positions[1, 0])
    tangent = np.array([-math.sin(psi), math.cos(psi), 0.0])
    cant = math.degrees(math.asin(float(np.clip(-spins[0] * axes[1] @ tangent, -1, 1))))
    start = (cant, float(np.mean(np.abs(km[1:]))), float(abs(km[0])), float(np.mean(thrust[1:])))
    return fit_rotor_geometry(est.effectiveness_rad_s2, est.effectiveness_covariance,
                              positions, spins, built.body.inertia_kg_m2, float(thrust[0]),
                              start)


def geometry_params(geometry: dict, fit, spins) -> list:
    """The flown CA_* with the fitted thrust axes, largest thrusts and moment ratios (each
    signed by its rotor's spin, as the firmware reads it), as
    :class:`~heliquad.host.acquire.param_protocol.Param` lines."""
    values = dict(geometry)
    for i, spin in enumerate(spins):
        for key, value in zip(("AX", "AY", "AZ"), fit.thrust_axes[i]):
            values[f"CA_ROTOR{i}_{key}"] = float(value)
        values[f"CA_ROTOR{i}_CT"] = float(fit.max_thrust_n[i])
        ratio = fit.central_torque_ratio_m if i == 0 else fit.arm_torque_ratio_m
        values[f"CA_ROTOR{i}_KM"] = float(spin * abs(ratio))
    mav = dialect()
    return [Param(name, value, mav.MAV_PARAM_TYPE_INT32 if _GEOMETRY[name]
                  else mav.MAV_PARAM_TYPE_REAL32, index)
            for index, (name, value) in enumerate(values.items())]


def _rows(a) -> list:
    return np.asarray(a, dtype=float).tolist()


def _document(runs, rigs, est, flown, fit, built, models_paths) -> dict:
    """effectiveness.json's document (docs/file-formats.md); ``built``: (the rigs' inertia,
    the vehicle file it came from)."""
    return {
        "heliquad": __version__, "runs": [{"folder": os.path.abspath(r.folder), "axis": r.axis}
                                          for r in runs],
        "rows": list(AXES), "rotors": runs[0].rotors,
        "effectiveness_rad_s2": _rows(est.effectiveness_rad_s2),
        "effectiveness_sigma_rad_s2": _rows(est.effectiveness_sigma_rad_s2),
        "flown_geometry_rad_s2": _rows(flown),
        "fitted_geometry_rad_s2": _rows(fit.predicted_rad_s2),
        "spin_up_rad_s": _rows(est.spin_up_rad_s),
        "time_constant_s": _rows(est.time_constant_s),
        "time_constant_sigma_s": _rows(est.time_constant_sigma_s),
        "delay_s": _rows(est.delay_s), "delay_sigma_s": _rows(est.delay_sigma_s),
        "chi2_dof": est.chi2_dof,
        "rigs": {a: {"allocation": list(r.allocation),
                     "damping_rad_s": est.hinge_damping_rad_s[a],
                     "given_damping_rad_s": r.damping_rad_s,
                     "stiffness_rad2_s2": r.stiffness_rad2_s2} for a, r in rigs.items()},
        "axis_models": [os.path.abspath(p) for p in models_paths or ()],
        "inertia_kg_m2": _rows(built[0]), "vehicle": built[1],
        "geometry": {"cant_deg": fit.cant_deg, "cant_sigma_deg": fit.cant_sigma_deg,
                     "arm_torque_ratio_m": fit.arm_torque_ratio_m,
                     "arm_torque_ratio_sigma_m": fit.arm_torque_ratio_sigma_m,
                     "central_torque_ratio_m": fit.central_torque_ratio_m,
                     "central_torque_ratio_sigma_m": fit.central_torque_ratio_sigma_m,
                     "max_thrust_n": _rows(fit.max_thrust_n),
                     "max_thrust_sigma_n": _rows(fit.max_thrust_sigma_n),
                     "thrust_axes": _rows(fit.thrust_axes), "chi2_dof": fit.chi2_dof,
                     "params": GEOMETRY_PARAMS},
    }


def write_outputs(out_dir: str, doc: dict, params: list) -> list:
    """effectiveness.json and geometry.params into ``out_dir`` (the figure is drawn
    apart); the files written."""
    write_json(os.path.join(out_dir, EFFECTIVENESS_JSON), doc)
    write_params_file(os.path.join(out_dir, GEOMETRY_PARAMS), params,
                      header=f"heliquad {__version__}, the rotor geometry fitted to the "
                             f"effectiveness of {len(doc['runs'])} per-rotor runs "
                             "(heliquad effectiveness)")
    return [EFFECTIVENESS_JSON, GEOMETRY_PARAMS]
