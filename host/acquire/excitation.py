"""An excitation's amplitude at each injection point: the units the command line gives it in
and the firmware's, the default of a sweep, the firmware's bound, and a multisine's default
peak. The one place these are written; the commands, the sweep, its design and the multisine
take them from here.

The command line speaks deg (angle), deg/s (rate) and the normalised torque command (mixer);
the firmware rad, rad/s and the same normalised command. The bound is the firmware's own
(:func:`heliquad.sim.base.firmware_facts.max_amplitude`).
"""

from __future__ import annotations

import math

from ...sim.base import firmware_facts

__all__ = ["UNITS", "DEFAULT_SETPOINT", "firmware_amplitude", "command_line_amplitude",
           "default_amplitude", "amplitude_bound", "bound_text", "default_peak",
           "defaults_text", "units_text"]

#: The command line's unit of ``--amplitude`` per injection point.
UNITS = {"angle": "deg", "rate": "deg/s", "mixer": "normalised"}
#: A sweep's amplitude for angle and rate injection, in the command line's units: a 5 deg
#: angle or 10 deg/s rate setpoint, responses in themselves (a mixer sweep's amplitudes are
#: designed per frequency, :mod:`.design`).
DEFAULT_SETPOINT = {"angle": 5.0, "rate": 10.0}


def firmware_amplitude(inject: str, amplitude: float) -> float:
    """``--amplitude`` in the firmware's units: deg (angle) and deg/s (rate) become rad and
    rad/s; a mixer amplitude is already normalised."""
    return amplitude if inject == "mixer" else math.radians(amplitude)


def command_line_amplitude(inject: str, amplitude: float) -> float:
    """A firmware-unit amplitude in the command line's units (:func:`firmware_amplitude`
    undone)."""
    return amplitude if inject == "mixer" else math.degrees(amplitude)


def default_amplitude(inject: str) -> float:
    """The firmware-unit amplitude of an angle or rate sweep (:data:`DEFAULT_SETPOINT`)."""
    return firmware_amplitude(inject, DEFAULT_SETPOINT["rate" if inject == "rate" else "angle"])


def amplitude_bound(inject: str) -> float:
    """The firmware's largest amplitude for an injection point (its SafetyLimits), its units."""
    return firmware_facts.max_amplitude(inject)


def bound_text(inject: str) -> str:
    """The firmware's bound at ``inject`` as the command line gives it: "45 deg", "1"."""
    top = command_line_amplitude(inject, amplitude_bound(inject))
    return f"{top:g}" if inject == "mixer" else f"{top:g} {UNITS[inject]}"


def default_peak(inject: str) -> float:
    """A multisine's peak without ``--amplitude`` (firmware units): the dwell's setpoint for
    angle and rate injection, the firmware's bound at the mixer."""
    return amplitude_bound(inject) if inject == "mixer" else default_amplitude(inject)


def units_text() -> str:
    """``--amplitude``'s units for a help text: "deg (angle), deg/s (rate), normalised
    (mixer)"."""
    return ", ".join(f"{unit} ({inject})" for inject, unit in UNITS.items())


def defaults_text() -> str:
    """The angle and rate sweeps' default amplitudes for a help text: "5 deg (angle),
    10 deg/s (rate)"."""
    return ", ".join(f"{value:g} {UNITS[inject]} ({inject})"
                     for inject, value in DEFAULT_SETPOINT.items())
