"""heliquad-fw-pil: the Teensy 3.5 image, run in the emulated MK64FX512, as a drop-in for
the host build ``heliquad-fw-host`` (processor in the loop).

    python -m heliquad.sim.chip.pil --sim-link PATH --telemetry PATH [--image ELF]
                               [--loop-hz 200] [--idle-timeout-s 10] [--params FILE]

It honours the host build's link contract (docs/link-contract.md): it creates the same two
ptys and publishes their slave devices as the PATH symlinks, prints ``ready`` once the image
has booted, answers each HQ_SENSOR_FRAME with exactly one HQ_ACTUATOR_FRAME (same time and
counter; a repeated counter gets the same reply again, a gap is counted), and exits cleanly
on SIGINT/SIGTERM or when no frame comes for the idle timeout. What differs is inside: the
image that is flashed to the board runs instruction by instruction, and every input and
output goes through the chip's pins and peripherals, as on the rig:

* the frame's MPU6050 FIFO bytes go into the MPU6050 on I2C0, and its fault (NACK, silent,
  reset, overflow) into that chip, or (stuck bus) into the bus itself, whose clock a device
  then holds low; the image reads the chip over the bus byte by byte;
* the frame's RC channels become servo pulses on the six RC pins (as a 50 Hz receiver
  sends them, and at once on a change), captured by FTM3;
* one frame is one pass of the image's main loop: the board runs until the loop has done
  its step and is about to sleep for the next tick (``hq::teensy::LoopTimer::wait``);
* the five thrust fractions are read back from FTM0's pulse widths (the value loaded for the
  next PWM period), with the image's ESC calibration;
* the telemetry link carries UART0's TX pin at its line rate (921 600 baud) and feeds the
  host's bytes into UART0's RX pin; a frame marked ``sync`` also lets the board run until
  what it has queued is on the wire, so the simulator can read that loop's telemetry;
* armed, mode and sensor kind come from ``hq_loop_report``, the state the image keeps in RAM
  for a debug probe;
* with ``--params FILE`` the board's parameter flash (the two sectors the image keeps its
  parameters in) is kept in FILE across runs, as the host build keeps its parameters with
  the same option: restored before the boot, written back whenever the image has changed it
  (:class:`ParamFile`).

Time is the emulated chip's: core cycles from retired instructions (sim/chip/timing.py
states the cycle model) and device events, never the host's clock, so two runs of the same
frames give the same bytes. A watchdog reset reboots the emulated board as it would the
real one (counted, and said on stderr); a fault of the image (bus fault, undefined
instruction, ``hq_fatal``) ends the run with one line on stderr and exit code 5.
"""

from __future__ import annotations

import argparse
import errno
import os
import select
import signal
import struct
import sys
import time
import tty

from ..base.dialect import dialect
from ..base.firmware_facts import LOOP_RATE_HZ

from .machine import ChipReset, EmulationError

#: The image's loop rate (firmware/targets/teensy35/main.cpp's kLoopHz: the firmware's).
IMAGE_LOOP_HZ = LOOP_RATE_HZ
#: Where a loop ends: the step is done and the image is about to sleep for the next tick.
WAIT_SYMBOL = "hq::teensy::LoopTimer::wait"
REPORT_SYMBOL = "hq_loop_report"
#: hq_loop_report: loops, step cycles, overruns (uint32); armed, mode, sensor kind,
#: excitation state (uint8).
REPORT = struct.Struct("<IIIBBBB")
#: The stack is painted with this word before reset; the deepest word overwritten since is
#: the stack's high-water mark.
STACK_PAINT = 0xDEADBEEF
#: The image's ESC calibration (firmware/targets/teensy35/motors.hpp: EscCalibration's
#: defaults) and FTM0's counts per microsecond: a pulse of min_us is stop, max_us full thrust.
ESC_MIN_US, ESC_MAX_US, FTM0_COUNTS_PER_US = 1000, 2000, 15
#: The RC inputs the board captures (FTM3 channels 0-5).
RC_CHANNELS = 6
#: A receiver's frame: 20 ms, four loops.
RC_FRAME_LOOPS = 4
#: Emulated-time bounds: reset to the first loop; one loop (a loop that takes longer has hung,
#: and the 500 ms watchdog has already reset the chip); draining the UART on a sync frame.
BOOT_LIMIT_S = 5.0
LOOP_LIMIT_S = 2.0
DRAIN_LIMIT_S = 0.004
SYSTICK_EXCEPTION = 15
#: Telemetry is written out in chunks as a USB CDC device ships it (the link contract): after
#: a sync frame's reply, once this many bytes wait, or when the sim link is quiet this long.
TELEMETRY_CHUNK = 1024
QUIET_S = 0.001
EXIT_USAGE, EXIT_IDLE, EXIT_LINK, EXIT_IMAGE = 2, 3, 4, 5


