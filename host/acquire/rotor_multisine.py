"""The per-rotor multisine of ``heliquad sweep --inject motors``: every rotor excited at once,
each on lines of its own, as one HQ_EXCITATION with injection MOTORS.

The firmware gives harmonic ``j`` of the message (in its order) to rotor ``j mod R`` and
holds each rotor's own sum to the declared peak (or, with MOTORn, every harmonic to rotor
``n - 1``: one run per rotor, each with all the message's lines) (docs/effectiveness.md, "The experiment").
The lines are odd harmonics only, rotor ``i`` on ``2 (i + R m) + 1``: the rotors' thrust is
quadratic in their speed, so two lines of one rotor make sums and differences, which are even
and land on no rotor's line (docs/effectiveness.md: on the simulated roll rig this kept the
rotors with no roll moment below 0.1 % of the row's largest entry, where lines on every
harmonic left 2.9 %). In the message's order (increasing) the harmonic of rotor ``i`` at
step ``m`` is then entry ``R rank(m) + i``: rotor ``j mod R`` as the firmware assigns it.

Design (:func:`rotor_design`): ``MAX_LINES // R`` lines per rotor (the most HQ_EXCITATION
carries, shared; fewer, down to two, when the rig time cannot hold three periods), the steps ``m`` log-spaced from 0 to the highest whose every rotor's line
stays at or below the band's top; the base period the shortest that gives each rotor that
many lines (the most whole periods in the rig time), and as many whole periods as fit the
rig time with the fades (one cycle of the lowest line each way). Each rotor's lines have
equal amplitudes and low-crest phases (:func:`.multisine.low_crest_phases`), scaled so that
each rotor's own sum peaks at the rotor's peak. The peak the message declares, which the
firmware holds each rotor's sum to, is that peak, or the whole sum's RMS when it is larger
(the firmware refuses a declared peak below the RMS of all the lines together).
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from ...sim.base import firmware_facts
from ...sim.base.errors import InputError
from .multisine import MAX_LINES, MIN_PERIODS, RIG_TIME_S, Multisine, low_crest_phases

__all__ = ["RotorMultisine", "rotor_design", "rotor_orders", "ROTOR_PEAK"]

#: Each rotor's peak, thrust fraction: on the simulated rigs 0.03 already bent the points by
#: 2 % (the rotors' quadratic thrust, docs/effectiveness.md); at 0.01 the intermodulation
#: stayed below 0.1 % of a row's largest entry.
ROTOR_PEAK = 0.01
#: The declared peak is at least the whole sum's RMS times this (the firmware compares in
#: single precision).
RMS_MARGIN = 1.001
#: The fewest lines a rotor may have: a lag and a delay need two frequencies.
MIN_ROTOR_LINES = 2


def rotor_orders(rotors: int, steps) -> tuple:
    """Each rotor's harmonics: rotor ``i`` on ``2 (i + rotors m) + 1`` for each ``m`` of
    ``steps``."""
    return tuple(tuple(int(2 * (i + rotors * m) + 1) for m in steps) for i in range(rotors))


@dataclasses.dataclass(frozen=True)
class RotorMultisine(Multisine):
    """A :class:`~heliquad.host.acquire.multisine.Multisine` whose lines are shared out among
    ``rotors`` rotors, harmonic ``j`` (in increasing order) to rotor ``j mod rotors``;
    ``peak`` is each rotor's own."""

    rotors: int = 1
    rotor_peak: float = 0.0
    only: int | None = None        # the one rotor excited (0-based; MOTORn), or None: all

    @property
    def rotor_orders(self) -> tuple:
        """Per rotor (the central one first), its harmonics (none for a rotor not excited)."""
        if self.only is not None:
            return tuple(tuple(self.orders) if i == self.only else () for i in
                         range(self.rotors))
        return tuple(tuple(self.orders[i::self.rotors]) for i in range(self.rotors))

    def record(self) -> dict:
        """The design, for the manifest: the multisine's, and each rotor's lines."""
        return {**super().record(), "rotors": self.rotors, "rotor_peak": self.rotor_peak,
                "rotor_orders": [list(o) for o in self.rotor_orders]}


