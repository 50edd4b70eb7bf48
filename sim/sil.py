"""One sine experiment with the firmware in the loop (``heliquad sil``).

The simulator plays the rig and the pilot: it drives the host firmware in lockstep with the
transfer-function plant and the MPU6050 FIFO packets, gives RC (throttle low, arm switch up,
then hover throttle), and, as the host tool, starts the excitation over the telemetry link
with the same code a real board gets. Every telemetry packet goes to ``RUN.tlog`` stamped with
simulated time; the full-amplitude cycles go to ``RUN.csv`` (``t_s,u,y``) for ``heliquad fsf``.

Input and output follow the injection point (HQ_INJECTION in the dialect):
mixer -> u = the axis's total torque command, y = measured rate (the fit gives the plant);
rate -> u = rate setpoint, y = measured rate (closed inner loop);
angle -> u = angle setpoint, y = angle (closed cascade).
"""

from __future__ import annotations

import dataclasses
import math
import os
import select
import time

import numpy as np

from heliquad.host.link import HEARTBEAT_PERIOD_S, INPUT_OUTPUT, SESSION_MESSAGES, reason_text
from .dialect import dialect

from .faults import check_faults, imu_fault_codes, link_close_frame
from .lockstep import FirmwareError, SimLink, actuators, start_firmware
from .tf_plant import TfPlant

__all__ = ["SilConfig", "SilResult", "run_sil", "RC_CENTER_US"]

RC_CENTER_US, RC_LOW_US, RC_HIGH_US = 1500, 1000, 2000
#: Frames with everything low after start (the firmware initialises), then arm switch up.
BOOT_FRAMES, ARM_FRAMES = 20, 20
#: Frames recorded after the excitation ends.
TAIL_FRAMES = 10
#: Frames per batch of the engine: a tool sees the telemetry (and a sweep checks its safety
#: limits) this often, 250 ms of simulated time at 200 Hz. Larger batches run faster.
TELEMETRY_BATCH = 50
#: How long to wait for a loop's telemetry (its HQ_SYSID_SAMPLE) after its reply.
TELEMETRY_TIMEOUT_S = 2.0
#: While a batch runs, the telemetry link is read this often (the firmware buffers 64 KiB).
ENGINE_POLL_S = 0.002


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
    loop_hz: float = 200.0
    collective: float = 0.4        # hover throttle, fraction of full stick travel
    settle_s: float = 1.0          # hover before the excitation starts
    dmp_image: str | None = None
    plant: str = "tf"              # "tf" (num/den) or "vehicle" (the 6-DoF model)
    rig: str = "roll"              # vehicle plant: roll, pitch, yaw or free
    params: str | None = None      # vehicle parameter file (default: the shipped one)
    turbulence: str | None = None  # vehicle plant: light, moderate or severe Dryden turbulence
    seed: int = 0                  # turbulence and sensor-noise seed
    ideal_sensor: bool = False     # vehicle plant: no IMU noise, bias or DMP latency
    faults: tuple = ()             # sim.faults.Fault: what goes wrong, and when
    firmware: str = "host"         # "host" (the host build) or "teensy35" (the image, emulated)
    firmware_image: str | None = None  # teensy35: the .elf (default: the installed image)


def make_plant(cfg: SilConfig, dt_s: float):
    """The plant of a run: the per-axis transfer function or the 6-DoF vehicle on its rig."""
    if cfg.plant == "tf":
        return TfPlant(cfg.axis, cfg.num, cfg.den, dt_s)
    from .params import load_params
    from .vehicle_plant import VehiclePlant

    return VehiclePlant(cfg.axis, cfg.rig, dt_s, load_params(cfg.params),
                        trim_collective=cfg.collective, turbulence=cfg.turbulence, seed=cfg.seed,
                        ideal_sensor=cfg.ideal_sensor)


@dataclasses.dataclass
class SilResult:
    tlog_path: str
    csv_path: str
    samples: int                   # full-amplitude samples written to the CSV
    frames: int
    seq_gaps: int                  # HQ_SYSID_SAMPLE sequence gaps (dropped telemetry)
    actual_freq_hz: float
    saturated_samples: int         # measured samples whose torque the mixer could not meet
    imu_mode: str
    wall_s: float                  # the whole run, firmware start-up included
    loop_s: float                  # the lockstep loop alone
    truth: complex                 # sampled-data truth at the actual frequency (mixer injection)
    stopped: str | None = None     # why the firmware ended the excitation early, if it did
    firmware_summary: str = ""     # the firmware's own last word: counters, loop figures


