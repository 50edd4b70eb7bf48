"""The firmware processes and the sim link of the lockstep (docs/link-contract.md).

:class:`HostFirmware` starts ``heliquad-fw-host``, which creates the sim-link and telemetry
ptys (:class:`PilFirmware` starts the Teensy image in the emulated chip instead, the same
link contract: ``heliquad.sim.chip.pil``; :func:`start_firmware` picks one by name);
:class:`SimLink` then exchanges frames on the sim link: one HQ_SENSOR_FRAME out, exactly one
HQ_ACTUATOR_FRAME back with the same time and counter. A reply that does not come within
the timeout, a wrong counter, or a firmware that died are errors with a clear message, never
a hang. The lockstep driver that puts them together with a plant is
:class:`heliquad.sim.rig.driver.Rig`.
"""

from __future__ import annotations

import dataclasses
import hashlib
import os
import selectors
import shutil
import signal
import subprocess
import sys
import sysconfig
import tempfile
import time

import serial

from heliquad import _simcore
from heliquad._simcore import LinkStatus

from ..base.dialect import dialect
from ..base.errors import FirmwareError, InputError
from ..base.firmware_facts import LOOP_RATE_HZ
from ..base.firmware_image import teensy35_image
from .setup import DEFAULT_BOARD_LINK

__all__ = ["FirmwareError", "HostFirmware", "PilFirmware", "SimLink", "Actuators", "actuators",
           "find_firmware", "start_firmware", "FIRMWARES"]

#: How long the firmware may take to create its ptys and print "ready".
START_TIMEOUT_S = 10.0
#: How long one frame's reply may take before the link is declared dead.
REPLY_TIMEOUT_S = 2.0


#: The firmwares that can fly the simulated rig: the host build, and the Teensy 3.5 image in
#: the emulated MK64FX512 (processor in the loop).
FIRMWARES = ("host", "teensy35")


def find_firmware() -> str:
    """Path of the host firmware executable (installed next to the ``heliquad`` script)."""
    env = os.environ.get("HELIQUAD_FW_HOST")
    candidates = [env] if env else []
    candidates.append(os.path.join(sysconfig.get_path("scripts"), "heliquad-fw-host"))
    candidates.append(shutil.which("heliquad-fw-host") or "")
    for path in candidates:
        if path and os.path.isfile(path) and os.access(path, os.X_OK):
            return path
    raise FirmwareError("heliquad-fw-host not found; reinstall heliquad (pip install .) "
                        "or set HELIQUAD_FW_HOST")


