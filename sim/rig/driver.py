"""The lockstep driver: the firmware, the plant and the link between them, as one thing.

:class:`Rig` starts a firmware (one of :data:`~heliquad.sim.rig.lockstep.FIRMWARES`: the
host build, or the Teensy image in the emulated chip behind the same link contract,
docs/link-contract.md), opens the sim link to it and hands the link and the plant to the
C++ batch engine (``heliquad._simcore.RigEngine``), which runs the frames in its own thread:
the plant's FIFO bytes out, exactly one reply back, the plant stepped with the reply's
motors. :meth:`Rig.advance` runs ``n`` frames with the batch's RC, the plant's random inputs
(sensor noise, gusts, drawn in Python beforehand so that a run repeats) and the injected IMU
faults of those frames. The firmware's telemetry link is left to the caller
(:attr:`Rig.telemetry_path`).

What drives it: the SIL session of the host tool (:class:`heliquad.host.acquire.session.
SilSession`: batches, its telemetry read while each runs) and the free-running board
(:mod:`heliquad.sim.rig.board`: one frame at a time, paced to real time).
"""

from __future__ import annotations

import contextlib
from typing import Callable

from heliquad import _simcore

from ..base.closing import Closing
from ..base.dialect import dialect
from ..base.firmware_facts import LOOP_RATE_HZ
from .faults import check_faults, imu_fault_codes
from .lockstep import Actuators, SimLink, actuators, start_firmware

__all__ = ["Rig", "frame_period_us", "ENGINE_POLL_S"]

#: While a batch runs, how often the caller's ``while_running`` is called (the firmware
#: buffers 64 KiB of telemetry, so its reader may wait this long).
ENGINE_POLL_S = 0.002


def frame_period_us(loop_hz: float) -> int:
    """One lockstep frame, whole microseconds: the firmware's loop period."""
    return int(round(1e6 / loop_hz))


class Rig(Closing):
    """A firmware flying a plant in lockstep. Started by the constructor, in this order: the
    faults checked, the plant made (``make_plant(dt_s)``, with the frame period), the
    firmware started, the sim link and the engine (a failure or Ctrl-C on the way stops what
    started); stopped by :meth:`close`.

    ``faults``: the run's injected faults (:mod:`heliquad.sim.rig.faults`), checked before
    the firmware starts; the IMU ones reach the firmware with their frames. The other
    keywords are the firmware's (:class:`~heliquad.sim.rig.lockstep.HostFirmware`:
    ``dmp_image``, ``params_file``, ``telemetry_path``, ``telemetry_backlog_bytes``,
    ``sd_image``, ``sd_faults``, ``image`` for the Teensy image)."""

    def __init__(self, make_plant: Callable[[float], object], firmware: str = "host",
                 loop_hz: float = LOOP_RATE_HZ, faults=(), **firmware_options):
        self.dt_us = frame_period_us(loop_hz)
        self.faults = tuple(faults)
        check_faults(self.faults, self.dt_us)
        self.plant = make_plant(self.dt_us * 1e-6)
        self.fw = start_firmware(firmware, loop_hz=loop_hz, **firmware_options)
        with contextlib.ExitStack() as undo:       # a failure or Ctrl-C here stops it all
            undo.callback(self.fw.stop)
            self.link = SimLink(self.fw)
            undo.callback(self.link.close)
            self.engine = _simcore.RigEngine(self.link.port, self.plant.core)
            undo.pop_all()
        #: The last frame run, the sensor kind the firmware last asked for, its last reply.
        self.frame, self.kind, self.reply = 0, dialect().HQ_SENSOR_NONE, None

    @property
    def telemetry_path(self) -> str:
        """Where the firmware's telemetry link is (a pty's symlink)."""
        return self.fw.telemetry_path

    @property
    def time_us(self) -> int:
        """The simulated time of the last frame run."""
        return self.frame * self.dt_us

    def advance(self, n: int, rc, while_running: Callable[[], None] | None = None,
                poll_s: float = ENGINE_POLL_S) -> Actuators | None:
        """Run the next ``n`` frames with the pilot's ``rc`` (n rows of the RC channels, us)
        and return the last reply. ``while_running`` is called every ``poll_s`` while the
        engine runs them (off the lockstep's critical path); if it raises, the batch is
        cancelled and the error goes on. A link that fails (no reply, a wrong one, a dead
        firmware) is a FirmwareError, :attr:`frame` then the last frame answered."""
        if self.engine.running():
            # A signal that landed as the last batch ended (between its end and the wait for
            # it) left it to this call: stop it and count it first.
            self._end_batch()
        first = self.frame + 1
        noise, gust = self.plant.frame_inputs(n)
        faults = imu_fault_codes(self.faults, first, n, self.dt_us)
        self.engine.start(first, n, self.dt_us, self.kind, rc, noise, gust, faults)
        try:
            # Called at a fixed pace rather than on every arrival: one wake-up per few frames
            # leaves the cores to the engine and the firmware.
            while not self.engine.wait_finished(poll_s):
                if while_running is not None:
                    while_running()
        finally:
            result = self._end_batch()               # Ctrl-C or an error here: stopped
        self.link.check(result.status, result.failed_frame, result.last,
                        rotors=self.plant.core.rotors)
        return self.reply

    def _end_batch(self):
        """Stop the running batch if it has not finished, wait for it and count the frames
        the firmware answered, even of a batch stopped early: the next one goes on from
        them (the firmware takes a repeated counter as a resend). Its result."""
        if not self.engine.finished():
            self.engine.cancel()
        result = self.engine.wait()
        self.frame += result.frames_done
        if result.frames_done:
            self.reply = actuators(result.last)
            self.kind = self.reply.sensor_kind
        return result

    def firmware_died(self) -> bool:
        """Whether the firmware has exited (given a moment to be reaped)."""
        self.fw.wait_exit(0.5)
        return not self.fw.alive()

    def close(self) -> None:
        """Close the sim link and stop the firmware, each even when the one before fails
        (the firmware last, so that it is never left running)."""
        with contextlib.ExitStack() as stack:
            stack.callback(self.fw.stop)
            stack.callback(self.link.close)
