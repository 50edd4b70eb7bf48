"""The Teensy 3.5 on the simulated rig, one lockstep frame at a time (:class:`PilBoard`):
the frame's inputs into the emulated chip's pins and peripherals, one pass of the image's
main loop, the motors and the loop's state read back, the telemetry its link sent: the USB
port (a USB host model that enumerated the board and holds its port open) or UART0."""

from __future__ import annotations

import struct
import sys

from ...base.dialect import dialect
from ...base.firmware_facts import LOOP_RATE_HZ
from ...rig.setup import BOARD_LINKS
from ..machine import ChipReset, EmulationError
from ..teensy35 import ESC_PINS, PINS, RC_PINS, Teensy35
from ..usb_host import UsbHost
from .param_file import ParamFile

#: The image's loop rate (firmware/targets/teensy35/main.cpp's kLoopHz: the firmware's).
IMAGE_LOOP_HZ = LOOP_RATE_HZ
#: Where a loop ends: the step is done and the image is about to sleep for the next tick.
WAIT_SYMBOL = "hq::teensy::LoopTimer::wait"
#: Where a loop ends too: a tick came while the card is busy, and its step is about to run
#: inside the card's wait (main.cpp's StepWhenDue). Its frame's inputs go in there.
CARD_WAIT_STEP_SYMBOL = "hq_card_wait_step"
#: Where a loop's step has its outputs final (the motors written, hq_loop_report's flight
#: state set): the frame's reply can go while the rest of the loop runs (begin_frame).
STEP_OUTPUTS_SYMBOL = "hq_step_outputs"
REPORT_SYMBOL = "hq_loop_report"
#: hq_loop_report: loops, step cycles, overruns (uint32); armed, mode, sensor kind,
#: excitation state, rotor count (uint8).
REPORT = struct.Struct("<IIIBBBBB")
#: The stack is painted with this word before reset; the deepest word overwritten since is
#: the stack's high-water mark.
STACK_PAINT = 0xDEADBEEF
#: The image's ESC calibration (firmware/targets/teensy35/motors.hpp: EscCalibration's
#: defaults) and FTM0's counts per microsecond: a pulse of min_us is stop, max_us full thrust.
ESC_MIN_US, ESC_MAX_US, FTM0_COUNTS_PER_US = 1000, 2000, 15
#: The RC inputs the board captures (FTM3 channels 0-6: the pilot's channels 1-7).
RC_CHANNELS = len(RC_PINS)
#: A receiver's frame: 20 ms, four loops.
RC_FRAME_LOOPS = 4
#: Emulated-time bounds: reset to the first loop; one loop (a loop that takes longer has hung,
#: and the 500 ms watchdog has already reset the chip); draining the UART on a sync frame.
BOOT_LIMIT_S = 5.0
LOOP_LIMIT_S = 2.0
DRAIN_LIMIT_S = 0.004
#: A drain ends at least this long before the next SysTick.
DRAIN_MARGIN_S = 20e-6
SYSTICK_EXCEPTION = 15
#: The telemetry links a board has: its USB port (CDC-ACM) and UART0 (pins 0 and 1).
LINKS = BOARD_LINKS
#: The emulated hub reports the board attached at once: a host's 100 ms debounce
#: (usb_host.DEBOUNCE_S) would outlast the image's start-up, and the port must be open
#: before the first loop so that its telemetry is read from the first loop on, as UART0's.
PIL_DEBOUNCE_S = 0.0


class ImageFault(RuntimeError):
    """The image stopped in a way a board would not recover from by itself."""


