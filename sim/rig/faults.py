"""Fault injection in the SIL: what goes wrong, and when (``heliquad sil --fault KIND@T``).

The emulated MPU6050 (and, on the emulated Teensy, its bus) takes a fault per sim-link frame,
``HQ_SENSOR_FRAME.imu_fault`` (the dialect's HQ_IMU_FAULT):

* ``silent``: the chip answers on the bus but produces no FIFO data;
* ``nack``: the chip does not acknowledge its address, every transfer fails;
* ``reset``: the chip resets to its power-on defaults (a brown-out): registers, FIFO and
  DMP memory are lost; once, at T;
* ``overflow``: the FIFO overflows (filled past 1024 bytes, misaligned); once, at T;
* ``stuck-bus``: a device holds the I2C clock low, no transfer completes (on the emulated
  Teensy; the host build, whose bus has no timing, fails every transfer as for ``nack``).

``silent``, ``nack`` and ``stuck-bus`` hold from T for the given duration (``KIND@T:D``, seconds), or to the
end of the run. And one fault of the host, not the chip:

* ``link``: the host tool closes its telemetry link at T (as when it crashes): no more
  heartbeats or commands. The simulator's own tap of the link keeps logging.

A fault acts on the first frame whose time is at or after T.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from ..base.dialect import dialect
from ..base.errors import InputError

__all__ = ["Fault", "parse_fault", "check_faults", "imu_fault_codes", "link_close_frame", "KINDS"]

#: Fault kinds and whether they hold over a duration (True) or act once (False).
KINDS = {"silent": True, "nack": True, "stuck-bus": True, "reset": False, "overflow": False,
         "link": False}


@dataclasses.dataclass(frozen=True)
class Fault:
    """One fault: ``kind`` (see :data:`KINDS`) from ``at_s``; ``duration_s`` for the holding
    kinds (None: to the end)."""

    kind: str
    at_s: float
    duration_s: float | None = None

    def __post_init__(self):
        if self.kind not in KINDS:
            raise InputError(f"unknown fault {self.kind!r}; one of {', '.join(KINDS)}")
        if not (math.isfinite(self.at_s) and self.at_s >= 0):
            raise InputError(f"fault {self.kind}: the time must be a non-negative number of seconds")
        if self.duration_s is not None:
            if not KINDS[self.kind]:
                raise InputError(f"fault {self.kind} happens once; it takes no duration")
            if not (math.isfinite(self.duration_s) and self.duration_s > 0):
                raise InputError(f"fault {self.kind}: the duration must be positive")

    def imu_code(self) -> int | None:
        """The HQ_IMU_FAULT value, or None for the host's own fault (``link``)."""
        if self.kind == "link":
            return None
        return getattr(dialect(), "HQ_IMU_FAULT_" + self.kind.upper().replace("-", "_"))

    def first_frame(self, dt_us: int) -> int:
        """The first frame (frame k runs at k * dt_us) at or after the fault's time."""
        return max(1, math.ceil(round(self.at_s * 1e6) / dt_us))

    def last_frame(self, dt_us: int) -> float:
        """The last frame the fault acts on (inclusive; inf: to the end)."""
        if not KINDS[self.kind]:
            return self.first_frame(dt_us)
        if self.duration_s is None:
            return math.inf
        end_us = round((self.at_s + self.duration_s) * 1e6)
        return math.ceil(end_us / dt_us) - 1


def parse_fault(text: str) -> Fault:
    """``KIND@T`` or ``KIND@T:D`` (seconds), as given to ``--fault``."""
    kind, sep, when = text.partition("@")
    if not sep:
        raise InputError(f"--fault {text!r}: expected KIND@T or KIND@T:D, e.g. silent@2:0.5")
    at, _, duration = when.partition(":")
    try:
        at_s = float(at)
        duration_s = float(duration) if duration else None
    except ValueError:
        raise InputError(f"--fault {text!r}: T and D are seconds, e.g. silent@2:0.5") from None
    try:
        return Fault(kind.strip().lower(), at_s, duration_s)
    except InputError as exc:
        raise InputError(f"--fault {text!r}: {exc}") from None


def check_faults(faults, dt_us: int) -> None:
    """Refuse a fault that would act on no frame (shorter than a loop, between two frames)."""
    for f in faults:
        if f.last_frame(dt_us) < f.first_frame(dt_us):
            raise InputError(f"fault {f.kind}@{f.at_s:g}:{f.duration_s:g} falls between two "
                             f"loops ({dt_us * 1e-3:g} ms apart) and would act on none; "
                             "make it longer")


def imu_fault_codes(faults, first: int, n: int, dt_us: int) -> np.ndarray | None:
    """HQ_IMU_FAULT per frame for frames ``first .. first + n - 1``; None when no IMU fault
    acts on any of them. Where two overlap, the later-listed fault wins."""
    codes = np.zeros(n, dtype=np.uint8)
    frames = np.arange(first, first + n)
    for fault in faults:
        code = fault.imu_code()
        if code is None:
            continue
        on = (frames >= fault.first_frame(dt_us)) & (frames <= fault.last_frame(dt_us))
        codes[on] = code
    return codes if codes.any() else None


def link_close_frame(faults, dt_us: int) -> int | None:
    """The frame before which the host closes its telemetry link, or None."""
    frames = [f.first_frame(dt_us) for f in faults if f.kind == "link"]
    return min(frames) if frames else None
