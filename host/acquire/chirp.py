"""Chirp excitation: one frequency sweep over the band (``heliquad sweep --signal chirp``), as
ArduPilot's SystemID mode flies one.

The firmware sweeps from the band's bottom to its top over ``sweep_s`` seconds at full
amplitude, logarithmically by default (the frequency a constant factor per second, so every
octave gets the same time and as many of its cycles as the record's windows need) or
linearly; it fades in over ``fade_cycles`` cycles held at the start frequency and out over as
many samples at the frequency reached (firmware/core/excitation.hpp). A chirp has no period:
``heliquad identify`` estimates it, fades included, by the composite of overlapped windows of
several lengths (host/estimate/composite.py), against the logged excitation.

Amplitude: one for the whole sweep, bounded by the firmware as a sine's. A chirp puts its
power at one frequency at a time, as a dwell does, so its default is the dwell's (the
setpoints for angle and rate injection); at the mixer, where a dwell's amplitude is designed
per frequency for the rig's swing, it is :data:`MIXER_AMPLITUDE`, a quarter of the
firmware's bound (what an on-board program's dwell starts with): on the simulated vehicle's
rigs in still air the cascade holds the swing to 1.5 deg (roll, pitch), and under moderate
turbulence the roll model identified from it stays within 0.6 dB and 2.5 deg of the
still-air one.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from ...sim.base import firmware_facts
from ...sim.base.errors import InputError
from .excitation import amplitude_bound, default_amplitude

__all__ = ["Chirp", "design", "fade_cycles_for", "fade_samples", "SWEEP_S", "LAWS",
           "MIXER_AMPLITUDE",
           "FADE_S", "MAX_FADE_CYCLES"]

#: The sweep's length at full amplitude by default, s (fades come on top).
SWEEP_S = 60.0
#: How the frequency moves: logarithmically (HQ_SIGNAL_CHIRP) or linearly.
LAWS = ("log", "linear")
#: A mixer chirp's amplitude without --amplitude (normalised torque command).
MIXER_AMPLITUDE = 0.25
#: The fades (in, and out) last whole cycles of the band's bottom: as many as fit FADE_S,
#: at most MAX_FADE_CYCLES and at least the firmware's least. They hold the two ends'
#: frequencies, which the sweep only passes through, and identify reads them with the
#: sweep: on the simulated roll rig (0.5-4.5 Hz) the points at the band's bottom came within
#: 2.96, 1.87 and 1.35 deg of the dwell's with 4, 6 and 8 cycles (0.25 dB and 4.6 deg off
#: the truth with 2).
FADE_S = 12.0
MAX_FADE_CYCLES = 6


@dataclasses.dataclass(frozen=True)
class Chirp:
    """One chirp: its two ends (start, stop), sweep length, law, amplitude and fades."""

    start_hz: float
    stop_hz: float
    sweep_s: float
    law: str
    amplitude: float
    fade_cycles: int
    fs_hz: float = firmware_facts.LOOP_RATE_HZ

    @property
    def band_hz(self) -> tuple:
        return min(self.start_hz, self.stop_hz), max(self.start_hz, self.stop_hz)

    @property
    def sweep_samples(self) -> int:
        """The sweep's loop samples, as the firmware rounds them."""
        return int(round(self.sweep_s * self.fs_hz))

    @property
    def fade_samples(self) -> int:
        """Each fade's loop samples: :func:`fade_samples`."""
        return fade_samples(self.band_hz[0], self.fade_cycles, self.fs_hz)

    @property
    def duration_s(self) -> float:
        """The excitation's length, fades included (the rig time it costs), in the
        firmware's whole samples."""
        return (self.sweep_samples + 2 * self.fade_samples) / self.fs_hz

    def record(self) -> dict:
        """The design, for the manifest."""
        return {"signal": "chirp", "start_hz": self.start_hz, "stop_hz": self.stop_hz,
                "sweep_s": self.sweep_s, "law": self.law, "amplitude": self.amplitude,
                "fade_cycles": self.fade_cycles, "duration_s": self.duration_s}


def fade_samples(lo_hz: float, fade_cycles: int, loop_hz: float) -> int:
    """A chirp's fade in loop samples as the firmware counts it (excitation.cpp
    ``chirp_fade_samples_for``): ``fade_cycles`` cycles of its lower end ``lo_hz``, each
    rounded up to a sample, the lower end being the request's single-precision value."""
    return fade_cycles * math.ceil(float(loop_hz) / float(np.float32(lo_hz)))


def fade_cycles_for(lo_hz: float) -> int:
    """The fades' cycles of a chirp whose band's bottom is ``lo_hz`` (:data:`FADE_S`)."""
    return max(firmware_facts.MIN_FADE_CYCLES, min(MAX_FADE_CYCLES, int(FADE_S * lo_hz)))


def design(band_hz, inject: str, amplitude=None, sweep_s=None, law: str = "log",
           loop_hz: float = firmware_facts.LOOP_RATE_HZ) -> Chirp:
    """A chirp from the band's bottom to its top (firmware units for ``amplitude``), checked
    against the firmware's limits (its band, amplitude bound and duration cap), so that what
    the firmware would refuse is said before anything flies."""
    lo, hi = (float(f) for f in band_hz)
    if law not in LAWS:
        raise InputError(f"unknown chirp law {law!r}; use one of {', '.join(LAWS)}")
    top = firmware_facts.MAX_FREQ_FRACTION * loop_hz
    if not (firmware_facts.MIN_FREQ_HZ <= lo < hi <= top):
        raise InputError(f"a chirp over {lo:g}-{hi:g} Hz is outside the firmware's excitation "
                         f"band [{firmware_facts.MIN_FREQ_HZ:g}, {top:g}] Hz at a {loop_hz:g} Hz "
                         "loop (or its edges are not increasing)")
    if amplitude is None:
        amplitude = MIXER_AMPLITUDE if inject == "mixer" else default_amplitude(inject)
    if not 0 < amplitude <= amplitude_bound(inject):
        raise InputError(f"the chirp's amplitude {amplitude:g} is outside the firmware's bound "
                         f"for {inject} injection (0, {amplitude_bound(inject):g}]")
    chirp = Chirp(lo, hi, float(sweep_s or SWEEP_S), law, float(amplitude),
                  fade_cycles_for(lo), float(loop_hz))
    if not math.isfinite(chirp.sweep_s) or chirp.sweep_s <= 0:
        raise InputError("the chirp's sweep must last a positive time")
    if chirp.duration_s > firmware_facts.MAX_DURATION_S:
        raise InputError(f"the chirp lasts {chirp.duration_s:.0f} s with its fades; the "
                         f"firmware allows {firmware_facts.MAX_DURATION_S:g} s: a shorter "
                         "--rig-time")
    return chirp
