"""Sessions: what a sweep drives, on the simulated rig or on a board's port.

A session (the :class:`Session` protocol) gives a tool the telemetry link of a vehicle that
hovers on its rig, and time that advances: the tool starts and stops excitations through
``tel`` (the same :class:`~heliquad.host.acquire.link.TelemetryLink` code for both), and
:meth:`Session.advance` passes it the messages of interest (``SESSION_MESSAGES``) as they
arrive, every one of them logged to the session's .tlog.

* :class:`SilSession`: the firmware in the loop. The simulator (:mod:`heliquad.sim`) plays
  the rig and the pilot in lockstep; time is simulated, so a run is the same every time.
* :class:`PortSession`: a board on a serial port (or a ``heliquad board`` pty), in real
  time; the pilot arms and hovers it.
"""

from __future__ import annotations

import contextlib
import os
import select
import time
from typing import Callable, Protocol

from heliquad import _simcore

from ...sim.base.closing import Closing
from ...sim.base.errors import NO_ROOM, DiskFull, InputError, LinkLost
from ...sim.rig.board import DISARM_WAIT_S, SAVE_WAIT_S
from ...sim.rig.driver import Rig
from ...sim.rig.faults import link_close_frame
from ...sim.rig.lockstep import FirmwareError
from ...sim.rig.setup import ARM_FRAMES, BOOT_FRAMES, SilConfig, make_plant, rc_block
from ..records.tlog import TlogWriter, create_log
from .link import DEFAULT_BAUD, HEARTBEAT_PERIOD_S, SESSION_MESSAGES, TelemetryLink
from .param_protocol import SessionLink
from .preflight import preflight_sets, set_on_board

__all__ = ["Session", "SilSession", "PortSession", "TELEMETRY_BATCH"]

#: Frames per batch of the engine: a tool sees the telemetry (and a sweep checks its safety
#: limits) this often, 250 ms of simulated time at 200 Hz. Larger batches run faster.
TELEMETRY_BATCH = 50
#: How long to wait for a loop's telemetry (its HQ_SYSID_SAMPLE) after its reply.
TELEMETRY_TIMEOUT_S = 2.0
#: A sweep over a port waits this long (seconds) for the board's first sample, and this long
#: for the pilot to arm it, before it gives up.
FIRST_SAMPLE_WAIT_S = 5.0
ARM_WAIT_S = 120.0


class Session(Protocol):
    """What a sweep drives. ``tel`` sends the host's commands and heartbeats (the session
    sends the heartbeats itself while it advances); ``time_us`` is the session's clock
    (simulated, or wall time since the session opened)."""

    tel: TelemetryLink
    #: What the log's stamps count from: a simulated session's records are stamped with this
    #: (the run's start, us since 1970 on the wall clock) plus the simulated time of their
    #: loop; None where the host's clock stamps them (a board).
    start_us: int | None

    @property
    def time_us(self) -> int: ...

    def hover(self, progress=print) -> None:
        """Bring the vehicle to a hover on its rig (on a board, the pilot does, and the
        session waits until the board says it is armed)."""

    def advance(self, handle: Callable) -> None:
        """Let time pass; call ``handle`` with each message of interest that arrives."""

    def close(self) -> None:
        """Stop what the session started; its log is complete and closed."""


class _TelemetryLog:
    """Reads the telemetry link and logs every packet with the simulated time of its loop:
    each loop's telemetry ends with its HQ_SYSID_SAMPLE, so every packet is stamped with
    ``start_us`` plus the time_us of the first HQ_SYSID_SAMPLE at or after it in the stream.
    Repeatable apart from ``start_us``, without a read per frame. Framing and logging are C++ (``_simcore.TelemetryTap``); the messages of
    interest are decoded here with the host tool's codec.

    The tap has its own descriptor on the link, as a wire tap would: when the host tool
    closes its end (the ``link`` fault), what the firmware sends is still logged."""

    def __init__(self, tel, tlog_path: str, start_us: int):
        self.codec = tel.codec
        self.ids = {name: tel.ids[name] for name in SESSION_MESSAGES}
        self.fd = os.open(tel.name, os.O_RDONLY | os.O_NOCTTY | os.O_NONBLOCK)
        try:
            self._file = create_log(tlog_path)
        except BaseException:
            os.close(self.fd)
            raise
        self.tap = _simcore.TelemetryTap(self.fd, self._file.fileno(), list(self.ids.values()),
                                         start_us)

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
            # The file ends with the last whole record that fitted; the run stops here.
            code = self.tap.write_errno
            if code in NO_ROOM:
                raise DiskFull(self._file.name, os.strerror(code))
            raise OSError(code, os.strerror(code), self._file.name)
        return out

    def close(self) -> None:
        """Log what is left on the link (packets of a loop cut short get the last loop's
        time, not lost), then close the log."""
        try:
            if not self.tap.write_failed:
                self.tap.drain()
        finally:
            try:
                self._file.close()
            finally:
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

    heartbeat = arm = set_mode = start_excitation = stop_excitation = finish_excitation = _drop

    def close(self) -> None:
        pass


