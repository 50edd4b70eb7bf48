"""validation.json, what ``heliquad validate`` found of a model in closed loop
(docs/file-formats.md, "validation.json"): :class:`ValidationFile`, its writer and its
reader, checked for what ``heliquad report`` shows. Validation builds the record
(:func:`heliquad.host.validate.closed_loop.validation_record`, the verdicts included: a
writer judges nothing), ``heliquad validate`` and the demo write it, the report reads it.
"""

from __future__ import annotations

import dataclasses
import functools

from . import schema as S
from .output import document, write_json
from .reading import read_json, record_of

__all__ = ["ValidationFile", "write_validation_json", "read_validation"]


@dataclasses.dataclass(frozen=True, kw_only=True)
class ValidationFile:
    """validation.json: its keys in the file's order (the meaning of each:
    docs/file-formats.md), each optional one None when the file leaves it out. The sections
    (each loop's margins and crossovers in ``loops`` and ``truth_loops``, ``measured_loop``,
    ``instability``, ``step``, ``sine``, ``turbulence``, ``gains``) stay the checked dicts the
    schema describes: the report and the command read them key by key, and a type of their
    own would only copy the schema."""

    axis: str | None = None
    num: list | None = None
    den: list | None = None
    delay_s: float | None = None
    gains: dict | None = None
    band_rad_s: list | None = None
    loops: dict
    measured_loop: dict | None = None
    truth_loops: dict | None = None
    stable: bool
    instability: dict | None = None
    step: dict | None = None
    sine: dict | None = None
    turbulence: dict | None = None


def write_validation_json(path, record: ValidationFile) -> None:
    """Write validation.json, atomically."""
    write_json(path, document(record))


@functools.cache
def _validation_schema():
    num = S.Null(S.Num())
    crossing = S.Obj(required={"omega_rad_s": S.Num(0)}, optional={"in_band": S.Bool()},
                     values=num)
    crossings = {"gain_crossovers": S.List(crossing), "phase_crossovers": S.List(crossing)}
    loop = S.Obj(required={"closed_loop_stable": S.Bool()},
                 optional={**crossings, "not_validated": S.List(S.Str())}, values=num)
    truth = S.Obj(optional={**crossings, "not_validated": S.List(S.Str()),
                            "closed_loop_stable": S.Bool()}, values=num)
    point = S.Obj(required={"freq_hz": S.Num(0, lo_open=True), "magnitude_db": S.Num(),
                            "phase_deg": S.Num()})
    measured = S.Obj(required={"loop": S.Str(), "injection": S.Str()},
                     optional={**crossings, "unmeasured": S.List(S.Str()),
                               "points": S.List(point)}, values=num)
    return S.Obj(
        required={"stable": S.Bool(), "loops": S.Obj(values=loop)},
        optional={
            "band_rad_s": S.Seq(("low", S.Num(0)), ("high", S.Num(0))),
            "truth_loops": S.Obj(values=truth), "measured_loop": measured,
            "step": S.Obj(required={"size": S.Num(), "unit": S.Str()}, values=num),
            "sine": S.Obj(required={"freq_hz": S.Num()}, values=num),
            "turbulence": S.Obj(required={"level": S.Str(), "rate_rms_deg_s": S.Num(),
                                          "gust_rate_rms_deg_s": S.Num()}),
            "instability": S.Obj(required={"pole_rad_s": S.Num(0),
                                           "band_top_rad_s": S.Num(0, lo_open=True),
                                           "outside_band": S.Bool()})})


def read_validation(path) -> ValidationFile:
    """validation.json (``heliquad validate``), checked for what ``heliquad report`` shows."""
    doc = read_json(path, "validation.json", _validation_schema())
    if doc["stable"]:
        for name in ("step", "sine"):
            if name not in doc:
                S.fail(path, name, "is missing (the cascade is stable)")
    return record_of(ValidationFile, doc)
