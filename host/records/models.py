"""MODELS.json and MODELS.mat, the transfer functions fitted to a points file
(docs/file-formats.md, "MODELS.json" and "MODELS.mat"): ``{"models": [...], "recommended":
INDEX, ...}``, coefficients in descending powers of s, den monic; the .mat a MATLAB struct
array of the same models.

:class:`ModelsFile` is the document and :class:`StoredModel` each of its models, their
fields the file's keys in the file's order. The fit and identify build one
(:func:`fitted_models` from a :class:`~heliquad.host.estimate.models.FitResult`, read by its
attributes, with identify's sections beside it), :func:`write_models_json` and
:func:`write_models_mat` write it, and :func:`read_models_json` checks a file and returns
it, for validation, the report and the demo. The recommended model's quality verdict comes
from the fit (host/estimate/metrics.py): a writer judges nothing.
"""

from __future__ import annotations

import dataclasses
import functools
import math

import numpy as np

from ...sim.base import dialect as names
from ...sim.base.errors import InputError
from . import schema as S
from .choices import COSTS, RESPONSES
from .gains import recorded_gains_schema
from .manifest import SWEEP_SIGNALS
from .output import NULLABLE, atomic_write, document, write_json
from .reading import read_json, record_of

__all__ = ["StoredModel", "ModelsFile", "fitted_models", "read_models_json", "check_plant_models",
           "write_models_json", "write_models_mat", "MAT_FIELDS"]

#: A model's pure delay, s.
MAX_DELAY_S = 10.0


@functools.cache
def _models_schema():
    pairs = S.List(S.Seq(("real", S.Num()), ("imag", S.Num())), 0, 12)
    model = S.Obj(
        required={"num": S.List(S.Num(), 1, 13), "den": S.List(S.Num(), 2, 13)},
        optional={"order": S.Seq(("M", S.Int(0, 12)), ("N", S.Int(1, 12))),
                  "delay_s": S.Num(0, MAX_DELAY_S), "stable": S.Bool(), "degenerate": S.Bool(),
                  "degenerate_why": S.Str(), "integrator": S.Bool(),
                  "metrics": S.Obj(values=S.Null(S.Num())), "poles": pairs, "zeros": pairs,
                  "dc_gain": S.Null(S.Num())})
    log = S.Obj(optional={"first_regions": S.List(S.List(S.Int(0, 2**63), 2, 2))},
                values=S.Int(0, 2**63))
    return S.Obj(
        required={"models": S.List(model, 1, 1000)},
        optional={"recommended": S.Null(S.Int(0, 999)), "reason": S.Str(),
                  "axis": S.Str(tuple(names.AXES)), "points_file": S.Str(), "weights": S.Str(),
                  "cost": S.Str(COSTS),
                  "log": log,
                  "skipped_frequencies": S.List(S.Str()),
                  "saturated_frequencies": S.List(S.Str()),
                  "estimate": S.Str(("excitation", "input")), "sil_truth": _sil_truth_schema(),
                  "signal": S.Str(SWEEP_SIGNALS),
                  "replay": _replay_schema(),
                  "quality": S.Obj(required={"level": S.Str(("good", "acceptable", "poor")),
                                             "why": S.Str()}),
                  "band_rad_s": S.Seq(("low", S.Num(0, 1e7, lo_open=True)),
                                      ("high", S.Num(0, 1e7, lo_open=True))),
                  "broken_loop": S.Obj(), "gains": recorded_gains_schema(),
                  "record": S.Obj(),
                  "imu_path": S.Str(("raw", "dmp")),
                  "linearity": _linearity_schema(), "response": S.Str(RESPONSES)})



def _linearity_schema():
    """models.json's ``linearity`` (host/campaign/linearity.py): what the report reads of it."""
    count = S.Int(0, 10_000)
    level = S.Obj(required={"peak": S.Num(0), "realisations": count, "count": count,
                            "above_noise": count, "distortion_db": S.Num(),
                            "noise_db": S.Num(), "flagged": S.Bool()})
    dependence = S.Obj(required={"max_db": S.Num(0), "max_deg": S.Num(0),
                                 "significant": S.Bool()})
    return S.Obj(required={"levels": S.List(level, 1, 2), "flagged": S.Bool(),
                           "distortion_limit_db": S.Num()},
                 optional={"amplitude_dependence": dependence})


