"""The cascade's gains: those the firmware flies, and gains files.

The firmware's ``CascadeGains::paper_defaults()`` (firmware/core/controllers.cpp) is the one
definition of the gains it flies by default; they are read here through its bindings.
host/records/paper.py keeps the paper's published figures as the reference, and tests/paper_test.py
ties the two. On a board the gains are parameters (docs/parameters.md): a sweep reads them
from the board it flies and records them in its manifest (:func:`gains_from_params`),
identify carries them into models.json, and validation uses them unless given a gains file.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from heliquad import _firmware

from ...sim.base import dialect as names

__all__ = ["Gains", "firmware_gains", "load_gains", "gains_from_params", "recorded_gains",
           "single", "DERIVATIVE_FILTER_N"]

#: The derivative filter's N (tau_f = tau_D / N) of the firmware's rate loop, which it flies.
DERIVATIVE_FILTER_N = float(_firmware.CascadeGains.paper_defaults().rate(
    _firmware.Axis.ROLL).derivative_filter_n)


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


def recorded_gains(doc: dict | None) -> Gains | None:
    """The gains a manifest or models.json recorded (``{"rate": [...], "angle": [...] or
    None}``), or None when it recorded none."""
    g = (doc or {}).get("gains")
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
    (:func:`heliquad.host.records.files.read_gains`, checked against its schema):
    ``{"rate": {"roll": [Kc, tau_I, tau_D], ...}, "angle": {"roll": [Kc, tau_D], ...}}``."""
    if path is None:
        return firmware_gains(axis)
    from .files import read_gains

    return Gains(*read_gains(path, axis))
