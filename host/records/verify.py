"""verify.json, what ``heliquad verify`` found of tuned gains on the board
(docs/file-formats.md, "verify.json"): :class:`VerifyFile`, its writer and its reader.

Per verified axis (``axes.roll`` ...): the board it ran on, the sweeps it flew (folders under
``verify/AXIS/``), the gains it loaded and the ones the board held before, per loop the
predicted margins (tune.json's), the band allowed around them, the measured ones and, on the
simulated rig, the simulator's truth, each loop's verdict with what failed, and the axis's
verdict with what was restored and which gains the board holds at the end. The verification
builds the record (its verdicts included: a writer judges nothing); a run for one axis keeps
the other axes' entries of an earlier run.
"""

from __future__ import annotations

import dataclasses
import functools

from ...sim.base import dialect as names
from . import schema as S
from .output import document, write_json
from .reading import read_json, record_of

__all__ = ["VerifyFile", "VERIFY_FORMAT", "VERIFY_VERSION", "VERDICTS", "BOARD_HOLDS",
           "write_verify_json", "read_verify"]

#: The file's format name and version (``format``, ``version``).
VERIFY_FORMAT = "heliquad verify"
VERIFY_VERSION = 1
#: An axis's verdict: its gains accepted, rejected (the previous ones restored), or the run
#: ended before a verdict (the link lost, Ctrl-C, a sweep stopped early).
VERDICTS = ("accepted", "rejected", "unfinished")
#: Which gains the board holds when verify ended: the tuned ones, the previous ones, or not
#: known (the link was lost while they were being set).
BOARD_HOLDS = ("tuned", "previous", "unknown")


@dataclasses.dataclass(frozen=True, kw_only=True)
class VerifyFile:
    """verify.json: the tune.json it verified (``tune``, relative to the folder), its
    specification (``spec``), the least band each margin is allowed (``floor``: never
    tighter than this around a prediction) and per axis the verification (``axes``, the
    checked dicts of docs/file-formats.md)."""

    format: str = VERIFY_FORMAT
    version: int = VERIFY_VERSION
    tune: str
    spec: dict
    floor: dict
    axes: dict


def write_verify_json(path, record: VerifyFile) -> None:
    """Write verify.json, atomically."""
    write_json(path, document(record))


@functools.cache
def _verify_schema():
    num = S.Null(S.Num())
    allowed = S.Obj(required={"phase_margin_deg": S.Num(0), "gain_margin_db": S.Num(0)})
    margins = S.Obj(optional={"unmeasured": S.List(S.Str()),
                              "extrapolated": S.List(S.Str(("phase_margin_deg",
                                                            "gain_margin_db"))),
                              "uncertainty": allowed}, values=num)
    loop = S.Obj(required={"sweep": S.Str(), "predicted": margins, "allowed": allowed,
                           "measured": S.Null(margins), "passed": S.Bool(),
                           "failures": S.List(S.Str())},
                 optional={"truth": S.Null(margins)})
    values = S.Obj(values=S.Num())
    axis = S.Obj(required={"board": S.Str(), "started": S.Str(), "verdict": S.Str(VERDICTS),
                           "board_holds": S.Str(BOARD_HOLDS), "said": S.List(S.Str()),
                           "loaded": values, "previous": values, "restored": S.Null(values),
                           "sweeps": S.Obj(values=S.Str()),
                           "band_rad_s": S.Obj(values=S.Seq(("low", S.Num(0, lo_open=True)),
                                                            ("high", S.Num(0, lo_open=True)))),
                           "loops": S.Obj(values=loop)})
    return S.Obj(required={"format": S.Str((VERIFY_FORMAT,)),
                           "version": S.Int(1, VERIFY_VERSION), "tune": S.Str(),
                           "spec": S.Obj(values=S.Num()), "floor": allowed,
                           "axes": S.Obj(values=axis)})


def read_verify(path) -> VerifyFile:
    """verify.json (``heliquad verify``), checked: every axis named as the firmware names
    them."""
    doc = read_json(path, "verify.json", _verify_schema())
    for axis in doc["axes"]:
        if axis not in names.AXES:
            S.fail(path, f"axes.{axis}", f"is not an axis (known: {', '.join(names.AXES)})")
    return record_of(VerifyFile, doc)
