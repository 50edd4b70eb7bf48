"""The simulated pilot as a script: what the radio's channels do, and when.

A script is text, one change per line::

    # time_s  channel=pulse_us ...
    0.5   5=2000            # arm switch up
    1.0   3=1400            # throttle to 40 %
    2.5   7=2000            # the program switch up
    12.0  7=1000 3=1000 5=1000

``TIME_S`` is seconds of simulated time from the run's first frame (frame ``f`` is at
``f / loop_hz``); each ``CH=US`` sets channel ``CH`` (1-8, the radio's numbering: 1 roll,
2 pitch, 3 throttle, 4 yaw, 5 arm switch, 6 mode switch, 7 and 8 free) to a pulse of ``US``
microseconds from that time on: 800-2200 (a receiver's extended range) or 0 (no pulse: the
receiver's channel lost). ``#`` starts a comment. Before its first change the pilot is the
landed one: sticks centred, throttle and arm switch low, channels 7 and 8 without a pulse.
With a script the script is the pilot: nothing arms or moves a stick unless a line says so.

Lines may come in any order; at equal times the later line wins. A line that is not one of
these is refused with its number (:class:`~heliquad.sim.base.errors.InputError`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..base.errors import InputError
from ..base.userfiles import read_text
from .setup import rc_disarmed

__all__ = ["RcScript", "parse_rc_script", "read_rc_script", "RC_SCRIPT_CHANNELS",
           "PULSE_RANGE_US"]

RC_SCRIPT_CHANNELS = 8
#: The pulses a line may set, us: a receiver's extended output range (0 is "no pulse").
PULSE_RANGE_US = (800, 2200)
#: The landed pilot, channels 1-8 (us): what the rig's default pilot holds before arming.
LANDED_US = tuple(rc_disarmed())
_MAX_BYTES = 1 << 20                      # a script is a few lines; more is not a script


@dataclass(frozen=True)
class RcScript:
    """The pilot's changes, sorted by time: ``changes[k] = (time_s, ((index, us), ...))``,
    channel indexes from 0."""

    changes: tuple = ()

    def rows(self, first: int, n: int, loop_hz: float) -> np.ndarray:
        """The channels of frames ``first`` .. ``first + n - 1``, one row each (uint16 us)."""
        times = np.array([t for t, _ in self.changes], dtype=float)
        # the changes in force at each frame: those at or before its time (a frame's time
        # rounded to the microsecond, so "2.5" means the frame at 2.5 s whatever the rounding)
        frame_us = np.round(np.arange(first, first + n) * (1e6 / loop_hz))
        done = np.searchsorted(np.round(times * 1e6), frame_us, side="right")
        out = np.empty((n, RC_SCRIPT_CHANNELS), dtype=np.uint16)
        state, applied = list(LANDED_US), 0
        for row, upto in enumerate(done):
            for _, sets in self.changes[applied:upto]:
                for index, us in sets:
                    state[index] = us
            applied = max(applied, upto)
            out[row] = state
        return out

    def row(self, frame: int, loop_hz: float) -> np.ndarray:
        """One frame's channels."""
        return self.rows(frame, 1, loop_hz)[0]


def _change(number: int, token: str) -> tuple:
    channel, sep, pulse = token.partition("=")
    where = f"line {number}: {token!r}"
    if not sep:
        raise InputError(f"{where}: expected CH=US (a channel 1-{RC_SCRIPT_CHANNELS} and a "
                         "pulse in us, e.g. 5=2000)")
    try:
        ch, us = int(channel), int(pulse)
    except ValueError:
        raise InputError(f"{where}: channel and pulse must be whole numbers") from None
    if not 1 <= ch <= RC_SCRIPT_CHANNELS:
        raise InputError(f"{where}: channel {ch} is not one of 1-{RC_SCRIPT_CHANNELS}")
    lo, hi = PULSE_RANGE_US
    if us != 0 and not lo <= us <= hi:
        raise InputError(f"{where}: pulse {us} us is outside {lo}-{hi} us (0: no pulse)")
    return ch - 1, us


def parse_rc_script(text: str) -> RcScript:
    """The script in ``text``; InputError naming the first bad line."""
    changes = []
    for number, line in enumerate(text.splitlines(), start=1):
        tokens = line.split("#", 1)[0].split()
        if not tokens:
            continue
        try:
            t = float(tokens[0])
        except ValueError:
            raise InputError(f"line {number}: {tokens[0]!r} is not a time in seconds") from None
        if not math.isfinite(t) or t < 0:
            raise InputError(f"line {number}: time {tokens[0]} must be a finite number of "
                             "seconds, 0 or more")
        if len(tokens) == 1:
            raise InputError(f"line {number}: a time with no CH=US after it")
        changes.append((t, number, tuple(_change(number, tok) for tok in tokens[1:])))
    if not changes:
        raise InputError("no changes: every line is blank or a comment")
    changes.sort(key=lambda c: (c[0], c[1]))
    return RcScript(tuple((t, sets) for t, _, sets in changes))


def read_rc_script(path) -> RcScript:
    """The script in the file ``path``; InputError naming the file (and the line)."""
    text = read_text(path, _MAX_BYTES, "RC script")
    try:
        return parse_rc_script(text)
    except InputError as exc:
        raise InputError(f"{path}: {exc}") from None