class _FirmwareTelemetry(TelemetryLink):
    """The SIL's telemetry link to its own firmware: a write that finds the link gone
    because the firmware died reports the death (``died`` raises it), not a lost link."""

    def __init__(self, path: str, died: Callable[[], None]):
        super().__init__(path)
        self._died = died

    def write(self, data) -> int:
        try:
            return super().write(data)
        except LinkLost:
            self._died()
            raise


#: A pilot_from that no run reaches: the pilot stays landed (its frames count from there).
_PILOT_WAITS = 1 << 40


class SilSession(Closing):
    """The firmware in the loop as a session: it boots, arms and hovers the simulated rig,
    and steps it in batches; a tool drives it through ``tel`` (the telemetry link, the same
    code as for a board) and :meth:`advance`. Every telemetry packet is logged to ``tlog``
    stamped with ``start_us`` (the wall clock when the session began, us since 1970; given,
    for a test that wants two logs byte for byte) plus the simulated time of its loop, so
    tools show when the run happened while the run itself stays the same every time.

    The firmware, the plant and the frames between them are the lockstep driver's
    (:class:`heliquad.sim.rig.driver.Rig`, whose batches run in C++ in their own thread);
    this session gives each batch the pilot's RC and, while it runs, reads and logs the
    telemetry. Commands and heartbeats go out between batches only, on exact frames, so a
    run is the same every time."""

    def __init__(self, cfg: SilConfig, tlog_path: str, start_us: int | None = None):
        self.cfg = cfg
        self.start_us = int(time.time() * 1e6) if start_us is None else int(start_us)
        image = {"image": cfg.firmware_image} if cfg.firmware_image else {}
        if cfg.firmware == "teensy35":
            image["link"] = cfg.firmware_link
        self.rig = Rig(lambda dt_s: make_plant(cfg, dt_s), cfg.firmware, cfg.loop_hz,
                       cfg.faults, dmp_image=cfg.dmp_image, params_file=cfg.param_store,
                       idle_timeout_s=cfg.idle_timeout_s,
                       sd_image=cfg.sd_image, sd_faults=cfg.sd_faults, **image)
        #: What flies and what it flies (a manifest records them).
        self.fw, self.plant, self.dt_us = self.rig.fw, self.rig.plant, self.rig.dt_us
        with contextlib.ExitStack() as undo:       # a failure or Ctrl-C here stops it all
            undo.callback(self.rig.close)
            self.tel = _FirmwareTelemetry(self.rig.telemetry_path, self._raise_if_died)
            undo.callback(self.tel.close)
            self.telemetry = _TelemetryLog(self.tel, tlog_path, self.start_us)
            undo.pop_all()
        # The tool's heartbeat, on exact frames so that runs repeat.
        self.heartbeat_frames = max(1, int(round(HEARTBEAT_PERIOD_S * cfg.loop_hz)))
        self.link_close_frame = link_close_frame(cfg.faults, self.dt_us)
        # The default pilot (or the RC script) counts its frames from here: a session that
        # sets the vehicle's geometry first holds the board disarmed while it does.
        self.pilot_from = 0
        self.hovering = False

    @property
    def frame(self) -> int:
        """The last frame run."""
        return self.rig.frame

    @property
    def reply(self):
        """The firmware's last reply (None before the first frame)."""
        return self.rig.reply

    @property
    def time_us(self) -> int:
        return self.rig.time_us

    def advance(self, handle=None, frames: int = TELEMETRY_BATCH) -> list:
        """Step ``frames`` lockstep frames (a batch by default) and pass each message of
        interest in their telemetry to ``handle`` as it arrives, while the engine runs the
        next frames: work done there is off the lockstep's critical path. ``handle`` must
        not write to the telemetry link. Without ``handle``, the messages are returned."""
        end, out = self.frame + frames, []

        def collect(messages):
            for m in messages:
                (handle or out.append)(m)

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
        try:
            messages = self.telemetry.read_until(self.time_us)
        except FirmwareError:
            # Killed after its last reply, the firmware leaves the telemetry short: say so.
            self._raise_if_died()
            raise
        collect(messages)
        return out

    def _raise_if_died(self) -> None:
        """A link that failed because the firmware died (killed, crashed) is that death,
        said as such, whichever end noticed it first; otherwise nothing."""
        if self.rig.firmware_died():
            raise FirmwareError(f"the firmware died at frame {self.frame} "
                                f"({self.fw.stderr_tail()})") from None

    def close_host_link(self) -> None:
        """The host tool closes its end of the telemetry link (the ``link`` fault): from now
        on nothing it sends reaches the firmware. The tap keeps logging what arrives."""
        if isinstance(self.tel, _ClosedLink):
            return
        self.tel.close()
        self.tel = _ClosedLink(self.tel)

    def _run(self, first: int, n: int, collect) -> None:
        """Frames first .. first + n - 1 on the rig; telemetry read while they run."""
        self.rig.advance(n, rc_block(first - self.pilot_from, n, self.cfg.collective,
                                     self.cfg.rc_script, self.cfg.loop_hz),
                         while_running=lambda: collect(self.telemetry.read()))

    def hover(self, progress=print) -> None:
        """Boot, arm and hover for the settling time. With a vehicle file of its own
        (``--params``), the board is first given that vehicle's geometry parameters (the
        CA_* that ``heliquad params from-vehicle`` writes), disarmed, so that the firmware's
        allocation flies the vehicle the simulator flies. Called again once it hovers (a
        session that flies several sweeps), it hovers for the settling time only."""
        settle = int(round(self.cfg.settle_s * self.cfg.loop_hz))
        if self.hovering:
            self.advance(frames=settle)
            return
        self.hovering = True
        geometry = self.cfg.plant == "vehicle" and self.cfg.params
        if geometry or self.cfg.load_params:
            self.pilot_from = _PILOT_WAITS             # landed until the parameters are set
            self.advance(frames=BOOT_FRAMES)
            set_on_board(SessionLink(self), preflight_sets(geometry and self.cfg.params,
                                                           self.cfg.load_params), progress)
            self.pilot_from = self.frame
        self.advance(frames=BOOT_FRAMES + ARM_FRAMES + settle)

    def land(self) -> bool:
        """The pilot lands: arm switch and throttle down until the firmware disarms, then
        the time it takes to save the parameters changed while armed (as ``heliquad board``
        lands, :data:`~heliquad.sim.rig.board.SAVE_WAIT_S`); whether it disarmed."""
        self.pilot_from = _PILOT_WAITS
        for _ in range(int(round(DISARM_WAIT_S * self.cfg.loop_hz))):
            self.advance(frames=1)
            if not self.reply.armed:
                self.advance(frames=int(round(SAVE_WAIT_S * self.cfg.loop_hz)))
                return True
        return False

    def close(self) -> None:
        """Close the telemetry link and the log, then the rig (the sim link, the firmware);
        each step runs even when one before it fails (the firmware last, so that it is never
        left running)."""
        with contextlib.ExitStack() as stack:
            stack.callback(self.rig.close)
            stack.callback(self.telemetry.close)
            stack.callback(self.tel.close)


