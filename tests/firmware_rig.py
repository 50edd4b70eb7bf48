"""A test bench for the firmware: the real ``heliquad-fw-host`` (or the Teensy image in the
emulated chip, tests/firmwares.py) on a transfer-function plant, stepped one frame at a time from Python through the link contract, with the pilot's
RC, IMU faults, and the host tool's telemetry link (not a test module: a helper the tests
import).

Commands on the telemetry link reach the firmware asynchronously (a pty), so a test that
needs one to have acted steps until its answer is in the telemetry (:meth:`FirmwareRig.ping`,
:meth:`FirmwareRig.until`): what is checked is firmware time, never wall time.
"""

from __future__ import annotations

import select
import time

from heliquad.host.acquire.link import TelemetryLink
from heliquad.sim.base.dialect import dialect
from heliquad.sim.plant.tf_plant import TfPlant
from heliquad.sim.rig.lockstep import HostFirmware, SimLink

MAV = dialect()
ROLL = ((28.19,), (1.0, 5.13, 22.93))
DT_US = 5000
#: RC at rest: sticks centred, throttle low, arm switch low, mode switch angle.
RC_REST = (1500, 1500, 1000, 1500, 1000, 1000, 0, 0)
ARM_HIGH, THROTTLE_HOVER = 2000, 1400
#: How long a test may wait for telemetry that is due (a bound on a hang, never a check).
WAIT_S = 5.0


class FirmwareRig:
    """A firmware flying a roll transfer-function plant, frame by frame."""

    def __init__(self, fw: HostFirmware, plant=None):
        self.fw = fw
        self.link = SimLink(fw)
        self.tel = TelemetryLink(fw.telemetry_path)
        self.plant = plant or TfPlant("roll", *ROLL, DT_US * 1e-6)
        self.rc = list(RC_REST)
        self.frame, self.kind, self.reply = 0, MAV.HQ_SENSOR_NONE, None
        self.messages = []              # every decoded telemetry message, in order
        self.samples = 0                # HQ_SYSID_SAMPLEs read: one per loop
        self.time_of = []               # the loop time of each (its HQ_SYSID_SAMPLE's)
        self._pending = []

    def close(self) -> None:
        self.tel.close()
        self.link.close()

    @property
    def time_us(self) -> int:
        return self.frame * DT_US

    def step(self, n: int = 1, imu_fault: int = MAV.HQ_IMU_FAULT_NONE):
        """Run n frames; the last reply. Telemetry is read as it comes."""
        for _ in range(n):
            self.frame += 1
            self.reply = self.link.step(self.time_us, self.plant.fifo(self.kind), self.kind,
                                        self.rc, imu_fault=imu_fault)
            self.kind = self.reply.sensor_kind
            self.plant.step_motors(self.reply.motor)
            self._read(wait=False)
        return self.reply

    def _read(self, wait: bool) -> int:
        """Decode what the link has (waiting up to 50 ms for it with ``wait``); how many
        bytes came."""
        fd = self.tel.fileno()
        if wait:
            select.select([fd], [], [], 0.05)
        before = self.tel.bytes_in
        packets = self.tel.read_packets()
        for msgid, _, payload in packets:
            m = self.tel.codec.decode(msgid, payload)
            self._pending.append(m)
            if m.get_type() == "HQ_SYSID_SAMPLE":
                self.samples += 1
                self.messages.extend(self._pending)
                self.time_of.extend([m.time_us] * len(self._pending))
                self._pending = []
        return self.tel.bytes_in - before

    def settle_telemetry(self) -> None:
        """Wait until every loop stepped so far has all its telemetry read."""
        # Every loop ends its telemetry with one HQ_SYSID_SAMPLE: settled when there is one
        # per frame stepped. (Counting, not comparing times: the host build's clock is the
        # simulator's, the Teensy image's starts at its own reset.) The emulated board puts
        # what left its UART on the link before it replies, so everything that will come is
        # already there; only a loop that sent more than its period carries is still partly
        # in the board's queue, and that arrives with later frames.
        if self.fw.name != "host":
            while self._read(wait=False):
                pass
            return
        deadline = time.monotonic() + WAIT_S
        while self.samples < self.frame:
            assert time.monotonic() < deadline, "telemetry stopped"
            self._read(wait=True)

    def last_loop_us(self) -> int:
        """The firmware's time of the last loop stepped (its HQ_SYSID_SAMPLE's time_us)."""
        self.settle_telemetry()
        return self.time_of[-1]

    def of_type(self, name: str, since_us: int = 0):
        """(loop time, message) of every message of one type from loop time since_us on."""
        self.settle_telemetry()
        return [(t, m) for t, m in zip(self.time_of, self.messages)
                if m.get_type() == name and t >= since_us]

    def until(self, predicate, max_frames: int = 400, imu_fault: int = MAV.HQ_IMU_FAULT_NONE):
        """Step until predicate(message) holds for a message of a loop stepped here; that
        (loop time, message). Fails after max_frames."""
        self.settle_telemetry()
        first = len(self.messages)
        for _ in range(max_frames):
            self.step(imu_fault=imu_fault)
            self.settle_telemetry()
            for t, m in zip(self.time_of[first:], self.messages[first:]):
                if predicate(m):
                    return t, m
            first = len(self.messages)
        raise AssertionError(f"not seen within {max_frames} frames")

    def ping(self) -> int:
        """Send the host's HEARTBEAT and step until the firmware has processed it; the loop
        time at which it did (a COMMAND_ACK sent with it marks the loop)."""
        # One write: both arrive together, so the ACK marks the heartbeat's own loop (the
        # firmware answers a command it does not support, a mission waypoint, without acting).
        mav = self.tel.mav
        self.tel.write(
            mav.heartbeat_encode(MAV.MAV_TYPE_GCS, MAV.MAV_AUTOPILOT_INVALID, 0, 0, 0).pack(mav)
            + mav.command_long_encode(1, 1, MAV.MAV_CMD_NAV_WAYPOINT, 0, 0, 0, 0, 0, 0, 0, 0).pack(mav))
        t, _ = self.until(lambda m: m.get_type() == "COMMAND_ACK"
                          and m.command == MAV.MAV_CMD_NAV_WAYPOINT)
        return t

    def hover(self, frames: int = 60):
        """Arm with the RC switch (low, then high, with the throttle low), then hover."""
        self.rc[4] = 1000
        self.step(10)
        self.rc[4] = ARM_HIGH
        self.step(10)
        self.rc[2] = THROTTLE_HOVER
        return self.step(frames)

    def excitation_answer(self, **kwargs):
        """Send HQ_EXCITATION START (a multisine with ``harmonics=[(order, amplitude,
        phase_rad), ...]``) and step until its HQ_EXCITATION_STATUS answer."""
        args = dict(axis="roll", injection="mixer", freq_hz=1.0, amplitude=0.05, cycles=20,
                    fade_cycles=1)
        args.update(kwargs)
        self.tel.start_excitation(args["axis"], args["injection"], args["freq_hz"],
                                  args["amplitude"], args["cycles"], args["fade_cycles"],
                                  args.get("harmonics"))
        return self.until(lambda m: m.get_type() == "HQ_EXCITATION_STATUS")
