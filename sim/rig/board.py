"""Free-running mode: the simulated rig behaves like a board on a serial port.

``heliquad board`` starts the firmware with a plant (a transfer function, or the 6-DoF
vehicle on a rig) and steps it in real time (one frame per loop period of wall-clock time), hovering with the arm switch up,
and publishes the firmware's telemetry link as a pty. Any tool then connects to that path
as it would to /dev/ttyACM0 (`heliquad log`, a sweep, QGroundControl over a serial link,
or pymavlink). Given a USB serial number, it announces the pty with the board's USB identity
while it runs, so that ``--port auto`` finds it (:mod:`.announce`). The simulator does not
read the telemetry: if nobody does, the firmware's buffer fills and it drops and counts
messages, as a UART would.

An orderly stop (Ctrl-C, SIGTERM, SIGHUP, the end of ``duration_s``) lands first, as a pilot
does before power-off: throttle low, arm switch down, and the firmware stepped (in lockstep,
no longer in real time) until it reports disarmed and then for :data:`SAVE_WAIT_S`, so that
the parameters it saves only while disarmed (``--param-store``) are saved before it stops.
"""

from __future__ import annotations

import contextlib
import os
import time

import numpy as np

from ..base.firmware_facts import LOOP_RATE_HZ, MAX_PTY_BACKLOG_BYTES
from .announce import announced
from .driver import Rig
from .setup import DEFAULT_BOARD_LINK, rc_block, rc_disarmed

__all__ = ["run_board"]

#: If the simulator falls this far behind real time, it resynchronises instead of racing.
MAX_LAG_S = 0.1
#: How long the landed board runs on after it disarmed: the firmware saves changed parameters
#: once disarmed and 0.5 s after the last change (kSaveQuietUs, firmware/core/
#: flight_controller.cpp), plus 0.1 s to spare.
SAVE_WAIT_S = 0.6
#: The most telemetry that waits for a reader on the pty, the oldest dropped past it, as a
#: board's USB or UART buffer holds a few KiB and not seconds: a tool that opens the port late
#: reads about this much of the past (0.17 s at the firmware's 25 kB/s), then the present.
#: The largest the pty's line discipline holds in sight (firmware_facts); a write the kernel
#: has not yet moved there is not seen, so one loop's more may wait.
TELEMETRY_BACKLOG_BYTES = MAX_PTY_BACKLOG_BYTES
#: How long the pilot's switch may take to disarm the board before the stop goes on without
#: it (the firmware disarms on the frame the switch goes down).
DISARM_WAIT_S = 1.0