class HostFirmware:
    """The host firmware as a child process with its two ptys in a private directory."""

    name = "host"
    #: How long the firmware may take to create its ptys and print "ready".
    start_timeout_s = START_TIMEOUT_S
    #: How long one frame's reply may take before the link is declared dead.
    reply_timeout_s = REPLY_TIMEOUT_S

    def __init__(self, loop_hz: float = LOOP_RATE_HZ, dmp_image: str | None = None,
                 idle_timeout_s: int = 10, telemetry_path: str | None = None,
                 reply_timeout_s: float | None = None, params_file: str | None = None,
                 telemetry_backlog_bytes: int = 0, sd_image: str | None = None,
                 sd_faults: str | None = None):
        """``params_file``: where the firmware keeps its parameters across runs (``--params``;
        the host build's record, the emulated Teensy's two flash sectors); default none.
        ``telemetry_backlog_bytes``: the most telemetry that waits for a reader, the oldest
        dropped past it (0: unbounded, the lockstep simulator reads all; docs/link-contract.md).
        ``sd_image``: the card-image file in the board's SD socket, where it logs each arming
        and whose logs it serves (``--sd-image``; a missing file is made at the default size
        first; docs/sd-card.md); default no card. ``sd_faults``: the host build's card faults,
        ``NAME=VALUE,...`` (``--sd-faults``; the host build only)."""
        self.loop_hz = loop_hz
        if reply_timeout_s is not None:
            self.reply_timeout_s = reply_timeout_s
        cmd = self.command()
        self.proc, self._stderr, self._links = None, None, {}
        self.summary = ""
        self.startup_lines = []           # what it printed up to "ready"
        self._tmp = tempfile.TemporaryDirectory(prefix="heliquad-sil-")
        try:
            self.workdir = self._tmp.name
            self.sim_link_path = os.path.join(self.workdir, "sim-link")
            self.telemetry_path = telemetry_path or os.path.join(self.workdir, "telemetry")
            cmd += ["--sim-link", self.sim_link_path, "--telemetry", self.telemetry_path,
                    "--loop-hz", repr(float(loop_hz)), "--idle-timeout-s", str(int(idle_timeout_s))]
            if dmp_image:
                cmd += ["--dmp-image", dmp_image]
            if params_file:                   # where the parameters persist (default: nowhere)
                # and, beside them in its own file, the on-board program (PARAMS.program)
                cmd += ["--params", os.path.abspath(params_file),
                        "--program", os.path.abspath(params_file) + ".program"]
            if telemetry_backlog_bytes:
                cmd += ["--telemetry-backlog-bytes", str(int(telemetry_backlog_bytes))]
            if sd_image:                      # the card: its logs written and served
                cmd += ["--sd-image", os.path.abspath(sd_image)]
            if sd_faults:
                cmd += self.card_fault_options(sd_faults)
            self.stderr_path = os.path.join(self.workdir, "firmware.stderr")
            self._stderr = open(self.stderr_path, "w+")
            # Its own session: a terminal's Ctrl-C goes to the tool's process group only, and
            # the tool ends the run in order (stops the excitation, keeps the records, then
            # stops the firmware) instead of losing the firmware under it.
            self.proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=self._stderr,
                                         start_new_session=True)
            self.imu_mode = self._wait_ready()
        except BaseException:
            # Whatever stops the start (the firmware's own failure, Ctrl-C, SIGTERM): no
            # process or folder is left behind.
            self.stop()
            raise

    def command(self) -> list:
        """The firmware's command line, before the link options."""
        self.executable = find_firmware()
        return [self.executable]

    def card_fault_options(self, sd_faults: str) -> list:
        """The command line's options for the card's faults."""
        return ["--sd-faults", sd_faults]

    def record(self) -> dict:
        """What flew, for a manifest."""
        return {"name": self.name, "executable": self.executable}

    def _wait_ready(self) -> str:
        """Read the firmware's start-up lines (raw reads: a buffered reader would hide data
        from select) until "ready", the process exits, or the timeout passes."""
        fd = self.proc.stdout.fileno()
        sel = selectors.DefaultSelector()
        sel.register(fd, selectors.EVENT_READ)
        deadline = time.monotonic() + self.start_timeout_s
        text = ""
        while time.monotonic() < deadline:
            if sel.select(timeout=0.1):
                chunk = os.read(fd, 4096).decode(errors="replace")
                if not chunk:
                    break
                text += chunk
                lines = text.splitlines()
                if "ready" in (line.strip() for line in lines):
                    self.startup_lines = [line.strip() for line in lines]
                    # Where its links point, to remove them if it dies without doing so.
                    self._links = {path: os.readlink(path)
                                   for path in (self.sim_link_path, self.telemetry_path)
                                   if os.path.islink(path)}
                    imu = [line.split(":", 1)[1].strip() for line in lines if line.startswith("imu:")]
                    return imu[0] if imu else "?"
            elif self.proc.poll() is not None:
                break
        self.wait_exit(1.0)                 # it closed its output: let its exit status arrive
        message = self.stderr_tail()
        self.stop()
        raise FirmwareError(f"the {self.name} firmware did not start: {message}")

    def _stderr_lines(self, lines: int) -> list:
        """The last lines the firmware wrote on stderr."""
        try:
            with open(self.stderr_path) as fh:
                return fh.read().strip().splitlines()[-lines:]
        except OSError:
            return []

    def stderr_tail(self, lines: int = 3) -> str:
        """The last lines the firmware wrote on stderr, and its exit status."""
        tail = self._stderr_lines(lines)
        code = self.proc.poll()
        status = f"exit code {code}" if code is not None else "still running"
        return f"{status}; " + (" | ".join(tail) if tail else "no message")

    def alive(self) -> bool:
        return self.proc.poll() is None

    def wait_exit(self, timeout_s: float) -> None:
        """Give the process up to ``timeout_s`` to finish exiting (no error if it does not)."""
        try:
            self.proc.wait(timeout_s)
        except subprocess.TimeoutExpired:
            pass

    def stop(self, timeout_s: float = 3.0) -> int | None:
        """Ask the firmware to exit (SIGTERM), then kill it (its whole process group) if it
        does not; remove the links it left (a killed firmware cannot remove its own) and the
        temporary folder. Safe to call again, and it finishes even when a Ctrl-C or SIGTERM
        interrupts the wait."""
        proc = self.proc
        try:
            if proc is not None and proc.poll() is None:
                proc.terminate()
                proc.wait(timeout_s)
        except subprocess.TimeoutExpired:
            pass
        finally:
            if proc is not None and proc.poll() is None:
                try:
                    os.killpg(proc.pid, signal.SIGKILL)    # its session leader: pgid = pid
                except ProcessLookupError:
                    pass
                proc.wait()
            self._release()
        return proc.returncode if proc is not None else None

    def _release(self) -> None:
        """What a stopped firmware leaves: its output pipe, its stderr file (its last line
        kept as :attr:`summary`), its links and the temporary folder."""
        if self.proc is not None and self.proc.stdout:
            self.proc.stdout.close()
        if self._stderr is not None and not self._stderr.closed:
            # The firmware's last line: its counters (and, emulated, its loop figures).
            self.summary = "".join(self._stderr_lines(1))
            self._stderr.close()
        for path, target in self._links.items():
            try:
                if os.readlink(path) == target:      # still the firmware's, not a newer one
                    os.unlink(path)
            except OSError:
                pass                                 # removed already (the firmware did)
        self._links = {}
        if self._tmp is not None:
            self._tmp.cleanup()
            self._tmp = None

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.stop()