class PortSession(Closing):
    """A board (or a ``heliquad board`` pty) as a session: wall-clock time, the link
    logging every packet with the host's clock."""

    start_us = None                 # the host's clock stamps the log, not an offset

    def __init__(self, port: str, tlog_path: str, baud: int = DEFAULT_BAUD, poll_s: float = 0.05):
        self.tel = TelemetryLink(port, baud=baud)   # the port first: a bad one creates nothing
        try:
            self.tlog = self.tel.tlog = TlogWriter(tlog_path)
        except BaseException:
            self.tel.close()
            raise
        self.poll_s = poll_s
        self.t0 = time.monotonic()
        self.tel.heartbeat()                  # the firmware wants one before an excitation
        self.last_hb = self.t0

    @property
    def time_us(self) -> int:
        return int((time.monotonic() - self.t0) * 1e6)

    @property
    def garbage_bytes(self) -> int:
        """Bytes the link's framer skipped so far: damaged packets and noise, which carry
        no sample (a sweep counts them per frequency)."""
        return self.tel.framer.skipped

    def hover(self, progress=print) -> None:
        """On a board the pilot arms and hovers: wait until the board's samples say it is
        armed (an excitation sent before would be refused), saying so once if it is not."""
        start, seen, said = time.monotonic(), False, False
        while True:
            for m in self.advance():
                if m.get_type() == "HQ_SYSID_SAMPLE":
                    if m.armed:
                        return
                    seen = True
            waited = time.monotonic() - start
            if not seen and waited > FIRST_SAMPLE_WAIT_S:
                raise InputError(f"no samples from the board in {FIRST_SAMPLE_WAIT_S:g} s: is "
                                 f"{self.tel.name} its telemetry port, and is it running?")
            if seen and not said:
                progress("waiting for the board to be armed (the pilot's arm switch) ...")
                said = True
            if waited > ARM_WAIT_S:
                raise InputError(f"the board was not armed within {ARM_WAIT_S:g} s; arm it, "
                                 "then run the sweep again")

    def advance(self, handle=None) -> list:
        """Wait one poll period, send the heartbeat when due, and pass what arrived to
        ``handle`` (or return it)."""
        time.sleep(self.poll_s)
        now = time.monotonic()
        if now - self.last_hb >= HEARTBEAT_PERIOD_S:
            self.tel.heartbeat()
            self.last_hb = now
        msgs = self.tel.poll(only=SESSION_MESSAGES)
        self.tlog.flush()
        if handle is None:
            return msgs
        for m in msgs:
            handle(m)
        return []

    def close(self) -> None:
        self.tel.close()
        self.tlog.close()
