"""The drop-in's plain frames in the native core (``heliquad._simcore.PilFrames``,
sim/chip/pil_frames.hpp): between two frames the Python path needs, the next frames in order
that carry no IMU fault and find no uplink waiting (sync frames among them) are read, run,
answered and their telemetry written without a call into Python. Each hand-back carries the
state both paths share (the frame counter, the reply and its sequence number, the RC pulses'
schedule, the bytes not yet consumed or written, the loop's stops and cycles), so the Python
path goes on from exactly where the native one stopped, in the middle of a frame if a run
stopped there for something only Python does (a Python event, a reset, a fault)."""

from __future__ import annotations

import collections
import time

from heliquad._simcore import PilFrames

# PilFrames::Reason.
(PYTHON, IDLE, UPLINK, SIGNAL, LINK_FAILED, MID_FRAME, KEEP, FRAMES) = range(1, 9)
# PilFrames::Phase: where a frame handed over in the middle stopped.
TO_OUTPUTS, TO_LOOP_END, DRAIN = 1, 2, 3
#: Frames a turn runs at most before Python looks at its signals and state again (a signal
#: that lands while the board runs, not while the turn waits for input, waits for this).
TURN_FRAMES = 200


class NativeFrames:
    """The native path of a :class:`~.drop_in.DropIn` (its ``native``)."""

    def __init__(self, drop_in):
        self.drop_in = drop_in
        self.frames = PilFrames(drop_in.board.machine.core)
        # Frames handed over in their middle (finish()), by the phase they stopped in.
        self.finished = collections.Counter()

    def ready(self) -> bool:
        """Whether the next frames may be native: the first frame answered (the telemetry
        rules for before it are Python's), no uplink waiting, no telemetry backlog bound (its
        dropping is Python's), the board between frames with no IMU fault held."""
        d = self.drop_in
        return (d.last_frame is not None and d.frames > 0 and not d.uplink
                and not d.backlog_bytes and d.board.native_ready()
                and d.board.native_capable())

    def turn(self, wait_s: float) -> int:
        """Plain frames until Python is needed: the reason (PilFrames::Reason). ``wait_s``:
        how long to wait for sim-link input before IDLE."""
        d, board, nat = self.drop_in, self.drop_in.board, self.frames
        config = board.native_config(d.sim.master, d.tel.master, d.codec.system_id,
                                     d.codec.component_id, d.telemetry_chunk, d.quiet_s)
        if config is None:
            return PYTHON
        nat.configure(config)
        self._hand_over(nat, d, board)
        before, read = nat.frames, nat.bytes_read
        try:
            reason = nat.serve(max(0, int(wait_s * 1000)), TURN_FRAMES)
        finally:
            self._take_back(nat, d, board, nat.frames - before)
            if nat.bytes_read != read:              # input from the simulator: not idle
                d.last_input = time.monotonic()
        return reason

    @staticmethod
    def _hand_over(nat, d, board) -> None:
        nat.input, d.framer.buf[:] = bytes(d.framer.buf), b""
        nat.telemetry = bytes(board.telemetry_out)
        board.telemetry_out.clear()
        nat.last_frame, nat.reply, nat.seq = d.last_frame, d.reply, d.codec.seq & 0xFF
        rc_last, nat.rc_age = board.rc_schedule()
        nat.rc_last = list(rc_last or ())
        nat.ftfe_changes = board.board.chip.ftfe.changes
        nat.waits, nat.in_card_wait = board.waits, board.in_card_wait

    @staticmethod
    def _take_back(nat, d, board, handled: int) -> None:
        d.framer.buf[:] = nat.input + bytes(d.framer.buf)
        board.telemetry_out += nat.telemetry
        if handled:
            d.frames += handled
            d.last_frame, d.reply, d.codec.seq = nat.last_frame, nat.reply, nat.seq
        board.set_rc_schedule(tuple(nat.rc_last) or None, nat.rc_age)
        board.waits, board.in_card_wait = nat.waits, nat.in_card_wait
        board.step_cycles += nat.take_step_cycles()
        board.board.chip.ports.level_log.clear()

    def finish(self) -> bool:
        """The frame the native path handed over in its middle, finished as the Python path
        does it (from the run's stop; a sync frame's reply after its telemetry); False when
        its reply could not be written."""
        d, board, nat = self.drop_in, self.drop_in.board, self.frames
        self.finished[nat.phase] += 1
        sync = nat.frame_sync
        if nat.phase == TO_OUTPUTS:
            d.reply = d.encode_reply(nat.frame_time_us, nat.last_frame,
                                     board.resume_begin(nat.code))
            if not sync:
                if not d.sim.write_all(d.reply, 5.0):
                    return False
                board.end_frame(False)
                return True
            board.end_frame(True)
        elif nat.phase == TO_LOOP_END:
            board.end_frame(sync, code=nat.code)
            if not sync:
                return True
        else:
            board.resume_drain(nat.code, nat.drain_until, nat.drain_after)
        d.flush_telemetry()
        return d.sim.write_all(d.reply, 5.0)