def _sil_truth_schema():
    """models.json's ``sil_truth`` (:func:`heliquad.host.validate.truth.truth_record`), as far as
    ``heliquad report`` reads it."""
    num = S.Null(S.Num())
    point = S.Obj(required={"freq_hz": S.Num(0, lo_open=True)},
                  optional={k: num for k in ("truth_db", "truth_deg", "error_db", "error_deg",
                                             "error_over_sigma")})
    return S.Obj(required={"points": S.List(point), "points_worst_db": S.Num(),
                           "points_worst_deg": S.Num()},
                 optional={k: num for k in ("points_rms_error_over_sigma", "model_worst_db",
                                            "model_worst_deg")})


def _replay_schema():
    """models.json's ``replay``: the recommended model's replay of each frequency's record."""
    point = S.Obj(required={"freq_hz": S.Num(0, lo_open=True), "periods": S.Int(1, 2**31),
                            "nrmse": S.Null(S.Num(0))})
    return S.Obj(required={"model": S.Int(0, 999), "points": S.List(point)},
                 optional={"discard_periods": S.Int(0, 2**31)})


@dataclasses.dataclass(frozen=True, kw_only=True)
class StoredModel:
    """One model of MODELS.json (the meaning of each key: docs/file-formats.md). A key a file
    leaves out reads as the default here (``order``: the coefficients' own); ``stable``
    None when the file does not say. ``metrics`` stays the file's dict (its keys are the
    fit's metrics, host/estimate/metrics.py); ``poles`` and ``zeros`` are ``[real, imag]``
    pairs. Numbers that are not finite (an infinite ``dc_gain`` or AICc) are kept as they
    are and written as null."""

    order: list
    integrator: bool = False
    num: list
    den: list
    delay_s: float = 0.0
    stable: bool | None = None
    degenerate: bool = False
    degenerate_why: str | None = None
    metrics: dict = dataclasses.field(default_factory=dict)
    poles: list | None = None
    zeros: list | None = None
    dc_gain: float | None = dataclasses.field(default=None, metadata=NULLABLE)

    @classmethod
    def of(cls, model) -> StoredModel:
        """A :class:`~heliquad.host.estimate.fit.TfModel` (read by its attributes) as stored."""
        return cls(order=list(model.order), integrator=bool(model.integrator),
                   num=[float(c) for c in model.num], den=[float(c) for c in model.den],
                   delay_s=float(model.delay_s), stable=bool(model.stable),
                   degenerate=bool(model.degenerate),
                   degenerate_why=model.degenerate_why or None,
                   metrics={k: float(v) if isinstance(v, float) else v
                            for k, v in model.metrics.items()},
                   poles=[[float(p.real), float(p.imag)] for p in model.poles],
                   zeros=[[float(z.real), float(z.imag)] for z in model.zeros],
                   dc_gain=float(model.dc_gain))


@dataclasses.dataclass(frozen=True, kw_only=True)
class ModelsFile:
    """MODELS.json: its :class:`StoredModel` list, the recommendation (``recommended`` an
    index into ``models``, or None, written as null) and every optional key, None when the
    file leaves it out (the meaning of each: docs/file-formats.md). ``band_rad_s`` is
    ``[low, high]``; ``quality`` ``{"level", "why"}``. The sections identify adds (``log``,
    ``gains``, ``broken_loop``, ``sil_truth``, ``replay``) stay the checked dicts the schema
    describes: their readers take them key by key, and a type of their own would only copy
    the schema."""

    models: list
    recommended: int | None = dataclasses.field(default=None, metadata=NULLABLE)
    reason: str | None = None
    log: dict | None = None
    skipped_frequencies: list | None = None
    saturated_frequencies: list | None = None
    estimate: str | None = None
    signal: str | None = None
    gains: dict | None = None
    broken_loop: dict | None = None
    sil_truth: dict | None = None
    replay: dict | None = None
    band_rad_s: list | None = None
    quality: dict | None = None
    axis: str | None = None
    points_file: str | None = None
    weights: str | None = None
    cost: str | None = None
    record: dict | None = None
    imu_path: str | None = None
    linearity: dict | None = None
    response: str | None = None

    def document(self) -> dict:
        """The file's JSON document: the keys that have a value, in field order."""
        return {**document(self), "models": [document(m) for m in self.models]}


def fitted_models(result, **sections) -> ModelsFile:
    """A :class:`~heliquad.host.estimate.models.FitResult` (read by its attributes) as
    MODELS.json: its models, recommendation and reason, weights, band (the lowest and highest
    frequency of the points fitted: validation trusts a model only there) and the
    recommended model's quality (given with the recommendation, and only with it);
    ``sections``: the other :class:`ModelsFile` fields (the axis, the points file, what
    identify adds)."""
    if (result.recommended is None) != (not result.quality):
        raise ValueError("a recommended model needs its quality, and only it has one")
    low, high = result.band_rad_s
    quality = {"level": result.quality[0], "why": result.quality[1]} if result.quality \
        else None
    return ModelsFile(models=[StoredModel.of(m) for m in result.models],
                      recommended=result.recommended, reason=result.reason,
                      band_rad_s=[float(low), float(high)], quality=quality,
                      weights=result.weights, cost=result.cost, **sections)


