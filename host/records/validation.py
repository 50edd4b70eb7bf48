"""validation.json, what ``heliquad validate`` found of a model in closed loop
(docs/file-formats.md, "validation.json"): its schema and its reader, checked for what
``heliquad report`` shows. The document is written by host/present/validation.py; the reader
returns it as the dict it is (the report reads it key by key, many keys optional).
"""

from __future__ import annotations

import functools

from . import schema as S
from .reading import read_json

__all__ = ["read_validation"]


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


def read_validation(path) -> dict:
    """validation.json (``heliquad validate``), checked for what ``heliquad report`` shows."""
    doc = read_json(path, "validation.json", _validation_schema())
    if doc["stable"]:
        for name in ("step", "sine"):
            if name not in doc:
                S.fail(path, name, "is missing (the cascade is stable)")
    return doc
