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
* the frame's RC channels become servo pulses on the seven RC pins (as a 50 Hz receiver
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
  (:class:`~.param_file.ParamFile`).

Time is the emulated chip's: core cycles from retired instructions (sim/chip/timing.py
states the cycle model) and device events, never the host's clock, so two runs of the same
frames give the same bytes. A watchdog reset reboots the emulated board as it would the
real one (counted, and said on stderr); a fault of the image (bus fault, undefined
instruction, ``hq_fatal``) ends the run with one line on stderr and exit code 5.

This is the firmware's side of the sim link, not a driver of a plant: the lockstep driver
(:class:`heliquad.sim.rig.driver.Rig`) starts it as it starts heliquad-fw-host. Its modules:
:mod:`.board` (:class:`~.board.PilBoard`: one frame in the emulated chip), :mod:`.param_file`
(the ``--params`` flash file), :mod:`.pty` (the two published ptys), :mod:`.drop_in` (the
server loop behind them) and :mod:`.program` (the command line and its exit codes).
"""