class ImageFault(RuntimeError):
    """The image stopped in a way a board would not recover from by itself."""


class ParamFileError(ValueError):
    """A --params file that cannot be the board's parameter flash."""


class ParamFile:
    """The board's parameter flash kept in a file across runs, as a board keeps it across
    power cycles. The file holds the two sectors exactly as the flash does (8 KiB; the slot
    format is the image's, docs/teensy35.md), not the host build's parameter file. A file
    that does not exist yet is a new board: the sectors stay erased, and the file is created
    when the image first writes them. :meth:`keep` writes the file back (whole, replaced in
    one rename) when a flash command has changed the flash since the last time."""

    def __init__(self, board, path: str):
        self.board, self.path = board, path
        try:
            self.start, self.end = board.param_flash_range()
        except KeyError:
            raise ImageFault("the image has no parameter flash (hq_param_flash_start): it is "
                             "older than the parameter storage; --params needs a newer one") \
                from None
        self._changes = board.chip.ftfe.changes

    def restore(self) -> None:
        """The file's bytes into the sectors (before the boot)."""
        size = self.end - self.start
        try:
            with open(self.path, "rb") as fh:
                data = fh.read(size + 1)
        except FileNotFoundError:
            return
        if len(data) != size:
            raise ParamFileError(f"{self.path}: {len(data)} bytes; the Teensy image's parameter "
                                 f"file holds its two flash sectors, {size} bytes")
        self.board.write_param_flash(data)
        self._changes = self.board.chip.ftfe.changes

    def keep(self) -> None:
        """Write the sectors back if the image has changed them. A write that fails is said
        on stderr; the run goes on (the flash itself still has them)."""
        changes = self.board.chip.ftfe.changes
        if changes == self._changes:
            return
        self._changes = changes
        tmp = self.path + ".tmp"
        try:
            with open(tmp, "wb") as fh:
                fh.write(self.board.read_param_flash())
            os.replace(tmp, self.path)
        except OSError as e:
            print(f"heliquad-fw-pil: the parameters could not be kept in {self.path}: {e}",
                  file=sys.stderr, flush=True)


