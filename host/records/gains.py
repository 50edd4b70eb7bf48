"""The cascade's gains: those the firmware flies, gains files (docs/file-formats.md, "Gains
file"), and the gains a sweep records (manifest.json's and models.json's ``gains``).

The firmware's ``CascadeGains::paper_defaults()`` (firmware/core/controllers.cpp) is the one
definition of the gains it flies by default; they are read here through its bindings.
host/records/paper.py keeps the paper's published figures as the reference, and tests/paper_test.py
ties the two. On a board the gains are parameters (docs/parameters.md): a sweep reads them
from the board it flies and records them in its manifest (:func:`gains_from_params`),
identify carries them into models.json, and validation uses them unless given a gains file.
"""

from __future__ import annotations

import dataclasses
import functools

import numpy as np

from heliquad import _firmware

from ...sim.base import dialect as names
from . import schema as S
from .reading import read_json

__all__ = ["Gains", "firmware_gains", "load_gains", "read_gains", "gains_from_params",
           "gains_params", "param_range", "recorded_gains", "recorded_gains_schema", "single",
           "DERIVATIVE_FILTER_N", "AXIS_COMMAND_MAX"]

#: The derivative filter's N (tau_f = tau_D / N) of the firmware's rate loop, which it flies.
DERIVATIVE_FILTER_N = float(_firmware.CascadeGains.paper_defaults().rate(
    _firmware.Axis.ROLL).derivative_filter_n)
#: The largest |axis command| the firmware's rate PID puts out (its output clamp, normalised
#: torque; the same on every axis).
AXIS_COMMAND_MAX = float(_firmware.CascadeGains.paper_defaults().rate(
    _firmware.Axis.ROLL).output_max)
#: Each parameter's (minimum, maximum, floor of a time constant that is not 0).
_RANGES = {p.name: (float(p.minimum), float(p.maximum), float(p.floor))
           for p in _firmware.param_table()}


@dataclasses.dataclass(frozen=True)
class Gains:
    """Cascade gains of one axis: rate (Kc, tau_I, tau_D) and, for roll/pitch, angle (Kc, tau_D)."""

    rate: tuple
    angle: tuple | None


def firmware_gains(axis: str) -> Gains:
    """The gains the firmware flies on ``axis``, each written as the shortest decimal that is
    the firmware's single-precision value (2.422 reads 2.422)."""
    g = _firmware.CascadeGains.paper_defaults()
    which = _firmware.Axis(names.AXES[axis])
    r = g.rate(which)
    rate = (single(r.kc), single(r.tau_i_s), single(r.tau_d_s))
    try:
        a = g.angle(which)
    except ValueError:                     # yaw: no angle loop
        return Gains(rate, None)
    return Gains(rate, (single(a.kc), single(a.tau_d_s)))


#: The parameters' name for each axis (RATE_RLL_KC, ANG_PIT_TD, ...).
PARAM_AXIS = {"roll": "RLL", "pitch": "PIT", "yaw": "YAW"}


def gains_from_params(axis: str, params: dict) -> Gains | None:
    """The gains a board flies on ``axis``, from its parameters (``{name: value}``): rate
    ``RATE_<AX>_KC, _TI, _TD``, angle ``ANG_<AX>_KC, _TD`` (none for yaw); None when the
    parameters do not hold them all."""
    ax = PARAM_AXIS[axis]
    try:
        rate = tuple(single(params[f"RATE_{ax}_{k}"]) for k in ("KC", "TI", "TD"))
        angle = None if axis == "yaw" else tuple(single(params[f"ANG_{ax}_{k}"])
                                                  for k in ("KC", "TD"))
    except KeyError:
        return None
    return Gains(rate, angle)


def gains_params(axis: str, gains: Gains) -> dict:
    """The parameters that set ``gains`` on ``axis`` (the inverse of
    :func:`gains_from_params`), each the single-precision value the firmware holds."""
    ax = PARAM_AXIS[axis]
    out = {f"RATE_{ax}_{k}": single(v) for k, v in zip(("KC", "TI", "TD"), gains.rate)}
    if gains.angle is not None:
        out.update({f"ANG_{ax}_{k}": single(v) for k, v in zip(("KC", "TD"), gains.angle)})
    return out


def param_range(name: str) -> tuple:
    """A parameter's ``(minimum, maximum, floor)`` as the firmware's table has them (the
    floor: the least a time constant other than 0 may be)."""
    return _RANGES[name]


def recorded_gains(g: dict | None) -> Gains | None:
    """The gains a manifest or models.json recorded (its ``gains``: ``{"rate": [...],
    "angle": [...] or None}``), or None when it recorded none."""
    if not g or not g.get("rate"):
        return None
    angle = g.get("angle")
    return Gains(tuple(float(v) for v in g["rate"]),
                 None if angle is None else tuple(float(v) for v in angle))


def single(value: float) -> float:
    """A single-precision number as the shortest decimal that rounds back to it."""
    return float(str(np.float32(value)))


def load_gains(axis: str, path: str | None = None) -> Gains:
    """The gains the firmware flies (:func:`firmware_gains`: the paper's), or a gains file's
    (:func:`read_gains`)."""
    if path is None:
        return firmware_gains(axis)
    return read_gains(path, axis)


def _rate_angle_specs():
    """A rate loop's ``[Kc, tau_I_s, tau_D_s]`` and an angle loop's ``[Kc, tau_D_s]``."""
    gain, tau_i, tau_d = S.Num(0, 1e4, lo_open=True), S.Num(0, 1e4), S.Num(0, 1e3)
    return (S.Seq(("Kc", gain), ("tau_I_s", tau_i), ("tau_D_s", tau_d)),
            S.Seq(("Kc", gain), ("tau_D_s", tau_d)))


@functools.cache
def _gains_file_schema():
    rate, angle = _rate_angle_specs()
    return S.Obj(required={"rate": S.Obj(optional={a: rate for a in names.AXES}, strict=True)},
                 optional={"angle": S.Obj(optional={a: angle for a in names.AXES if a != "yaw"},
                                          strict=True)},
                 strict=True)


def read_gains(path, axis: str) -> Gains:
    """A gains file's gains for ``axis`` (docs/file-formats.md, "Gains file"): ``{"rate":
    {"roll": [Kc, tau_I_s, tau_D_s], ...}, "angle": {"roll": [Kc, tau_D_s], ...}}``, checked
    against its schema; the angle gains are None for yaw, which is rate only."""
    doc = read_json(path, "gains file", _gains_file_schema())
    if axis not in doc["rate"]:
        S.fail(path, f"rate.{axis}", "is missing ([Kc, tau_I_s, tau_D_s])")
    if axis != "yaw" and axis not in doc.get("angle", {}):
        S.fail(path, f"angle.{axis}", "is missing ([Kc, tau_D_s])")
    rate = tuple(float(v) for v in doc["rate"][axis])
    return Gains(rate, None if axis == "yaw" else tuple(float(v) for v in doc["angle"][axis]))


def recorded_gains_schema():
    """The gains a sweep recorded from its board (manifest.json, carried into models.json):
    rate ``[Kc, tau_I_s, tau_D_s]``, angle ``[Kc, tau_D_s]`` or null (yaw)."""
    rate, angle = _rate_angle_specs()
    return S.Obj(required={"rate": rate}, optional={"angle": S.Null(angle)})