def _rc(frame, collective):
    rc = [RC_CENTER_US, RC_CENTER_US, RC_LOW_US, RC_CENTER_US, RC_LOW_US, RC_CENTER_US, 0, 0]
    if frame > BOOT_FRAMES:
        rc[4] = RC_HIGH_US                                     # arm switch
    if frame > BOOT_FRAMES + ARM_FRAMES:
        rc[2] = int(round(RC_LOW_US + collective * (RC_HIGH_US - RC_LOW_US)))
    return rc


def rig_step(link, plant, frame, time_us, kind, collective, imu_fault=0):
    """One lockstep frame of the simulated rig, driven from Python (the free-running board
    and tests): the plant's FIFO bytes and the pilot's RC out, the firmware's reply in, the
    plant stepped with the reply's motors. :class:`SilSession` runs batches of the same in C++."""
    reply = link.step(time_us, plant.fifo(kind), kind, _rc(frame, collective), imu_fault=imu_fault)
    plant.step_motors(reply.motor)
    return reply


class _TelemetryLog:
    """Reads the telemetry link and logs every packet with the simulated time of its loop:
    each loop's telemetry ends with its HQ_SYSID_SAMPLE, so every packet is stamped with the
    time_us of the first HQ_SYSID_SAMPLE at or after it in the stream. Repeatable, without a
    read per frame. Framing and logging are C++ (``_simcore.TelemetryTap``); the messages of
    interest are decoded here with the host tool's codec.

    The tap has its own descriptor on the link, as a wire tap would: when the host tool
    closes its end (the ``link`` fault), what the firmware sends is still logged."""

    def __init__(self, tel, tlog_path: str):
        from heliquad import _simcore

        self.codec = tel.codec
        self.ids = {name: tel.ids[name] for name in SESSION_MESSAGES}
        from heliquad.host.tlog import create_log

        self.fd = os.open(tel.serial.port, os.O_RDONLY | os.O_NOCTTY | os.O_NONBLOCK)
        try:
            self._file = create_log(tlog_path)
        except BaseException:
            os.close(self.fd)
            raise
        self.tap = _simcore.TelemetryTap(self.fd, self._file.fileno(), list(self.ids.values()))

    @property
    def last_time_us(self):
        t = self.tap.last_time_us
        return None if t < 0 else t

    def read(self) -> list:
        """Decoded messages of interest that arrived; every packet logged once its loop
        is known."""
        decode = self.codec.decode
        out = [decode(msgid, payload) for msgid, payload in self.tap.read()]
        if self.tap.write_failed:
            raise OSError(f"cannot write {self._file.name}")
        return out

    def close(self) -> None:
        self._file.close()
        os.close(self.fd)

    def read_until(self, time_us: int) -> list:
        """Read until the loop at ``time_us`` has all its telemetry."""
        out = self.read()
        deadline = time.monotonic() + TELEMETRY_TIMEOUT_S
        while self.last_time_us is None or self.last_time_us < time_us:
            remaining = deadline - time.monotonic()
            if remaining <= 0:
                raise FirmwareError(f"no telemetry for the step at {time_us * 1e-6:.3f} s")
            select.select([self.fd], [], [], remaining)
            out += self.read()
        return out


class _ClosedLink:
    """What is left of the host's telemetry link after the ``link`` fault: commands and
    heartbeats go nowhere (counted in ``lost``); the codec still decodes what the tap reads."""

    def __init__(self, closed):
        self.codec, self.ids = closed.codec, closed.ids
        self.lost = 0

    def _drop(self, *args, **kwargs) -> None:
        self.lost += 1

    heartbeat = arm = set_mode = start_excitation = stop_excitation = _drop

    def close(self) -> None:
        pass