def run_board(plant, telemetry_path: str, loop_hz: float = LOOP_RATE_HZ,
              collective: float = 0.4, duration_s: float | None = None,
              dmp_image: str | None = None, ready=None, firmware: str = "host",
              params_file: str | None = None, armed: bool = True,
              backlog_bytes: int = TELEMETRY_BACKLOG_BYTES,
              usb_serial: str | None = None, link: str = DEFAULT_BOARD_LINK, rc_script=None,
              sd_image: str | None = None, sd_faults: str | None = None,
              configure=None) -> dict:
    """Fly ``plant`` (given the loop period, s, it returns the rig's plant: setup.make_plant)
    until ``duration_s`` of wall time (or Ctrl-C), then land (disarm) and stop.
    Returns counters, whether it ``landed`` and what KeyboardInterrupt ``stopped_by`` it
    (None for ``duration_s``): the caller says so, with its exit code. ``ready`` is told
    when the telemetry port is there (default: a line on stdout, flushed at once, for
    whatever waits for it). ``params_file``: where the firmware keeps its parameters
    (default: nowhere; every start has the defaults). ``armed=False``: the pilot leaves the
    arm switch and the throttle low (a ground station then sees a disarmed vehicle, whose
    every parameter may change). ``backlog_bytes``: the most telemetry that waits for a
    reader, the oldest dropped past it (0: all of it waits, as a bare pty keeps it).
    ``usb_serial``: announce the pty, with this USB serial number, from before ``ready`` until
    the board has landed (default: not announced). ``link``: the Teensy image's link the
    pty carries (``usb``, the default, or ``uart``; teensy35 only). ``rc_script``: the pilot, an
    :class:`~.rc_script.RcScript` (its times from the first frame; ``armed`` then unused).
    ``sd_image``, ``sd_faults``: the board's SD card, a card-image file, and the host build's
    faults of it (:class:`~.lockstep.HostFirmware`; default no card). ``configure``: called
    with the rig once the firmware runs and before the board flies in real time (the host
    tool's parameter settings, stepping the rig in lockstep with the pilot landed)."""

    ready = ready or (lambda text: print(text, flush=True))
    dt_s = 1.0 / loop_hz
    run = {"frames": 0, "resyncs": 0, "stopped_by": None, "landed": False}
    with Rig(plant, firmware, loop_hz,
             dmp_image=dmp_image, telemetry_path=os.path.abspath(telemetry_path),
             params_file=params_file, telemetry_backlog_bytes=backlog_bytes,
             **({"link": link} if firmware == "teensy35" else {}),
             sd_image=sd_image, sd_faults=sd_faults) as rig, \
            (contextlib.nullcontext() if usb_serial is None else
             announced(telemetry_path, usb_serial, firmware)):
        if configure is not None:
            configure(rig)
        _fly(rig, run, dt_s, duration_s,
             lambda: ready(f"board running: telemetry on {telemetry_path} (Ctrl-C to stop)"),
             _pilot(rc_script, armed, collective, loop_hz))
        run["landed"] = _land(rig, run, dt_s)
    return run             # the rig closed: the firmware's links and temporary folder gone


def _pilot(rc_script, armed: bool, collective: float, loop_hz: float):
    """The pilot's channels at a frame: the script's, else armed and hovering at
    ``collective``, else landed."""
    if rc_script is not None:
        return lambda frame: rc_script.row(frame, loop_hz)
    if armed:
        return lambda frame: rc_block(frame, 1, collective)[0]
    landed = rc_disarmed()
    return lambda frame: landed


def _fly(rig, run, dt_s, duration_s, say_ready, pilot) -> None:
    """Say ready, then fly in real time until ``duration_s`` or a KeyboardInterrupt (kept
    in ``run``), the pilot's channels ``pilot(frame)``."""
    try:
        # Said inside: a Ctrl-C from whoever waited for the line stops the board as any
        # later one does.
        say_ready()
        t0 = time.monotonic()
        while duration_s is None or run["frames"] * dt_s < duration_s:
            run["frames"] += 1
            target = t0 + run["frames"] * dt_s
            now = time.monotonic()
            if now < target:
                time.sleep(target - now)
            elif now - target > MAX_LAG_S:
                run["resyncs"] += 1
                t0 = now - run["frames"] * dt_s     # resynchronise to real time
            _step(rig, pilot(run["frames"]))
    except KeyboardInterrupt as exc:             # Ctrl-C; SIGTERM, SIGHUP as its subclasses
        run["stopped_by"] = exc


def _land(rig, run, dt_s) -> bool:
    """The pilot's switch down and throttle low until the firmware reports disarmed, then
    :data:`SAVE_WAIT_S` more (its pending parameter save); whether it disarmed."""
    rc, armed, after = rc_disarmed(), True, 0
    for _ in range(int(round((DISARM_WAIT_S + SAVE_WAIT_S) / dt_s))):
        run["frames"] += 1
        armed = _step(rig, rc).armed
        after = 0 if armed else after + 1
        if after * dt_s >= SAVE_WAIT_S:
            return True
    return not armed


def _step(rig, rc):
    """One lockstep frame with the pilot's ``rc`` (one row of channels, us): its reply."""
    return rig.advance(1, np.asarray(rc, dtype=np.uint16).reshape(1, -1))