def check_plant_models(path, doc: ModelsFile, command: str) -> None:
    """Refuse models of a loop's response (a rate or angle sweep fitted with ``response``
    ``loop``: its setpoint to its output) where ``command`` needs the plant's."""
    if doc.response == "loop":
        raise InputError(f"{path}: its models are a loop's response (the setpoint to the rate "
                         f"or angle), not the plant's; {command} needs the plant: identify "
                         "the same sweep with --response plant")


def read_models_json(path) -> ModelsFile:
    """MODELS.json, checked (docs/file-formats.md): each model proper (num no longer than
    den, and both as long as its ``order`` says), den's leading coefficient not zero,
    ``recommended`` an index into ``models`` or null. A
    model without ``order`` gets the one its coefficients have."""
    doc = read_json(path, "MODELS.json", _models_schema())
    for i, m in enumerate(doc["models"]):
        key = f"models[{i}]"
        deg_num, deg_den = m.setdefault("order", [len(m["num"]) - 1, len(m["den"]) - 1])
        if deg_num > deg_den:
            S.fail(path, f"{key}.order", "is improper (numerator degree above the "
                   "denominator's)", m["order"])
        for name, want in (("num", deg_num + 1), ("den", deg_den + 1)):
            if len(m[name]) != want:
                S.fail(path, f"{key}.{name}", f"must have {want} coefficients (order "
                       f"{deg_num}/{deg_den})", m[name])
        if m["den"][0] == 0:
            S.fail(path, f"{key}.den[0]", "must not be 0 (the leading coefficient)")
        with np.errstate(all="ignore"):
            scaled = np.asarray(m["num"] + m["den"], float) / float(m["den"][0])
        if not np.all(np.isfinite(scaled)):
            S.fail(path, key, "has coefficients beyond double range once den is monic")
    band = doc.get("band_rad_s")
    if band is not None and not band[0] <= band[1]:
        S.fail(path, "band_rad_s", "must be [low, high] with low <= high", band)
    rec = doc.get("recommended")
    if rec is not None and rec >= len(doc["models"]):
        S.fail(path, "recommended", f"is not an index into models (0..{len(doc['models']) - 1})",
               rec)
    return record_of(ModelsFile, doc,
                     models=[record_of(StoredModel, m) for m in doc["models"]])


def write_models_json(path, models: ModelsFile) -> None:
    """Write MODELS.json; the file is replaced atomically so a failure never truncates it."""
    write_json(path, models.document())


#: MODELS.mat's struct fields; each model's metrics (MODELS.json's) come before dc_gain.
MAT_FIELDS = ("order", "num", "den", "delay_s", "stable", "degenerate", "dc_gain")


def _double(value) -> float:
    """A number of MODELS.json for the .mat: null (not finite, or not known) is NaN."""
    return math.nan if value is None else float(value)


def write_models_mat(path, doc: ModelsFile) -> None:
    """Write MODELS.mat (docs/file-formats.md), atomically: ``models``, a 1-by-N MATLAB
    struct array with the fields of :data:`MAT_FIELDS` around every metric of the models
    (doubles, logical flags, coefficient row vectors), and ``recommended``, a 1-based index
    (0 when none)."""
    # scipy.io (0.25 s) here: only a command asked for a .mat file pays
    import scipy.io

    metrics = list(dict.fromkeys(k for m in doc.models for k in m.metrics))
    fields = [*MAT_FIELDS[:-1], *metrics, MAT_FIELDS[-1]]
    array = np.empty((1, len(doc.models)), dtype=[(f, object) for f in fields])
    for i, m in enumerate(doc.models):
        entry = {"order": np.array([m.order], float), "num": np.array([m.num], float),
                 "den": np.array([m.den], float), "delay_s": float(m.delay_s),
                 "stable": bool(m.stable), "degenerate": bool(m.degenerate),
                 "dc_gain": _double(m.dc_gain),
                 **{k: _double(m.metrics.get(k)) for k in metrics}}
        array[0, i] = tuple(entry[f] for f in fields)
    recommended = 0 if doc.recommended is None else doc.recommended + 1
    with atomic_write(path, "wb") as fh:
        scipy.io.savemat(fh, {"models": array, "recommended": float(recommended)})
