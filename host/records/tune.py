"""tune.json, what ``heliquad tune`` designed and predicts (docs/file-formats.md,
"tune.json"): :class:`TuneFile`, its writer and its reader.

``heliquad tune`` writes it beside ``tuned.params`` (the same gains as the firmware's
parameters); ``heliquad verify`` reads it to know which gains to load, which loops to
measure and what their margins should be; the report reads it to show before and after.

Per axis (``axes.roll`` ...): the models it was designed on, the identified band, the
``current`` gains (what the sweep's board flew) and the ``tuned`` ones, each with its loops'
predicted margins (the records of :func:`heliquad.host.validate.closed_loop.margins_record`:
``gain_margin_db``, ``phase_margin_deg``, their crossovers, every crossover), the tuned
loops' margins with their ``uncertainty`` (the half-width the model's uncertainty gives each
margin) and the margins read outside the identified band (``extrapolated``: no bound), and
the predicted step and disturbance rejection.
"""

from __future__ import annotations

import dataclasses
import functools

from ...sim.base import dialect as names
from . import schema as S
from .gains import recorded_gains_schema
from .output import document, write_json
from .reading import read_json, record_of

__all__ = ["TuneFile", "TUNE_FORMAT", "TUNE_VERSION", "write_tune_json", "read_tune",
           "LOOP_KEYS"]

#: The file's format name and version (``format``, ``version``).
TUNE_FORMAT = "heliquad tune"
TUNE_VERSION = 1
#: The loops a tuned axis predicts: rate for every axis, angle and input for roll and pitch.
LOOP_KEYS = ("rate", "angle", "input")


@dataclasses.dataclass(frozen=True, kw_only=True)
class TuneFile:
    """tune.json: the specification the gains were designed to (``spec``: its figures by
    name, e.g. ``phase_margin_deg``, ``gain_margin_db``), and per axis its design
    (``axes``: ``{axis: {...}}``, the keys of docs/file-formats.md). The sections stay the
    checked dicts the schema describes, as in validation.json."""

    format: str = TUNE_FORMAT
    version: int = TUNE_VERSION
    spec: dict
    axes: dict


def write_tune_json(path, record: TuneFile) -> None:
    """Write tune.json, atomically."""
    write_json(path, document(record))


@functools.cache
def _tune_schema():
    num = S.Null(S.Num())
    crossing = S.Obj(required={"omega_rad_s": S.Num(0)}, optional={"in_band": S.Bool()},
                     values=num)
    uncertainty = S.Obj(optional={"phase_margin_deg": S.Num(0), "gain_margin_db": S.Num(0)})
    loop = S.Obj(required={"phase_margin_deg": num, "gain_margin_db": num},
                 optional={"gain_crossovers": S.List(crossing),
                           "phase_crossovers": S.List(crossing),
                           "gain_crossover_rad_s": num, "phase_crossover_rad_s": num,
                           "not_validated": S.List(S.Str()), "uncertainty": uncertainty,
                           "extrapolated": S.List(S.Str(("phase_margin_deg",
                                                         "gain_margin_db")))})
    loops = S.Obj(required={"rate": loop}, optional={"angle": loop, "input": loop})
    design = S.Obj(required={"gains": recorded_gains_schema(), "loops": loops})
    axis = S.Obj(required={"band_rad_s": S.Seq(("low", S.Num(0, lo_open=True)),
                                               ("high", S.Num(0, lo_open=True))),
                           "current": design, "tuned": design,
                           "params": S.Obj(values=S.Num())},
                 optional={"models": S.Str(), "model_index": S.Int(0, 10_000),
                           "meets_spec": S.Bool(), "said": S.List(S.Str())})
    return S.Obj(required={"format": S.Str((TUNE_FORMAT,)), "version": S.Int(1, TUNE_VERSION),
                           "spec": S.Obj(values=S.Num()),
                           "axes": S.Obj(values=axis)})


def read_tune(path) -> TuneFile:
    """tune.json (``heliquad tune``), checked for what ``heliquad verify`` and the report
    read: every axis named as the firmware names them, with at least one axis."""
    doc = read_json(path, "tune.json", _tune_schema())
    if not doc["axes"]:
        S.fail(path, "axes", "must name at least one axis")
    for axis, entry in doc["axes"].items():
        if axis not in names.AXES:
            S.fail(path, f"axes.{axis}", f"is not an axis (known: {', '.join(names.AXES)})")
        if axis != "yaw":
            for side in ("current", "tuned"):
                if entry[side]["gains"].get("angle") is None:
                    S.fail(path, f"axes.{axis}.{side}.gains.angle", "is missing (roll and "
                           "pitch fly an angle loop)")
    return record_of(TuneFile, doc)