class PilBoard:
    """The Teensy 3.5 on the simulated rig, one lockstep frame at a time. ``params_file``:
    keep the parameter flash in that file (:class:`ParamFile`)."""

    def __init__(self, elf: str, params_file: str | None = None):
        from . import Teensy35

        self.board = Teensy35(elf, track_loops=False)      # the wait breakpoint ends a loop
        self.machine = self.board.machine
        image = self.machine.image
        for needed in (WAIT_SYMBOL, REPORT_SYMBOL):
            if not image.has(needed):
                raise ImageFault(f"{elf} has no {needed}: not a heliquad Teensy 3.5 image "
                                 "(or one older than the processor-in-the-loop target)")
        self.params = ParamFile(self.board, params_file) if params_file else None
        self.report_address = image.symbol(REPORT_SYMBOL).address
        self.waits = 0
        self._wait_target = None
        self.machine.break_at(WAIT_SYMBOL, self._on_wait)
        self.resets = 0
        self._rc_last, self._rc_age = None, 0
        self._fault = None
        self.step_cycles = []
        self.telemetry_out = bytearray()

    def _on_wait(self, machine):
        self.waits += 1
        if self._wait_target is not None and self.waits >= self._wait_target:
            return "loop-done"
        return None

    def _run_to_wait(self, limit_s: float, what: str):
        """Run until the main loop next reaches its sleep; a watchdog reset reboots."""
        self._wait_target = self.waits + 1
        try:
            while True:
                try:
                    stop = self.machine.run(seconds=limit_s)
                except ChipReset as e:
                    self.resets += 1
                    print(f"heliquad-fw-pil: {e} during {what}; the board reboots",
                          file=sys.stderr, flush=True)
                    self.board.reset()
                    self._rc_last = None            # the image lost its captures
                    self._fault = None
                    self.waits = 0
                    self._wait_target = 1
                    continue
                except EmulationError as e:
                    raise ImageFault(f"{what}: {e}") from None
                if stop.reason == "loop-done":
                    return
                if stop.reason == "fatal":
                    raise ImageFault(f"{what}: the image stopped in hq_fatal "
                                     f"(code {stop.detail.get('code')})")
                raise ImageFault(f"{what}: the main loop did not come round within "
                                 f"{limit_s:g} s of emulated time ({stop})")
        finally:
            self._wait_target = None

    def boot(self) -> None:
        """Reset to the main loop's first sleep, before the first tick (the stack painted
        first, for its high-water mark)."""
        image = self.machine.image
        if self.params:
            self.params.restore()
        self.machine.paint(image.ram_end(), image.initial_sp, STACK_PAINT)
        self._run_to_wait(BOOT_LIMIT_S, "start-up")
        if self.params:
            self.params.keep()
        self.machine.core.keep_records = False
        self.board.mpu.log.clear()
        self.board.chip.i2c0.transfers.clear()
        self.board.chip.ftm3.captures.clear()
        self._collect_telemetry()

    # -- inputs ----------------------------------------------------------------------------
    def apply_imu_fault(self, fault: int) -> None:
        """The frame's IMU fault. The held ones (none, NACK, silent, stuck bus) are set
        again only when the fault changes; reset and overflow act at every frame that
        carries them."""
        mav = dialect()
        if fault == self._fault and fault not in (mav.HQ_IMU_FAULT_RESET,
                                                  mav.HQ_IMU_FAULT_OVERFLOW):
            return
        self._fault = fault
        mpu = self.board.mpu
        self.board.chip.i2c0.hold_scl(fault == mav.HQ_IMU_FAULT_STUCK_BUS)
        mpu.set_present(fault != mav.HQ_IMU_FAULT_NACK)
        mpu.emu.set_silent(fault == mav.HQ_IMU_FAULT_SILENT)
        if fault == mav.HQ_IMU_FAULT_RESET:
            mpu.emu.power_on_reset()
        if fault == mav.HQ_IMU_FAULT_OVERFLOW:
            mpu.emu.force_overflow()

    def rc_pulses(self, rc_us) -> None:
        """Servo pulses as a 50 Hz receiver sends them (every RC_FRAME_LOOPS frames), and at
        once when a channel's value changes, so a stick change reaches the image's next loop
        as it reaches the host build's. One pulse per channel with a signal (0: none). A
        receiver's pulse is continuous, the frame's value an integer: each pulse is the one
        the image's capture reads as exactly that integer (Teensy35.rc_capture_pulse)."""
        rc = tuple(int(v) for v in rc_us[:RC_CHANNELS])
        self._rc_age += 1
        if rc == self._rc_last and self._rc_age < RC_FRAME_LOOPS:
            return
        self._rc_last, self._rc_age = rc, 0
        self.board.rc_capture_pulses({ch: us for ch, us in enumerate(rc) if us > 0})

    def feed_telemetry(self, data: bytes) -> None:
        if data:
            self.board.receive(data)

    # -- one frame ---------------------------------------------------------------------------
    def frame(self, fifo: bytes, dmp: bool, rc_us, imu_fault: int, sync: bool):
        """Inputs in, one loop, outputs out: (motors, armed, mode, sensor kind)."""
        self.apply_imu_fault(imu_fault)
        if fifo:
            self.board.mpu.emu.push_fifo(bytes(fifo), dmp)
        self.rc_pulses(rc_us)
        self._run_to_wait(LOOP_LIMIT_S, f"loop {self.waits}")
        if self.params:
            self.params.keep()
        if sync:
            self._drain_uart()
        self._collect_telemetry()
        loops, cycles, _, armed, mode, kind, _ = self.report()
        self.step_cycles.append(cycles)
        return self.thrust(), bool(armed), mode, kind

    def report(self) -> tuple:
        """hq_loop_report as the image last wrote it."""
        return REPORT.unpack(self.machine.read(self.report_address, REPORT.size))

    def figures(self) -> dict:
        """What the board would report of its loop: cycles per step (median and maximum over
        the frames run), overruns since boot, the stack's high-water mark, and the
        emulated time."""
        m, image = self.machine, self.machine.image
        loops, _, overruns, *_ = self.report()
        cycles = sorted(self.step_cycles) or [0]
        low = m.painted_high_water(image.ram_end(), image.initial_sp, STACK_PAINT)
        return {"loops": loops, "step_cycles_median": cycles[len(cycles) // 2],
                "step_cycles_max": cycles[-1], "overruns": overruns,
                "stack_bytes": image.initial_sp - low, "emulated_s": m.seconds(),
                "watchdog_resets": self.resets}

    def _drain_uart(self) -> None:
        """Let the board run (it sleeps, the TX interrupt feeds the UART) until nothing it
        queued is left to send: then the loop's telemetry is on the wire. Never into the
        next loop, whose inputs are not in yet: at most until 20 us before the next SysTick
        (none at all when that tick is already pending: the loop overran), and at most
        DRAIN_LIMIT_S. What is still queued then leaves during the next frame, as the bytes
        of a loop that sent more than its period carries leave a board late."""
        uart = self.board.chip.uart0
        m = self.machine
        systick = self.board.chip.scs.systick
        if m.pending & (1 << SYSTICK_EXCEPTION) or systick.zero_at is None:
            return
        deadline = min(m.now() + int(DRAIN_LIMIT_S * m.core_hz),
                       systick.zero_at - int(20e-6 * m.core_hz))
        while m.now() < deadline and not uart.tx_idle():
            step = min(uart.frame_cycles() * 4, deadline - m.now())
            m.run(seconds=step / m.core_hz)

    def thrust(self) -> list:
        """The five thrust fractions the ESCs get from the next PWM period on."""
        ftm0 = self.board.chip.ftm0
        lo, hi = ESC_MIN_US * FTM0_COUNTS_PER_US, ESC_MAX_US * FTM0_COUNTS_PER_US
        out = []
        for ch in range(5):
            counts = ftm0.commanded_value(ch)
            out.append(min(1.0, max(0.0, (counts - lo) / (hi - lo))) if counts is not None
                       else 0.0)
        return out

    def _collect_telemetry(self) -> None:
        chip = self.board.chip
        self.telemetry_out += self.board.take_telemetry()
        # A lockstep run is long: the models' inspection logs must not grow with it (the
        # native models keep none after the boot, see boot(); the pin model's level log is
        # Python's).
        chip.ports.level_log.clear()



class Pty:
    """A pseudo-terminal whose slave device is published as ``link_path`` (a symlink), raw,
    with our own slave descriptor kept open so the master never sees EOF between users."""

    #: The most a backlog bound can be: what the line discipline holds in sight of TIOCINQ
    #: (Linux's N_TTY_BUF_SIZE, 4096, less one), as heliquad-fw-host's.
    MAX_BACKLOG = 4095

    def __init__(self, link_path: str):
        self.master, slave = os.openpty()
        self.slave = slave
        tty.setraw(slave)
        os.set_blocking(self.master, False)
        self.slave_path = os.ttyname(slave)
        self.link_path = link_path
        try:
            os.unlink(link_path)
        except FileNotFoundError:
            pass
        os.symlink(self.slave_path, link_path)
        os.set_blocking(self.slave, False)        # read only to drop the oldest: never wait

    def drop_oldest(self, queued: bytearray, limit: int) -> int:
        """Drop the oldest bytes of what waits for a reader (in the pty, then at the front
        of ``queued``) past ``limit``; returns how many were dropped."""
        import fcntl
        import termios

        waiting = struct.unpack("i", fcntl.ioctl(self.slave, termios.FIONREAD, b"\0" * 4))[0]
        excess, dropped = waiting + len(queued) - limit, 0
        while excess > 0 and waiting > 0:
            try:
                data = os.read(self.slave, min(excess, waiting, 4096))
            except BlockingIOError:
                break
            if not data:
                break
            excess, waiting, dropped = excess - len(data), waiting - len(data), dropped + len(data)
        if excess > 0:
            cut = min(excess, len(queued))
            del queued[:cut]
            dropped += cut
        return dropped

    def close(self) -> None:
        try:
            os.unlink(self.link_path)
        except OSError:
            pass
        for fd in (self.slave, self.master):
            try:
                os.close(fd)
            except OSError:
                pass

    def read(self) -> bytes:
        try:
            return os.read(self.master, 65536)
        except BlockingIOError:
            return b""
        except OSError as e:
            if e.errno == errno.EIO:
                return b""
            raise

    def write_some(self, data: bytes) -> int:
        """Write what fits without blocking; the rest is lost as on a wire nobody reads."""
        try:
            return os.write(self.master, data)
        except BlockingIOError:
            return 0

    def write_all(self, data: bytes, timeout_s: float) -> bool:
        view, deadline = memoryview(data), time.monotonic() + timeout_s
        while view:
            try:
                n = os.write(self.master, view)
                view = view[n:]
            except BlockingIOError:
                if time.monotonic() > deadline:
                    return False
                select.select([], [self.master], [], 0.05)
        return True


def _usage(message: str) -> None:
    print(f"heliquad-fw-pil: {message}", file=sys.stderr)
    sys.exit(EXIT_USAGE)


def parse(argv):
    p = argparse.ArgumentParser(
        prog="heliquad-fw-pil",
        description="The Teensy 3.5 image in the emulated MK64FX512, driven in lockstep like "
                    "heliquad-fw-host (the same sim-link and telemetry ptys).")
    p.add_argument("--sim-link", required=True, help="path for the sim link's pty symlink")
    p.add_argument("--telemetry", required=True, help="path for the telemetry pty symlink")
    p.add_argument("--image", help="the .elf (default: the image the install built)")
    p.add_argument("--loop-hz", type=float, default=IMAGE_LOOP_HZ,
                   help=f"must be the image's loop rate, {IMAGE_LOOP_HZ:g}")
    p.add_argument("--idle-timeout-s", type=int, default=10,
                   help="exit when no sensor frame arrives for this long (wall time)")
    p.add_argument("--dmp-image", help="refused: the Teensy image carries its DMP firmware "
                                       "from its build")
    p.add_argument("--telemetry-backlog-bytes", type=int, default=0, metavar="N",
                   help="the most telemetry that waits for a reader, the oldest dropped past "
                        "it, as a board's USB or UART buffer (default 0: unbounded, for the "
                        "lockstep simulator)")
    p.add_argument("--params", metavar="FILE",
                   help="keep the board's parameter flash (two 4 KiB sectors, 8 KiB) in FILE "
                        "across runs: restored before the boot, written when the image "
                        "changes it; a missing FILE is a new board")
    args = p.parse_args(argv)
    if args.loop_hz != IMAGE_LOOP_HZ:
        _usage(f"--loop-hz {args.loop_hz:g}: the Teensy image runs its loop at "
               f"{IMAGE_LOOP_HZ:g} Hz")
    if args.idle_timeout_s <= 0:
        _usage("--idle-timeout-s must be positive")
    if args.telemetry_backlog_bytes < 0:
        _usage("--telemetry-backlog-bytes must not be negative")
    if args.dmp_image:
        _usage("--dmp-image: the Teensy image carries its DMP firmware from its build "
               "(-DHQ_DMP_IMAGE=FILE); the emulated board runs what the image has")
    return args


class _Stop:
    requested = False


class _DropIn:
    """The board behind the two ptys: sensor frames in, replies and telemetry out, as
    heliquad-fw-host does (docs/link-contract.md)."""

    def __init__(self, board, sim, tel, idle_timeout_s: float, backlog_bytes: int = 0):
        from ..base.framing import Codec, Framer

        self.backlog_bytes = min(backlog_bytes, Pty.MAX_BACKLOG)
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
        while not _Stop.requested:
            # Telemetry leaves as the link contract says: after a sync frame's reply, and
            # otherwise once TELEMETRY_CHUNK bytes wait or the sim link is quiet QUIET_S.
            if len(board.telemetry_out) >= TELEMETRY_CHUNK:
                self.flush_telemetry()
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
            if self.last_frame is not None and msg.frame == self.last_frame:
                self.repeated += 1                 # the simulator resent it: same reply
            else:
                self._step(msg)
            if msg.sync:
                self.flush_telemetry()
            if not self.sim.write_all(self.reply, 5.0):
                print("heliquad-fw-pil: sim link write failed; exiting", file=sys.stderr)
                return EXIT_LINK
        return 0

    def _step(self, msg) -> None:
        """One new sensor frame: the board's loop, and the reply to send."""
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
        motors, armed, mode, kind = self.board.frame(
            fifo, msg.fifo_kind == self.mav.HQ_SENSOR_DMP, msg.rc_us, msg.imu_fault, bool(msg.sync))
        self.reply = self.codec.encode(self.reply_id, {
            "time_us": msg.time_us, "frame": msg.frame, "motor": motors, "armed": int(armed),
            "mode": mode, "sensor_kind": kind})

    def summary(self) -> str:
        f = self.board.figures()
        return (f"heliquad-fw-pil: {f['loops']} loops, {self.lost} frames lost, {self.repeated} "
                f"repeated, {self.dropped} telemetry bytes dropped, {f['watchdog_resets']} "
                f"watchdog resets, {f['emulated_s']:.3f} s emulated; step cycles median "
                f"{f['step_cycles_median']} max {f['step_cycles_max']} of "
                f"{int(self.board.machine.core_hz / IMAGE_LOOP_HZ)}, {f['overruns']} overruns, "
                f"stack high-water {f['stack_bytes']} bytes")


def _open(args):
    """The booted board and its two ptys, or a one-line usage error."""
    from ..base.firmware_image import ImageNotFound, teensy35_image
    try:
        elf = args.image or str(teensy35_image("elf"))
    except ImageNotFound as e:
        _usage(str(e))
    try:
        board = PilBoard(elf, args.params)
        board.boot()
    except (ImageFault, ParamFileError, OSError) as e:
        _usage(str(e))
    try:
        sim, tel = Pty(args.sim_link), Pty(args.telemetry)
    except OSError as e:
        _usage(f"cannot create the links: {e}")
    report = board.report()
    print(f"sim link: {args.sim_link} -> {sim.slave_path}\ntelemetry: {args.telemetry} -> "
          f"{tel.slave_path}\nimu: {'dmp' if report[5] == dialect().HQ_SENSOR_DMP else 'raw'}\n"
          f"image: {elf}\nready", flush=True)
    return board, sim, tel


def main(argv=None) -> int:
    args = parse(sys.argv[1:] if argv is None else argv)

    def on_signal(signum, frame):
        _Stop.requested = True
    signal.signal(signal.SIGINT, on_signal)
    signal.signal(signal.SIGTERM, on_signal)
    board, sim, tel = _open(args)
    drop_in = _DropIn(board, sim, tel, args.idle_timeout_s, args.telemetry_backlog_bytes)
    exit_code = 0
    try:
        exit_code = drop_in.serve()
    except ImageFault as e:
        print(f"heliquad-fw-pil: the image faulted at frame {drop_in.last_frame}: {e}",
              file=sys.stderr)
        exit_code = EXIT_IMAGE
    finally:
        if board.telemetry_out:
            tel.write_some(bytes(board.telemetry_out))
        print(drop_in.summary(), file=sys.stderr)
        sim.close()
        tel.close()
    return exit_code


if __name__ == "__main__":
    sys.exit(main())