class PilBoard:
    """The Teensy 3.5 on the simulated rig, one lockstep frame at a time. ``params_file``:
    keep the parameter flash in that file, ``program_file`` the on-board program's
    (:class:`ParamFile`). ``sd_image``: the card-image file in its microSD socket (default:
    the socket empty). ``link``: the link whose telemetry the board collects, ``usb`` (a USB
    host model enumerates the port and holds it open) or ``uart`` (UART0; nothing is plugged
    into the USB port: a caller may plug in a host of its own)."""

    def __init__(self, elf: str, params_file: str | None = None, *, link: str,
                 sd_image: str | None = None, program_file: str | None = None):
        if link not in LINKS:
            raise ValueError(f"link {link!r}: one of {', '.join(LINKS)}")
        # the wait breakpoint ends a loop
        self.board = Teensy35(elf, track_loops=False, sd_image=sd_image)
        self.usb_host = (UsbHost(self.board.chip, debounce_s=PIL_DEBOUNCE_S, open_port=True)
                         if link == "usb" else None)
        self.machine = self.board.machine
        image = self.machine.image
        for needed in (WAIT_SYMBOL, REPORT_SYMBOL):
            if not image.has(needed):
                raise ImageFault(f"{elf} has no {needed}: not a heliquad Teensy 3.5 image "
                                 "(or one older than the processor-in-the-loop target)")
        self.params = ParamFile(self.board, params_file) if params_file else None
        self.program = (ParamFile(self.board, program_file, "program") if program_file
                        else None)
        self.stored = [kept for kept in (self.params, self.program) if kept]
        self.report_address = image.symbol(REPORT_SYMBOL).address
        self.waits = 0
        # Where a loop ends: native stops (Machine.stop_at), no call into Python there.
        self._wait_at = self.machine.stop_at(WAIT_SYMBOL)
        self.in_card_wait = False          # the last loop ended with a step due in the card's wait
        self._card_wait_step = (self.machine.stop_at(CARD_WAIT_STEP_SYMBOL)
                                if image.has(CARD_WAIT_STEP_SYMBOL) else None)
        # Where the step's outputs are final (None: an image older than that symbol, whose
        # frames are answered at the loop's end); True while a frame stopped there.
        self._outputs_at = (self.machine.stop_at(STEP_OUTPUTS_SYMBOL)
                            if image.has(STEP_OUTPUTS_SYMBOL) else None)
        self._mid_loop = False
        self.resets = 0
        self._rc_last, self._rc_age = None, 0
        self._fault = None
        self.step_cycles = []
        self.telemetry_out = bytearray()

    def _waited(self, stop) -> bool:
        """A run stopped where a loop ends (the wait, or the card wait's step): count it."""
        if stop.reason != "stop-at":
            return False
        self.in_card_wait = stop.pc == self._card_wait_step
        self.waits += 1
        return True

    def _run_to_wait(self, limit_s: float, what: str, outputs: bool = False,
                     code: int | None = None) -> bool:
        """Run until the main loop next reaches its sleep, or with ``outputs`` until its
        step's outputs are final if that comes first (then True); a watchdog reset
        reboots. ``code``: a native run the caller made returned it (PilFrames): that run's
        stop first."""
        while True:
            try:
                if code is not None:
                    first, code = code, None        # once: a reset it raises is taken
                    stop = self.machine.after_run(first)
                    if stop is None:
                        continue
                else:
                    stop = self.machine.run(seconds=limit_s)
            except ChipReset as e:
                self.resets += 1
                print(f"heliquad-fw-pil: {e} during {what}; the board reboots",
                      file=sys.stderr, flush=True)
                self.board.reset()
                self._rc_last = None            # the image lost its captures
                self._fault = None
                self.waits = 0
                continue
            except EmulationError as e:
                raise ImageFault(f"{what}: {e}") from None
            if stop.reason == "stop-at" and stop.pc == self._outputs_at:
                if outputs:
                    return True
                continue
            if self._waited(stop):
                return False
            if stop.reason == "fatal":
                raise ImageFault(f"{what}: the image stopped in hq_fatal "
                                 f"(code {stop.detail.get('code')})")
            raise ImageFault(f"{what}: the main loop did not come round within "
                             f"{limit_s:g} s of emulated time ({stop})")

    def boot(self) -> None:
        """Reset to the main loop's first sleep, before the first tick (the stack painted
        first, for its high-water mark)."""
        image = self.machine.image
        for kept in self.stored:
            kept.restore()
        self.machine.paint(image.ram_end(), image.initial_sp, STACK_PAINT)
        self._run_to_wait(BOOT_LIMIT_S, "start-up")
        if self.usb_host is not None:
            self._check_usb_open()
        self.keep_stored()
        self.machine.core.keep_records = False
        self.board.mpu.log.clear()
        self.board.chip.i2c0.transfers.clear()
        self.board.chip.ftm3.captures.clear()
        self._collect_telemetry()

    def _check_usb_open(self) -> None:
        """The USB host enumerated the board and opened its port during the start-up."""
        host = self.usb_host
        if host.error is not None:
            raise ImageFault(f"start-up: {host.error}")
        opened = [r for r in host.transfers if r.request == "SET_LINE_CODING" and r.status == "ok"]
        if not host.configured or not opened:
            done = host.transfers[-1].request if host.transfers else "nothing"
            raise ImageFault("start-up: the image's USB port was not enumerated and open by "
                             f"its first loop (the host's last request: {done}); an image "
                             "without USB flies with --link uart")

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

    def rc_schedule(self) -> tuple:
        """(the RC values last sent as pulses or None, frames since): what rc_pulses decides
        the next pulses by (PilFrames shares it)."""
        return self._rc_last, self._rc_age

    def set_rc_schedule(self, last, age: int) -> None:
        self._rc_last, self._rc_age = last, age

    def feed_telemetry(self, data: bytes) -> None:
        if not data:
            return
        if self.usb_host is not None:
            self.usb_host.send(data)
        else:
            self.board.receive(data)

    # -- one frame ---------------------------------------------------------------------------
    def frame(self, fifo: bytes, dmp: bool, rc_us, imu_fault: int, sync: bool):
        """Inputs in, one loop, outputs out: (motors, armed, mode, sensor kind); the motors
        are the thrust fractions of the rotors the loop flies (its rotor count's channels)."""
        outputs = self.begin_frame(fifo, dmp, rc_us, imu_fault)
        self.end_frame(sync)
        return outputs

    def begin_frame(self, fifo: bytes, dmp: bool, rc_us, imu_fault: int):
        """Inputs in, and the loop run until its step's outputs are final: (motors, armed,
        mode, sensor kind) as :meth:`frame` returns them. The rest of the loop (its
        telemetry, the USB stack's work) is :meth:`end_frame`'s, which the caller runs
        next, after answering with these if it likes: nothing the rest of the loop does
        changes them. An image without hq_step_outputs runs its whole loop here."""
        self.apply_imu_fault(imu_fault)
        if fifo:
            self.board.mpu.emu.push_fifo(bytes(fifo), dmp)
        self.rc_pulses(rc_us)
        self._mid_loop = self._run_to_wait(LOOP_LIMIT_S, f"loop {self.waits}",
                                           outputs=self._outputs_at is not None)
        return self.outputs()

    def end_frame(self, sync: bool, code: int | None = None) -> None:
        """The rest of the loop begun by :meth:`begin_frame`, to where the loop ends; the
        stored records kept; with ``sync``, the telemetry drained (:meth:`_drain`); the
        telemetry that left collected. ``code``: the rest began with a native run that
        returned it (a frame PilFrames handed over after its reply)."""
        if self._mid_loop or code is not None:
            self._mid_loop = False
            self._run_to_wait(LOOP_LIMIT_S, f"loop {self.waits}", code=code)
        self.keep_stored()
        if sync and not self.in_card_wait:     # a step is due now: no time to drain
            self._drain()
        self._loop_done()

    def keep_stored(self) -> None:
        """The stored records' files written back where the image changed their flash."""
        for kept in self.stored:
            kept.keep()

    def _loop_done(self) -> None:
        """A frame's end: the telemetry that left collected, the step's cycles recorded."""
        self._collect_telemetry()
        self.step_cycles.append(self.report()[1])

    def resume_begin(self, code: int):
        """:meth:`begin_frame` from a native run of its loop that returned ``code`` (a frame
        PilFrames handed over before its reply): the outputs."""
        self._mid_loop = self._run_to_wait(LOOP_LIMIT_S, f"loop {self.waits}",
                                           outputs=True, code=code)
        return self.outputs()

    def resume_drain(self, code: int, until: int, after: int) -> None:
        """:meth:`end_frame`'s drain from a native run of it that returned ``code`` (a sync
        frame PilFrames handed over there), on to where that run would have ended (the core
        cycle ``until``; ``after``: the cycle it started at), then the rest of end_frame."""
        self.keep_stored()
        stop = self.machine.after_run(code)
        if stop is None:
            drain = ("usb", after) if self.usb_host is not None else ("uart", None)
            stop = self.machine.run(until=until, drain=drain)
        self._waited(stop)
        self._loop_done()

    def native_config(self, sim_fd: int, tel_fd: int, system_id: int, component_id: int,
                      chunk: int, quiet_s: float):
        """The set-up of PilFrames (sim/chip/pil_frames.hpp), which runs this board's plain
        frames natively; None when it cannot (an image without hq_step_outputs). The RC
        pins' table only when the core can drive their pulses now (Teensy35.native_pins);
        without it, frames with pulses are Python's, and so are frames with a pulse on a pin
        the table leaves out."""
        if self._outputs_at is None:
            return None
        pins = self.board.native_pins({ch: PINS[RC_PINS[ch]] for ch in range(RC_CHANNELS)},
                                      driven_only=True)
        return {"sim_fd": sim_fd, "tel_fd": tel_fd, "outputs_at": self._outputs_at,
                "wait_at": self._wait_at,
                "card_wait_at": self._card_wait_step or 0,
                "report_address": self.report_address, "mpu": self.board.mpu.native,
                "usb": self.usb_host is not None,
                "rc_pins": None if pins is None else [pins.get(ch) for ch in range(RC_CHANNELS)],
                "esc_lo": ESC_MIN_US * FTM0_COUNTS_PER_US,
                "esc_hi": ESC_MAX_US * FTM0_COUNTS_PER_US, "loop_limit_s": LOOP_LIMIT_S,
                "drain_limit_s": DRAIN_LIMIT_S, "drain_margin_s": DRAIN_MARGIN_S,
                "system_id": system_id, "component_id": component_id,
                "telemetry_chunk": chunk, "quiet_ms": max(1, round(quiet_s * 1000))}

    def native_capable(self) -> bool:
        """Whether PilFrames can run this board's frames at all: an image with
        hq_step_outputs, and no log of every peripheral access (which is Python's)."""
        return self._outputs_at is not None and not self.machine.core.log_all

    def native_ready(self) -> bool:
        """Between frames, in the state PilFrames takes over: no IMU fault held, no loop
        begun and not finished."""
        return self._fault == dialect().HQ_IMU_FAULT_NONE and not self._mid_loop

    def outputs(self):
        """The last step's outputs: (motors, armed, mode, sensor kind)."""
        _, _, _, armed, mode, kind, _, rotors = self.report()
        return self.thrust()[:rotors], bool(armed), mode, kind

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

    def _drain(self) -> None:
        """Let the board run (it sleeps; UART0's TX interrupt feeds the UART, or the USB host
        polls the bulk IN endpoint) until nothing it queued is left to send: UART0 idle, or a
        bulk IN poll NAKed after the loop's flush. Then the loop's telemetry is on the wire.
        Never into the next loop, whose inputs are not in yet: at most until 20 us before the
        next SysTick (none at all when that tick is already pending: the loop overran), and
        at most DRAIN_LIMIT_S. What is still queued then leaves during the next frame, as the
        bytes of a loop that sent more than its period carries leave a board late."""
        m = self.machine
        systick = self.board.chip.scs.systick
        if m.pending & (1 << SYSTICK_EXCEPTION) or systick.zero_at is None:
            return
        start = m.now()
        deadline = min(start + int(DRAIN_LIMIT_S * m.core_hz),
                       systick.zero_at - int(DRAIN_MARGIN_S * m.core_hz))
        if deadline > start:        # one run, ended natively the moment the link has drained
            drain = ("usb", start) if self.usb_host is not None else ("uart", None)
            self._waited(m.run(seconds=(deadline - start) / m.core_hz, drain=drain))

    def thrust(self) -> list:
        """The thrust fractions all eight ESCs (FTM0 channels 0-7) get from the next PWM
        period on."""
        lo, hi = ESC_MIN_US * FTM0_COUNTS_PER_US, ESC_MAX_US * FTM0_COUNTS_PER_US
        commanded = self.board.chip.ftm0.commanded_values()[:len(ESC_PINS)]
        return [min(1.0, max(0.0, (counts - lo) / (hi - lo))) if counts is not None else 0.0
                for counts in commanded]

    def _collect_telemetry(self) -> None:
        chip = self.board.chip
        uart = self.board.take_telemetry()
        if self.usb_host is not None:     # UART0's bytes leave on pins nothing listens to
            uart = self.usb_host.take_received()
        self.telemetry_out += uart
        # A lockstep run is long: the models' inspection logs must not grow with it (the
        # native models keep none after the boot, see boot(); the pin model's level log is
        # Python's).
        chip.ports.level_log.clear()
