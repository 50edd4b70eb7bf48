"""The drop-in's server loop: the emulated board behind the two ptys, sensor frames in,
replies and telemetry out, as heliquad-fw-host serves them (docs/link-contract.md)."""

from __future__ import annotations

import select
import sys
import time

from ...base.dialect import dialect
from ...base.firmware_facts import MAX_PTY_BACKLOG_BYTES
from ...base.framing import Codec, Framer
from ..teensy35 import ESC_PINS
from .board import IMAGE_LOOP_HZ
from .native_frames import IDLE, KEEP, LINK_FAILED, MID_FRAME, PYTHON, UPLINK, NativeFrames

#: Telemetry is written out in chunks as a USB CDC device ships it (the link contract): after
#: a sync frame's reply, once this many bytes wait, or when the sim link is quiet this long.
TELEMETRY_CHUNK = 1024
QUIET_S = 0.001
#: The drop-in's exit codes: a usage error (an option, the image, the parameter file), no
#: frame for the idle timeout, a sim link that failed, a fault of the image.
EXIT_USAGE, EXIT_IDLE, EXIT_LINK, EXIT_IMAGE = 2, 3, 4, 5


class Stop:
    """Set by the signal handler: the loop ends at its next turn."""

    requested = False


class DropIn:
    """The board behind the two ptys: sensor frames in, replies and telemetry out, as
    heliquad-fw-host does (docs/link-contract.md)."""

    def __init__(self, board, sim, tel, idle_timeout_s: float, backlog_bytes: int = 0, *,
                 native: bool = True):
        # At most what the pty's line discipline holds in sight, as heliquad-fw-host's bound.
        self.backlog_bytes = min(backlog_bytes, MAX_PTY_BACKLOG_BYTES)
        self.board, self.sim, self.tel, self.idle_timeout_s = board, sim, tel, idle_timeout_s
        self.mav = mav = dialect()
        # The vehicle's ids, as the board's.
        self.codec = Codec(mav, system_id=1, component_id=mav.MAV_COMP_ID_AUTOPILOT1)
        self.framer = Framer(self.codec)
        self.frame_id = mav.MAVLINK_MSG_ID_HQ_SENSOR_FRAME
        self.reply_id = mav.MAVLINK_MSG_ID_HQ_ACTUATOR_FRAME
        self.last_frame, self.reply = None, b""
        self.lost = self.repeated = self.frames = self.dropped = 0
        self.last_input = time.monotonic()
        self.uplink = b""
        self.telemetry_chunk, self.quiet_s = TELEMETRY_CHUNK, QUIET_S
        # The plain frames natively (native_frames.py); without it, every frame here.
        self.native = NativeFrames(self) if native else None

    def flush_telemetry(self) -> None:
        """Put the queued telemetry on the link; before the first frame, nothing: what the
        boot sent (the parameters' and the IMU's start-up messages) waits for the simulator,
        which opens the telemetry port before it steps (opening a serial port discards what
        was already waiting), as the host build does."""
        out = self.board.telemetry_out
        if self.backlog_bytes:
            self.dropped += self.tel.drop_oldest(out, self.backlog_bytes)
        if out and self.frames:
            del out[:self.tel.write_some(bytes(out))]

    def serve(self) -> int:
        """Answer sensor frames until asked to stop, idle, or the link fails: the exit code."""
        board, sim, tel = self.board, self.sim, self.tel
        while not Stop.requested:
            # Telemetry leaves as the link contract says: after a sync frame's reply, and
            # otherwise once TELEMETRY_CHUNK bytes wait or the sim link is quiet QUIET_S.
            if len(board.telemetry_out) >= TELEMETRY_CHUNK:
                self.flush_telemetry()
            if self.native is not None and self.native.ready():
                code, python_next = self._native_turn()
                if code is not None:
                    return code
                if not python_next:
                    continue
            ready, _, _ = select.select([sim.master, tel.master], [], [],
                                        QUIET_S if board.telemetry_out else 0.1)
            if tel.master in ready:
                self.uplink += tel.read()           # fed to the board before its next loop
            if sim.master in ready:
                self.last_input = time.monotonic()
                code = self._feed(sim.read())
                if code:
                    return code
            elif self._idle(ready):
                return EXIT_IDLE
        return 0

    def _native_turn(self) -> tuple:
        """The native path's frames, then what its hand-back asks: (an exit code or None,
        whether the Python path's select takes the next turn: uplink bytes wait). A frame
        that is not plain is fed here from the bytes the native path read; its wait finding
        no input is the idle turn the select would make."""
        native, board = self.native, self.board
        reason = native.turn(QUIET_S if board.telemetry_out else 0.1)
        if reason == LINK_FAILED or (reason == MID_FRAME and not native.finish()):
            print("heliquad-fw-pil: sim link write failed; exiting", file=sys.stderr)
            return EXIT_LINK, False
        if reason == KEEP:
            board.keep_stored()
        if reason == IDLE and self._idle([]):
            return EXIT_IDLE, False
        if reason == PYTHON:
            # The frame the native path left, if it read one; else the select's turn.
            seen = self.frames + self.repeated
            code = self._feed(b"")
            return code or None, seen == self.frames + self.repeated
        return None, reason == UPLINK

    def _idle(self, ready) -> bool:
        """Nothing on the sim link: flush, drop what nobody reads, and say when to give up."""
        if not ready:
            self.flush_telemetry()
            if len(self.board.telemetry_out) > (1 << 20):     # nobody reads the link
                self.dropped += len(self.board.telemetry_out)
                self.board.telemetry_out.clear()
        if time.monotonic() - self.last_input >= self.idle_timeout_s:
            print(f"heliquad-fw-pil: no sensor frame for {self.idle_timeout_s} s; exiting",
                  file=sys.stderr)
            return True
        return False

    def _feed(self, data: bytes) -> int:
        for msgid, _, payload in self.framer.feed(data):
            if msgid != self.frame_id:
                continue
            msg = self.codec.decode(msgid, payload)
            new = self.last_frame is None or msg.frame != self.last_frame
            if new:
                self._step(msg)
            else:
                self.repeated += 1                 # the simulator resent it: same reply
            if msg.sync:                           # its telemetry first, then the reply
                if new:
                    self.board.end_frame(True)
                self.flush_telemetry()
            if not self.sim.write_all(self.reply, 5.0):
                print("heliquad-fw-pil: sim link write failed; exiting", file=sys.stderr)
                return EXIT_LINK
            if new and not msg.sync:
                # The rest of the loop (its telemetry, the USB stack) while the simulator
                # integrates the plant with the reply: the two processes overlap.
                self.board.end_frame(False)
        return 0

    def _step(self, msg) -> None:
        """One new sensor frame: the board's loop to its step's outputs (the caller runs the
        rest, board.end_frame), and the reply to send."""
        if self.last_frame is not None and msg.frame > self.last_frame + 1:
            gap = msg.frame - self.last_frame - 1
            self.lost += gap
            print(f"heliquad-fw-pil: {gap} sensor frame(s) lost by frame {msg.frame}",
                  file=sys.stderr)
        self.last_frame = msg.frame
        self.frames += 1
        self.board.feed_telemetry(self.uplink)
        self.uplink = b""
        fifo = bytes(msg.fifo[:min(msg.fifo_len, len(msg.fifo))])
        self.reply = self.encode_reply(msg.time_us, msg.frame, self.board.begin_frame(
            fifo, msg.fifo_kind == self.mav.HQ_SENSOR_DMP, msg.rc_us, msg.imu_fault))

    def encode_reply(self, time_us: int, frame: int, outputs) -> bytes:
        """HQ_ACTUATOR_FRAME for the frame of ``time_us`` and ``frame`` with the board's
        ``outputs`` (PilBoard.begin_frame's)."""
        motors, armed, mode, kind = outputs
        return self.codec.encode(self.reply_id, {
            "time_us": time_us, "frame": frame,
            "motor": motors + [0.0] * (len(ESC_PINS) - len(motors)), "motor_count": len(motors),
            "armed": int(armed), "mode": mode, "sensor_kind": kind})

    def summary(self) -> str:
        f = self.board.figures()
        native = self.native.frames.frames if self.native is not None else 0
        return (f"heliquad-fw-pil: {f['loops']} loops ({native} frames run natively), "
                f"{self.lost} frames lost, {self.repeated} "
                f"repeated, {self.dropped} telemetry bytes dropped, {f['watchdog_resets']} "
                f"watchdog resets, {f['emulated_s']:.3f} s emulated; step cycles median "
                f"{f['step_cycles_median']} max {f['step_cycles_max']} of "
                f"{int(self.board.machine.core_hz / IMAGE_LOOP_HZ)}, {f['overruns']} overruns, "
                f"stack high-water {f['stack_bytes']} bytes")
