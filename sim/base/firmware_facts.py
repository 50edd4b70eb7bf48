"""The firmware's facts that the simulator and the host tool use: the control loop's rate and
period, the most the host build runs at, the most its ptys' backlog bound can be, the
defaults of its SafetyLimits (the excitation's band, length, fade and amplitude bounds, and
the abort limits), how many rotors its control allocation flies, and the Teensy image's USB
identity (what ``--port auto`` matches).

Each is defined once, in the firmware's C++ (firmware/core/flight_controller.hpp,
supervisor.hpp, excitation.hpp, pid.hpp, allocation.hpp; firmware/targets/host/pty_backlog.hpp;
firmware/targets/teensy35/usb_identity.hpp), and read
here from its bindings (``heliquad._firmware``, the same code the firmware compiles); every
Python use takes it from this module. tests/firmware_facts_test.py scans the Python sources
for a copy.
"""

from __future__ import annotations

from typing import NamedTuple

from heliquad import _firmware

from . import dialect

__all__ = ["LOOP_RATE_HZ", "LOOP_PERIOD_S", "MAX_LOOP_RATE_HZ", "MAX_PTY_BACKLOG_BYTES",
           "ABORT_ANGLE_RAD", "ABORT_RATE_RAD_S", "MIN_FREQ_HZ", "MAX_FREQ_FRACTION",
           "MAX_DURATION_S", "MIN_FADE_CYCLES", "MAX_HARMONICS", "MAX_PROGRAM_STEPS",
           "MIN_TIME_CONSTANT_S", "MIN_ROTORS", "MAX_ROTORS",
           "UsbIdentity", "USB_IDENTITY", "usb_serial_number",
           "max_amplitude", "safety_limits"]

#: The control loop's rate unless configured otherwise, Hz, and its period, s.
LOOP_RATE_HZ = float(_firmware.LOOP_RATE_HZ)
LOOP_PERIOD_S = 1.0 / LOOP_RATE_HZ
#: The most the host build's loop runs at (its --loop-hz), Hz.
MAX_LOOP_RATE_HZ = float(_firmware.MAX_LOOP_RATE_HZ)
#: The most telemetry a pty of the host build keeps waiting for a reader under a backlog bound
#: (its --telemetry-backlog-bytes): what the line discipline holds in sight of TIOCINQ, bytes.
MAX_PTY_BACKLOG_BYTES = int(_firmware.MAX_PTY_BACKLOG_BYTES)


class UsbIdentity(NamedTuple):
    """A USB device's identity as its descriptors give it."""

    vid: int
    pid: int
    manufacturer: str
    product: str


#: The Teensy image's USB identity: Teensyduino's USB Serial vendor and product IDs (a stock
#: sketch has them too), and the manufacturer and product strings; heliquad's product string
#: contains "heliquad".
USB_IDENTITY = UsbIdentity(int(_firmware.USB_VID), int(_firmware.USB_PID),
                           str(_firmware.USB_MANUFACTURER), str(_firmware.USB_PRODUCT))


def usb_serial_number(uid_words) -> str:
    """The USB serial number of a chip whose unique identification (SIM_UIDH, UIDMH, UIDML,
    UIDL) is ``uid_words``, as the image's descriptor says it."""
    return str(_firmware.usb_serial_number(*(int(w) for w in uid_words)))


def safety_limits():
    """A fresh copy of the firmware's default SafetyLimits (``heliquad._firmware``)."""
    return _firmware.SafetyLimits()


_LIMITS = safety_limits()
#: The abort limits: an angle (roll, pitch) or a body rate beyond these ends an excitation.
ABORT_ANGLE_RAD = float(_LIMITS.abort_angle_rad)
ABORT_RATE_RAD_S = float(_LIMITS.abort_rate_rad_s)
#: The excitation's band: from MIN_FREQ_HZ to MAX_FREQ_FRACTION of the loop rate.
MIN_FREQ_HZ = float(_LIMITS.min_freq_hz)
MAX_FREQ_FRACTION = float(_LIMITS.max_freq_fraction)
#: The longest excitation, fades included, s; the fewest cycles of fade each way.
MAX_DURATION_S = float(_LIMITS.max_duration_s)
MIN_FADE_CYCLES = int(_LIMITS.min_fade_cycles)
#: The most lines a multisine excitation carries.
MAX_HARMONICS = int(_firmware.MAX_HARMONICS)
#: The most steps an on-board program has.
MAX_PROGRAM_STEPS = int(_firmware.MAX_PROGRAM_STEPS)
#: The shortest integral or derivative time the PID takes, s (below it: no integral).
MIN_TIME_CONSTANT_S = float(_firmware.MIN_TIME_CONSTANT_S)
#: The fewest and the most rotors the control allocation flies (rotor 0 the central one).
MIN_ROTORS, MAX_ROTORS = int(_firmware.MIN_ROTORS), int(_firmware.MAX_ROTORS)


def max_amplitude(inject: str) -> float:
    """The firmware's largest amplitude (a multisine's peak) at an injection point, in its
    units: rad (angle), rad/s (rate), normalised torque command (mixer), thrust fraction
    (motor1..8 and motors, which share the last bound, EXC_MAX_MOT)."""
    bounds = _LIMITS.max_amplitude
    return float(bounds[min(dialect.INJECTIONS[inject], len(bounds) - 1)])