class PilFirmware(HostFirmware):
    """The Teensy 3.5 image in the emulated MK64FX512 (``python -m heliquad.sim.chip.pil``):
    the same ptys and frames as the host build, the image as flashed to the board inside.
    ``image``: the .elf (default: the installed one). ``link``: the board's link the ptys
    carry, ``uart`` (UART0) or ``usb`` (its USB port). ``params_file``: keep the board's
    parameter flash in that file across runs (``--params``; the file holds the two flash
    sectors, docs/processor-in-the-loop.md). The emulated chip runs slower than the
    host build, and one loop may hold the bus for an IMU re-initialisation, so its start-up
    and reply timeouts are longer; each loop is also bounded in emulated time inside."""

    name = "teensy35"
    start_timeout_s = 120.0
    reply_timeout_s = 60.0

    def __init__(self, *args, image: str | None = None, link: str = DEFAULT_BOARD_LINK,
                 **kwargs):
        self.image = image
        self.link = link
        super().__init__(*args, **kwargs)

    def command(self) -> list:
        self.image = os.path.abspath(self.image or str(teensy35_image("elf")))
        return [sys.executable, "-m", "heliquad.sim.chip.pil", "--image", self.image,
                "--link", self.link]

    def card_fault_options(self, sd_faults: str) -> list:
        raise FirmwareError("--sd-faults: only the host build's card takes faults (the "
                            "emulated card's are set on sim/chip/sd_card.py's SdCard)")

    def record(self) -> dict:
        with open(self.image, "rb") as fh:
            digest = hashlib.sha256(fh.read()).hexdigest()
        return {"name": self.name, "image": self.image, "image_sha256": digest,
                "link": self.link}


def start_firmware(firmware: str = "host", **kwargs) -> HostFirmware:
    """Start the named firmware (one of FIRMWARES) with HostFirmware's arguments."""
    if firmware == "host":
        return HostFirmware(**kwargs)
    if firmware == "teensy35":
        return PilFirmware(**kwargs)
    raise FirmwareError(f"unknown firmware {firmware!r}: one of {', '.join(FIRMWARES)}")