class SilSession:
    """The firmware in the loop as a session: it boots, arms and hovers the simulated rig,
    and steps it in batches; a tool drives it through ``tel`` (the telemetry link, the same
    code as for a board) and :meth:`advance`. Every telemetry packet is logged to ``tlog``
    with simulated time.

    The frames themselves run in C++ (``heliquad._simcore.RigEngine``, in its own thread):
    the plant, the FIFO packets and the sim link, with the batch's RC inputs and random
    inputs drawn here beforehand. Meanwhile this thread reads and logs the telemetry. Commands
    and heartbeats go out between batches only, so a run is the same every time."""

    def __init__(self, cfg: SilConfig, tlog_path: str):
        from heliquad import _firmware, _simcore
        from heliquad.host.link import TelemetryLink

        self.cfg = cfg
        self.dt_us = int(round(1e6 / cfg.loop_hz))
        check_faults(cfg.faults, self.dt_us)
        self.plant = make_plant(cfg, self.dt_us * 1e-6)
        self.mixer = _firmware.Mixer()                # the firmware's own mixer equations
        image = {"image": cfg.firmware_image} if cfg.firmware_image else {}
        self.fw = start_firmware(cfg.firmware, loop_hz=cfg.loop_hz, dmp_image=cfg.dmp_image,
                                 **image)
        try:
            self.link = SimLink(self.fw)
            self.tel = TelemetryLink(self.fw.telemetry_path)
            self.telemetry = _TelemetryLog(self.tel, tlog_path)
        except BaseException:
            self.fw.stop()
            raise
        self.engine = _simcore.RigEngine(self.link.port, self.plant.core)
        # The tool's heartbeat, on exact frames so that runs repeat.
        self.heartbeat_frames = max(1, int(round(HEARTBEAT_PERIOD_S * cfg.loop_hz)))
        self.link_close_frame = link_close_frame(cfg.faults, self.dt_us)
        self.frame, self.kind, self.reply = 0, 0, None
        self.t0 = time.monotonic()

    @property
    def time_us(self) -> int:
        return self.frame * self.dt_us

    def advance(self, frames: int = TELEMETRY_BATCH, handle=None) -> list:
        """Step ``frames`` lockstep frames; the messages of interest from their telemetry.

        With ``handle``, each message is passed to it as it arrives, while the engine runs
        the next frames (and the list returned is empty): work done there is off the
        lockstep's critical path. It must not write to the telemetry link."""
        end, out = self.frame + frames, []

        def collect(messages):
            if handle is None:
                out.extend(messages)
                return
            for m in messages:
                handle(m)

        while self.frame < end:
            first = self.frame + 1
            if first == self.link_close_frame:
                self.close_host_link()
            if first % self.heartbeat_frames == 0:
                self.tel.heartbeat()
            # A batch ends before the next heartbeat and before the link fault's frame, so
            # both happen at exact frames.
            last = min(end, (first // self.heartbeat_frames + 1) * self.heartbeat_frames - 1)
            if self.link_close_frame is not None and first < self.link_close_frame:
                last = min(last, self.link_close_frame - 1)
            self._run(first, last - first + 1, collect)
        collect(self.telemetry.read_until(self.time_us))
        return out

    def close_host_link(self) -> None:
        """The host tool closes its end of the telemetry link (the ``link`` fault): from now
        on nothing it sends reaches the firmware. The tap keeps logging what arrives."""
        if isinstance(self.tel, _ClosedLink):
            return
        self.tel.close()
        self.tel = _ClosedLink(self.tel)

    def _run(self, first: int, n: int, collect) -> None:
        """Frames first .. first + n - 1 in the engine; telemetry read while they run."""
        rc = np.array([_rc(f, self.cfg.collective) for f in range(first, first + n)],
                      dtype=np.uint16)
        noise, gust = self.plant.frame_inputs(n)
        faults = imu_fault_codes(self.cfg.faults, first, n, self.dt_us)
        self.engine.start(first, n, self.dt_us, self.kind, rc, noise, gust, faults)
        try:
            # Read at a fixed pace rather than on every arrival: one wake-up per few frames
            # leaves the cores to the engine and the firmware.
            while not self.engine.wait_finished(ENGINE_POLL_S):
                collect(self.telemetry.read())
        finally:
            if not self.engine.finished():           # Ctrl-C or an error here: stop it
                self.engine.cancel()
            result = self.engine.wait()
        self.frame = first + result.frames_done - 1
        if result.frames_done:
            self.reply = actuators(result.last)
            self.kind = self.reply.sensor_kind
        self.link.check(result.status, result.failed_frame, result.last)

    def hover(self) -> None:
        """Boot, arm and hover for the settling time."""
        self.advance(BOOT_FRAMES + ARM_FRAMES + int(round(self.cfg.settle_s * self.cfg.loop_hz)))

    def close(self) -> None:
        try:
            self.tel.close()
            self.link.close()
        finally:
            self.telemetry.close()
            self.fw.stop()

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()


class _Tally:
    """What one experiment keeps of the telemetry, message by message (called while the
    engine runs the next frames, see :meth:`SilSession.advance`)."""

    def __init__(self, cfg: SilConfig, mixer, dt_us: int, progress):
        self.axis_index = ("roll", "pitch", "yaw").index(cfg.axis)
        self.u_name, self.y_name = INPUT_OUTPUT[cfg.inject]
        self.mixer, self.dt_us, self.progress = mixer, dt_us, progress
        self.rows, self.saturated, self.gaps = [], 0, 0
        self.last_seq, self.exc_seen, self.exc_done_frame, self.status = None, False, None, None
        self.stopped = None
        mav = dialect()
        self.idle, self.running = mav.HQ_EXCITATION_STATE_IDLE, mav.HQ_EXCITATION_STATE_RUNNING
        self.finished = mav.HQ_REASON_FINISHED

    def __call__(self, m) -> None:
        t = m.get_type()
        if t == "HQ_SYSID_SAMPLE":
            self._sample(m)
        elif t == "HQ_EXCITATION_STATUS":
            self._status(m)
        elif t == "STATUSTEXT" and m.severity <= 4:
            self.progress(f"firmware: {m.text}")

    def _status(self, m) -> None:
        if self.status is None:                   # the answer to the start command
            self.status = m
            if not m.accepted:
                raise FirmwareError(f"the firmware refused the excitation: {reason_text(m.reason)}")
        elif m.state == self.idle and m.reason != self.finished and self.stopped is None:
            self.stopped = f"the firmware stopped the excitation: {reason_text(m.reason)}"

    def _sample(self, m) -> None:
        if self.last_seq is not None and m.seq != self.last_seq + 1:
            self.gaps += m.seq - self.last_seq - 1
        self.last_seq = m.seq
        if m.exc_state != self.idle:
            self.exc_seen = True
        elif self.exc_seen and self.exc_done_frame is None:
            self.exc_done_frame = m.time_us // self.dt_us
        if m.exc_state == self.running:
            self.rows.append((m.time_us * 1e-6, getattr(m, self.u_name), getattr(m, self.y_name)))
            got = self.mixer.achieved(m.motor)
            if abs((got.roll, got.pitch, got.yaw)[self.axis_index] - m.axis_cmd) > 1e-3:
                self.saturated += 1


def run_sil(cfg: SilConfig, out_base: str, progress=print) -> SilResult:
    """Run the experiment; writes ``out_base.tlog`` and ``out_base.csv``, never over files
    that exist (InputError before anything starts)."""
    from .errors import InputError

    csv_path = out_base + ".csv"
    for path in (out_base + ".tlog", csv_path):
        if os.path.lexists(path):
            raise InputError(f"{path} exists: heliquad never writes over a run's records; give "
                             "another --out (or move the old files away)")
    t0 = time.monotonic()
    with SilSession(cfg, out_base + ".tlog") as session:
        tally = _Tally(cfg, session.mixer, session.dt_us, progress)
        loop_t0 = time.monotonic()                 # the lockstep loop, hover included
        session.hover()
        start_frame = session.frame
        max_frames = start_frame + int(cfg.loop_hz / cfg.freq_hz *
                                       (cfg.cycles + 2 * cfg.fade_cycles + 2)) + 400
        session.tel.start_excitation(cfg.axis, cfg.inject, cfg.freq_hz, cfg.amplitude,
                                     cfg.cycles, cfg.fade_cycles)
        next_report = 0.1
        while True:
            session.advance(handle=tally)
            frame = session.frame
            if tally.exc_done_frame is not None and frame >= tally.exc_done_frame + TAIL_FRAMES:
                break
            if frame >= max_frames:
                if tally.status is None:
                    raise FirmwareError("the firmware never answered the excitation request"
                                        + (" (the host link was closed)"
                                           if session.link_close_frame is not None else ""))
                raise FirmwareError(f"the excitation did not finish within {frame} frames")
            if (frame - start_frame) / (max_frames - start_frame) >= next_report:
                progress(f"  {100 * frame / max_frames:3.0f} %  t = {session.time_us * 1e-6:6.2f} s")
                next_report += 0.1
        loop_s = time.monotonic() - loop_t0
        plant, imu_mode = session.plant, session.fw.imu_mode
    summary = session.fw.summary
    with open(csv_path, "x") as fh:
        np.savetxt(fh, np.array(tally.rows).reshape(-1, 3), delimiter=",", header="t_s,u,y",
                   comments="", fmt="%.9g")
    status = tally.status
    freq = float(status.freq_hz) if status is not None else float("nan")
    return SilResult(tlog_path=out_base + ".tlog", csv_path=csv_path, samples=len(tally.rows),
                     frames=frame, seq_gaps=tally.gaps, actual_freq_hz=freq,
                     saturated_samples=tally.saturated, imu_mode=imu_mode,
                     wall_s=time.monotonic() - t0, loop_s=loop_s,
                     truth=complex(plant.truth(2 * math.pi * freq)) if math.isfinite(freq) else complex("nan"),
                     stopped=tally.stopped, firmware_summary=summary)
