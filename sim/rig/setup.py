"""The simulated rig of a run with the firmware in the loop: its configuration, its plant,
and the pilot's RC.

The simulator plays the rig and the pilot: the plant (:class:`Plant`: a per-axis transfer
function or the 6-DoF vehicle on a rig) gives the MPU6050's FIFO bytes and takes the
firmware's motor commands; the pilot gives RC (throttle low, arm switch up, then hover
throttle). The host tool's side of the run, the telemetry link and the log, is
:class:`heliquad.host.acquire.session.SilSession`.

Input and output of an experiment follow the injection point (HQ_INJECTION in the dialect):
mixer -> u = the axis's total torque command, y = measured rate (the fit gives the plant);
rate -> u = rate setpoint, y = measured rate (closed inner loop);
angle -> u = angle setpoint, y = angle (closed cascade).
"""

from __future__ import annotations

import dataclasses
from typing import Protocol

import numpy as np

from ..base.firmware_facts import LOOP_RATE_HZ
from ..plant.tf_plant import TfPlant
from ..plant.vehicle_params import load_params

#: The Teensy image's links a tool can talk over when the image flies the rig: its own USB
#: port (the cable every Teensy user plugs in; the default) and UART0 (pins 0 and 1, where a
#: telemetry radio goes). The image serves MAVLink on both.
BOARD_LINKS = ("usb", "uart")
DEFAULT_BOARD_LINK = "usb"

__all__ = ["SilConfig", "Plant", "PLANTS", "make_plant", "rc_block", "RC_CENTER_US",
           "rc_disarmed", "BOOT_FRAMES", "ARM_FRAMES"]

RC_CENTER_US, RC_LOW_US, RC_HIGH_US = 1500, 1000, 2000
#: Frames with everything low after start (the firmware initialises), then arm switch up.
BOOT_FRAMES, ARM_FRAMES = 20, 20


@dataclasses.dataclass
class SilConfig:
    """One experiment. ``amplitude`` is in firmware units (rad, rad/s or normalised)."""

    axis: str = "roll"
    num: tuple = (28.19,)
    den: tuple = (1.0, 5.13, 22.93)
    inject: str = "mixer"
    freq_hz: float = 1.0
    amplitude: float = 0.05
    cycles: int = 10
    fade_cycles: int = 2
    loop_hz: float = LOOP_RATE_HZ
    collective: float = 0.4        # hover throttle, fraction of full stick travel
    settle_s: float = 1.0          # hover before the excitation starts
    dmp_image: str | None = None
    plant: str = "tf"              # "tf" (num/den) or "vehicle" (the 6-DoF model)
    rig: str = "roll"              # vehicle plant: roll, pitch, yaw or free
    params: str | None = None      # vehicle parameter file (default: the shipped one)
    load_params: str | None = None  # a .params file the board is given before it arms
    turbulence: str | None = None  # vehicle plant: light, moderate or severe Dryden turbulence
    seed: int = 0                  # turbulence and sensor-noise seed
    ideal_sensor: bool = False     # vehicle plant: no IMU noise, bias or DMP latency
    hinge_friction_n_m: float | None = None  # vehicle plant: the hinge's, over the file's
    faults: tuple = ()             # sim.faults.Fault: what goes wrong, and when
    firmware: str = "host"         # "host" (the host build) or "teensy35" (the image, emulated)
    firmware_image: str | None = None  # teensy35: the .elf (default: the installed image)
    firmware_link: str = DEFAULT_BOARD_LINK  # teensy35: its link the tools talk over (BOARD_LINKS)
    param_store: str | None = None  # where the firmware keeps its parameters (default: nowhere)
    # how long the firmware waits for its next frame before it takes its simulator for gone,
    # s of wall time (its own default; longer for a tool that computes between frames)
    idle_timeout_s: int = 10
    sd_image: str | None = None    # the board's SD card, a card-image file (default: no card)
    sd_faults: str | None = None   # host build: its card's faults, NAME=VALUE,... (docs/sd-card.md)
    rc_script: object = None       # rc_script.RcScript: the pilot (default: arm, then hover)


class Plant(Protocol):
    """What flies on the simulated rig. ``core`` is its C++ model (``heliquad._simcore``),
    which the batch engine steps; the methods step it from Python, one frame at a time."""

    core: object

    def fifo(self, kind: int) -> bytes:
        """This frame's MPU6050 FIFO bytes of the HQ_SENSOR_KIND ``kind``."""

    def step_motors(self, motor) -> float:
        """Advance one loop period with these thrust fractions; the axis's rate, rad/s."""

    def frame_inputs(self, frames: int):
        """The random inputs (sensor noise, gusts) of the next ``frames`` frames, drawn in
        Python so that a run repeats; (None, None) for a plant without any."""

    def truth(self, omega_rad_s, inject: str = "mixer"):
        """The sampled-data response identification should find at ``omega_rad_s``."""


#: The plants a run can fly (``SilConfig.plant``, the commands' ``--plant``): the per-axis
#: transfer function and the 6-DoF vehicle. A new plant is a name here and a branch of
#: :func:`make_plant`.
PLANTS = ("tf", "vehicle")


def make_plant(cfg: SilConfig, dt_s: float) -> Plant:
    """The plant of a run: the per-axis transfer function or the 6-DoF vehicle on its rig."""
    if cfg.plant not in PLANTS:
        raise ValueError(f"unknown plant {cfg.plant!r}")
    if cfg.plant == "tf":
        return TfPlant(cfg.axis, cfg.num, cfg.den, dt_s)
    # the vehicle's plant (8 ms, with its turbulence and IMU models) only for --plant vehicle
    from ..plant.vehicle_plant import VehiclePlant, flown_allocation

    # A vehicle file given to the run has its geometry set on the board (the session does
    # it); without one the firmware flies its defaults.
    params = load_params(cfg.params)
    if cfg.hinge_friction_n_m is not None:
        params = dataclasses.replace(params, rig=dataclasses.replace(
            params.rig, hinge_friction_n_m=float(cfg.hinge_friction_n_m)))
    return VehiclePlant(cfg.axis, cfg.rig, dt_s, params,
                        trim_collective=cfg.collective, turbulence=cfg.turbulence, seed=cfg.seed,
                        ideal_sensor=cfg.ideal_sensor,
                        flown=flown_allocation(params) if cfg.params else None)


def _rc(frame, collective):
    rc = [RC_CENTER_US, RC_CENTER_US, RC_LOW_US, RC_CENTER_US, RC_LOW_US, RC_CENTER_US, 0, 0]
    if frame > BOOT_FRAMES:
        rc[4] = RC_HIGH_US                                     # arm switch
    if frame > BOOT_FRAMES + ARM_FRAMES:
        rc[2] = int(round(RC_LOW_US + collective * (RC_HIGH_US - RC_LOW_US)))
    return rc


def rc_block(first: int, n: int, collective: float, script=None,
             loop_hz: float = LOOP_RATE_HZ) -> np.ndarray:
    """The pilot's RC of frames ``first`` .. ``first + n - 1``, one row each (uint16 us): the
    default pilot (arm, then throttle to ``collective``), or the RC script ``script``
    (sim/rig/rc_script.py) when there is one."""
    if script is not None:
        return script.rows(first, n, loop_hz)
    return np.array([_rc(f, collective) for f in range(first, first + n)], dtype=np.uint16)


def rc_disarmed() -> list:
    """The pilot's RC once landed: throttle low, arm switch down (the firmware disarms)."""
    return _rc(0, 0.0)
