"""The cascade's gains: those the firmware flies, and gains files.

The firmware's ``CascadeGains::paper_defaults()`` (firmware/core/controllers.cpp) is the one
definition of the gains it flies; they are read here through its bindings. host/paper.py keeps
the paper's published figures as the reference, and tests/paper_test.py ties the two. Sweeps
record these gains in their manifest; validation uses them unless given a gains file.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from heliquad import _firmware

from ..sim import dialect as names

__all__ = ["Gains", "firmware_gains", "load_gains", "DERIVATIVE_FILTER_N"]

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
    rate = (_single(r.kc), _single(r.tau_i_s), _single(r.tau_d_s))
    try:
        a = g.angle(which)
    except ValueError:                     # yaw: no angle loop
        return Gains(rate, None)
    return Gains(rate, (_single(a.kc), _single(a.tau_d_s)))


def _single(value: float) -> float:
    """A single-precision number as the shortest decimal that rounds back to it."""
    return float(str(np.float32(value)))


def load_gains(axis: str, path: str | None = None) -> Gains:
    """The gains the firmware flies (:func:`firmware_gains`: the paper's), or a gains file's
    (:func:`heliquad.host.files.read_gains`, checked against its schema):
    ``{"rate": {"roll": [Kc, tau_I, tau_D], ...}, "angle": {"roll": [Kc, tau_D], ...}}``."""
    if path is None:
        return firmware_gains(axis)
    from .files import read_gains

    return Gains(*read_gains(path, axis))