@dataclasses.dataclass
class Actuators:
    """One HQ_ACTUATOR_FRAME: ``motor`` the thrust fractions of the rotors the firmware flies
    (its ``motor[:motor_count]``)."""

    time_us: int
    frame: int
    motor: list
    armed: bool
    mode: int
    sensor_kind: int


class SimLink:
    """The simulator's end of the sim link: send a sensor frame, get exactly one reply.

    pyserial opens the pty and makes it raw; the exchange itself (MAVLink framing, the
    reply's counter check, the timeout) is C++ (``heliquad._simcore.SimLinkPort``,
    sim/rig/sim_link.cpp), shared with the batch engine of the lockstep driver
    (:class:`heliquad.sim.rig.driver.Rig`).
    """

    def __init__(self, firmware: HostFirmware):
        self.firmware = firmware
        self.timeout_s = firmware.reply_timeout_s
        self.serial = serial.Serial(firmware.sim_link_path, timeout=0, write_timeout=self.timeout_s)
        self.port = _simcore.SimLinkPort(self.serial.fileno(), int(self.timeout_s * 1000))
        self.frame = 0

    def close(self) -> None:
        self.serial.close()

    def step(self, time_us: int, fifo: bytes = b"", fifo_kind: int | None = None,
             rc_us=None, frame: int | None = None, imu_fault: int | None = None) -> Actuators:
        """Send one sensor frame and wait for its actuator frame. ``fifo_kind``: the dialect's
        HQ_SENSOR_KIND of ``fifo`` (default HQ_SENSOR_NONE); ``rc_us``: the RC channels, us
        (default: no signal on any); ``imu_fault``: the dialect's HQ_IMU_FAULT for the emulated
        MPU6050 at this frame (sim/rig/faults.py; default HQ_IMU_FAULT_NONE). A ValueError for more
        FIFO bytes than the frame carries."""
        mav = dialect()
        fifo_kind = mav.HQ_SENSOR_NONE if fifo_kind is None else fifo_kind
        imu_fault = mav.HQ_IMU_FAULT_NONE if imu_fault is None else imu_fault
        rc_us = [0] * _simcore.RC_CHANNELS if rc_us is None else list(rc_us)
        frame = self.frame + 1 if frame is None else frame
        status, reply, errno = self.port.exchange(int(time_us), frame, fifo_kind, bytes(fifo),
                                                  rc_us, imu_fault=int(imu_fault))
        self.check(status, frame, reply, errno)
        self.frame = frame
        return actuators(reply)

    def check(self, status, frame: int, reply=None, errno: int = 0, rotors: int = 0) -> None:
        """Raise the FirmwareError that a link status other than OK means (an InputError for
        a firmware that flies another number of rotors than the plant's ``rotors``)."""
        if status == LinkStatus.OK:
            return
        if status == LinkStatus.ROTOR_COUNT:
            raise InputError(f"the firmware flies {reply.motor_count} rotors but the vehicle has "
                             f"{rotors}: the firmware in the loop needs a vehicle file with its "
                             f"rotor count")
        if status == LinkStatus.WRONG_FRAME:
            raise FirmwareError(f"reply to frame {frame} carries frame {reply.frame}")
        if status == LinkStatus.CANCELLED:
            raise FirmwareError(f"stopped before frame {frame}")
        self.firmware.wait_exit(0.5)          # a dying process may need a moment to be reaped
        alive = self.firmware.alive()
        if status == LinkStatus.WRITE_FAILED:
            state = "stopped reading" if alive else "died"
            raise FirmwareError(f"the firmware {state} at frame {frame} (sim link write failed: "
                                f"{os.strerror(errno)}; {self.firmware.stderr_tail()})")
        why = f"did not answer within {self.timeout_s:g} s" if alive else "died"
        raise FirmwareError(f"the firmware {why} at frame {frame} ({self.firmware.stderr_tail()})")


def actuators(reply) -> Actuators:
    """An :class:`Actuators` from the C++ link's reply."""
    return Actuators(reply.time_us, reply.frame, list(reply.motor), bool(reply.armed),
                     reply.mode, reply.sensor_kind)