def _steps(rotors: int, per_rotor: int, highest_order: float) -> np.ndarray | None:
    """``per_rotor`` steps ``m``, log-spaced from 0, whose every rotor's line is at most
    ``highest_order``; None when fewer fit."""
    top = int(math.floor(((highest_order - 1) / 2 - (rotors - 1)) / rotors))
    if top + 1 < per_rotor:
        return None
    steps = np.unique(np.round(np.geomspace(1, top + 1, per_rotor)).astype(int) - 1)
    while steps.size < per_rotor:            # rounding merged two: fill from the bottom
        steps = np.union1d(steps, np.setdiff1d(np.arange(top + 1), steps)[:1])
    return steps


def _grid(top_hz: float, rotors: int, per_rotor: int, fs_hz: float) -> tuple:
    """(the base period, the steps ``m``): the shortest period that gives each rotor
    ``per_rotor`` lines at or below ``top_hz``."""
    highest = 2 * (rotors - 1 + rotors * (per_rotor - 1)) + 1
    n = int(math.ceil(highest * fs_hz / top_hz))
    steps = _steps(rotors, per_rotor, top_hz * n / fs_hz)
    if steps is None:                                 # round-off at the top: one more sample
        n += 1
        steps = _steps(rotors, per_rotor, top_hz * n / fs_hz)
    return n, steps


def rotor_design(top_hz: float, rotors: int, peak: float = ROTOR_PEAK, lines: int = MAX_LINES,
                 rig_time_s: float = RIG_TIME_S, fs_hz: float | None = None,
                 only: int | None = None) -> RotorMultisine:
    """The per-rotor multisine (module docstring) for ``rotors`` rotors whose lines reach up
    to ``top_hz``, ``lines`` in all (shared out, ``lines // rotors`` each), in
    ``rig_time_s``; ``peak``: each rotor's, thrust fraction. ``only``: every line to that
    rotor alone (0-based, injection MOTORn: still odd harmonics)."""
    fs_hz = float(fs_hz or firmware_facts.LOOP_RATE_HZ)
    sharing = rotors if only is None else 1
    per_rotor = min(lines, MAX_LINES) // sharing
    if per_rotor < MIN_ROTOR_LINES:
        raise InputError(f"{rotors} rotors need {MIN_ROTOR_LINES * rotors} lines, "
                         f"{MIN_ROTOR_LINES} each; HQ_EXCITATION carries {MAX_LINES}"
                         + ("" if lines >= MAX_LINES else f" and --lines gives {lines}"))
    hi = float(top_hz)
    if not 0 < hi <= fs_hz / 4:
        raise InputError(f"the band's top, {hi:g} Hz, must be above 0 and at most "
                         f"{fs_hz / 4:g} Hz")
    for lines_each in range(per_rotor, MIN_ROTOR_LINES - 1, -1):
        n, steps = _grid(hi, sharing, lines_each, fs_hz)
        periods = int((rig_time_s * fs_hz - 2 * n) // n)      # fades: a cycle of harmonic 1
        if periods >= MIN_PERIODS:
            break
    else:
        raise InputError(f"{MIN_ROTOR_LINES} lines for each of {sharing} rotors up to {hi:g} Hz "
                         f"need a {n / fs_hz:.3g} s period: {MIN_PERIODS} of them and the fades "
                         f"take {(MIN_PERIODS + 2) * n / fs_hz:.0f} s, more than "
                         f"{rig_time_s:g} s (a longer rig time or a higher band)")
    orders = sorted(o for rotor in rotor_orders(sharing, steps) for o in rotor)
    amplitudes, phases = np.zeros(len(orders)), np.zeros(len(orders))
    for i in range(sharing):
        own = orders[i::sharing]
        ph = low_crest_phases(own, np.ones(len(own)), n)
        alone = Multisine(fs_hz, n, tuple(own), (1.0,) * len(own), tuple(ph), 1.0, periods)
        scale = peak / float(np.max(np.abs(alone.period())))
        amplitudes[i::sharing], phases[i::sharing] = scale, ph
    # The firmware also refuses a declared peak below the whole sum's RMS (a peak is at
    # least the RMS), which with many rotors exceeds each rotor's own peak.
    declared = max(float(peak), RMS_MARGIN * math.sqrt(float(np.sum(amplitudes ** 2)) / 2))
    return RotorMultisine(fs_hz, n, tuple(orders), tuple(float(a) for a in amplitudes),
                          tuple(float(p) for p in phases), declared, periods,
                          rotors=rotors, rotor_peak=float(peak), only=only)
