"""Benchmark: the Teensy 3.5 image's main loop in the emulated MK64FX512 (sim/chip).

Runs the image as built (build/teensy35/heliquad-fw-teensy35.elf, the preset's
optimisation level, read from the build's CMakeCache.txt) from reset through N loops, with
the emulated MPU6050 producing one raw FIFO sample per loop (a level vehicle at rest, a
little rotation) so the attitude filter and the cascade run, and reports:

* instructions per ``hq::FlightController::step`` (the step's own, interrupt handlers that
  ran meanwhile excluded): median and maximum over the loops;
* instructions per loop including interrupts (step entry to the next step entry, sleep
  excluded: it retires none), and interrupts per loop;
* core cycles per loop by the emulator's stated cycle model (sim/chip/timing.py), against
  the baseline of the loop's budget at 200 Hz: 600 000 cycles at 120 MHz (the ratio is the
  loop's CPU load, estimated);
* the stack high-water mark: the stack region (from the end of .bss to the initial SP) is
  painted before reset and the deepest overwritten word found after the run;
* the emulator's own speed: instructions per second of wall time and the real-time factor
  (simulated over wall time), the only wall-clock figures here.

    python benchmarks/teensy35_cycles.py [--loops 400] [--elf PATH] [--build]
"""

import argparse
import os
import pathlib
import statistics
import subprocess
import sys
import time

from heliquad.sim.chip import Teensy35
from heliquad.sim.chip.machine import Stop

ROOT = pathlib.Path(__file__).resolve().parents[1]
DEFAULT_ELF = ROOT / "build" / "teensy35" / "heliquad-fw-teensy35.elf"
LOOP_HZ = 200
CORE_HZ = 120e6
PAINT = 0xDEADBEEF
BOOT_BUDGET = 40_000_000
# The I2C backend's transfers: each byte's wait sleeps until the I2C0 interrupt (it polled
# before), so what is left in them is the driver's own work; the step's figure is also given
# without them.
I2C_TRANSFERS = ("hq::teensy::I2c0Bus::read", "hq::teensy::I2c0Bus::write")
PER_LOOP_BUDGET = 200_000


def optimisation(elf: pathlib.Path) -> str:
    cache = elf.parent / "CMakeCache.txt"
    if not cache.exists():
        return "unknown (no CMakeCache.txt beside the image)"
    values = {}
    for line in cache.read_text().splitlines():
        if ":" in line and "=" in line and not line.startswith(("#", "//")):
            key, value = line.split("=", 1)
            values[key.split(":")[0]] = value
    build_type = values.get("CMAKE_BUILD_TYPE", "")
    flags = values.get(f"CMAKE_CXX_FLAGS_{build_type.upper()}", "")
    return f"{build_type} ({flags.strip() or 'no flags'})"


def imu_sample():
    """One raw FIFO packet of a level vehicle at rest, rotating a little (None when the
    packet encoders are not built)."""
    try:
        from heliquad.sim.sensor.mpu6050_packets import raw_packet
    except ImportError:
        return None
    return raw_packet([0.01, -0.02, 0.005], [0.0, 0.0, -9.80665])


class I2cTransferTime:
    """Instructions inside the I2C backend's transfers (interrupt handlers excluded), summed,
    and that sum at each step's entry and exit."""

    def __init__(self, machine):
        self.total = 0
        self.at_step_entry, self.at_step_exit = [], []
        self._call = None
        self._returns = set()
        for name in I2C_TRANSFERS:
            if machine.image.has(name):
                machine.break_at(name, self._transfer_entry)

    def _transfer_entry(self, machine):
        lr = machine.reg("lr") & ~1
        self._call = (machine.instructions_now(), machine.handler_instructions)
        if lr not in self._returns:
            self._returns.add(lr)
            machine.break_at(lr, self._transfer_exit)
        return None

    def _transfer_exit(self, machine):
        if self._call is not None:
            i0, h0 = self._call
            self._call = None
            self.total += (machine.instructions_now() - i0) - (machine.handler_instructions - h0)
        return None

    def step_entry(self, machine):
        self.at_step_entry.append(self.total)

    def step_exit(self, machine):
        self.at_step_exit.append(self.total)


class StepProbe:
    """Breakpoints on ``hq::FlightController::step``: the machine's counters at each entry
    and exit (instructions, handler instructions, cycles, sleep cycles, exceptions taken), an
    IMU sample pushed at each entry, and a stop after ``loops`` + 1 entries."""

    def __init__(self, board, loops: int, sample, i2c: I2cTransferTime):
        self.board, self.loops, self.sample, self.i2c = board, loops, sample, i2c
        self.entries, self.exits = [], []
        board.machine.break_at("hq::FlightController::step", i2c.step_entry)
        board.machine.break_at("hq::FlightController::step", self._entry)

    def _snapshot(self):
        m = self.board.machine
        return (m.instructions_now(), m.handler_instructions, m.now(), m.sleep_cycles,
                sum(n for exc, n in m.exception_counts.items()))

    def _entry(self, machine):
        if not self.entries:
            ret = machine.reg("lr") & ~1                        # the step's return address
            machine.break_at(ret, self.i2c.step_exit)
            machine.break_at(ret, self._exit)
        self.entries.append(self._snapshot())
        if self.sample is not None and self.board.mpu is not None:
            self.board.mpu.emu.push_fifo(self.sample, False)
        if len(self.entries) > self.loops:
            return Stop("done", machine.pc)
        return None

    def _exit(self, machine):
        self.exits.append(self._snapshot())
        return None


def i2c_bytes_per_loop(i2c, entries):
    """Bytes on the I2C bus (address bytes included) between consecutive step entries."""
    starts = [e[2] for e in entries]
    per_loop = [0] * (len(starts) - 1)
    for t in i2c.transfers:
        for k in range(len(starts) - 1):
            if starts[k] <= t.start_cycle < starts[k + 1]:
                per_loop[k] += 1 + len(t.data)
    return per_loop


def measure(elf: pathlib.Path, loops: int):
    """Run the image through ``loops`` + 1 steps; the figures of every loop after the first."""
    board = Teensy35(elf)
    m = board.machine
    stack_lo, stack_hi = m.image.ram_end(), m.image.initial_sp
    m.paint(stack_lo, stack_hi, PAINT)
    sample = imu_sample()
    i2c_time = I2cTransferTime(m)
    probe = StepProbe(board, loops, sample, i2c_time)
    t0 = time.perf_counter()
    stop = m.run(instructions=BOOT_BUDGET + PER_LOOP_BUDGET * (loops + 1))
    wall = time.perf_counter() - t0
    if stop.reason != "done":
        raise SystemExit(f"the image did not run {loops} loops: {stop} "
                         f"(fatal code {board.fatal_code})")
    entries, exits = probe.entries, probe.exits
    steps = [(x[0] - e[0]) - (x[1] - e[1]) for e, x in zip(entries, exits)]
    step_i2c = [b - a for a, b in zip(i2c_time.at_step_entry, i2c_time.at_step_exit)]
    loop_pairs = list(zip(entries, entries[1:]))
    return {
        "board": board, "wall": wall, "steps": steps[1:],
        "per_loop": [b[0] - a[0] for a, b in loop_pairs][1:],
        "busy": [(b[2] - a[2]) - (b[3] - a[3]) for a, b in loop_pairs][1:],
        "irqs": [b[4] - a[4] for a, b in loop_pairs][1:],
        "stack": stack_hi - m.painted_high_water(stack_lo, stack_hi, PAINT),
        "stack_region": stack_hi - stack_lo, "instructions": m.instructions,
        "simulated": m.seconds(), "fed": sample is not None,
        "imu": board.mpu.emu.raw_fifo_enabled or board.mpu.emu.dmp_enabled,
        "i2c_bytes": i2c_bytes_per_loop(board.chip.i2c0, entries)[1:],
        "scl_hz": board.chip.i2c0.scl_hz(), "step_i2c": step_i2c[1:len(steps)],
    }


def main():
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--loops", type=int, default=400)
    parser.add_argument("--elf", type=pathlib.Path, default=DEFAULT_ELF)
    parser.add_argument("--build", action="store_true",
                        help="build the image with the teensy35 preset first")
    args = parser.parse_args()
    if args.build:
        for cmd in (["cmake", "--preset", "teensy35", f"-DPython3_EXECUTABLE={sys.executable}"],
                    ["cmake", "--build", "--preset", "teensy35"]):
            subprocess.run(cmd, cwd=ROOT, check=True)
    if not args.elf.exists():
        raise SystemExit(f"{args.elf} not found: build it (cmake --preset teensy35 && cmake "
                         "--build --preset teensy35) or pass --build")
    r = measure(args.elf, args.loops)
    budget = CORE_HZ / LOOP_HZ
    med = statistics.median
    print(f"image: {os.path.relpath(args.elf, ROOT)}, {optimisation(args.elf)}")
    print(f"loops measured: {len(r['steps'])} (after the first), IMU samples fed: "
          f"{'yes' if r['fed'] else 'no'}, IMU configured: {'yes' if r['imu'] else 'no'}")
    print(f"instructions per FlightController::step: median {med(r['steps']):.0f}, "
          f"max {max(r['steps'])}")
    if r["step_i2c"]:
        rest = [a - b for a, b in zip(r["steps"], r["step_i2c"])]
        print(f"  of which in the I2C transfers:          median {med(r['step_i2c']):.0f}, "
              f"max {max(r['step_i2c'])}; the rest: median {med(rest):.0f}, max {max(rest)}")
    print(f"instructions per loop incl. interrupts:  median {med(r['per_loop']):.0f}, "
          f"max {max(r['per_loop'])}; interrupts per loop: median {med(r['irqs']):.0f}, "
          f"max {max(r['irqs'])}")
    print(f"cycles per loop (stated CPI model):      median {med(r['busy']):.0f}, "
          f"max {max(r['busy'])}")
    i2c_s = med(r["i2c_bytes"]) * 9 / r["scl_hz"]
    print(f"I2C per loop: median {med(r['i2c_bytes']):.0f} bytes, {i2c_s * 1e3:.3f} ms of bus "
          f"time at {r['scl_hz'] / 1e3:.0f} kHz ({i2c_s * CORE_HZ:.0f} cycles of the loop, which the "
          "driver sleeps through)")
    print(f"baseline: the 200 Hz loop's budget, {budget:.0f} cycles at 120 MHz")
    print(f"ratio (loop load, estimated):            median {med(r['busy']) / budget:.4f}, "
          f"max {max(r['busy']) / budget:.4f}")
    print(f"stack high-water mark: {r['stack']} bytes of a {r['stack_region']}-byte region")
    speed = r["instructions"] / r["wall"]
    print(f"emulator: {r['instructions']} instructions in {r['wall']:.2f} s wall "
          f"({speed / 1e6:.2f} M instructions/s), {r['simulated']:.3f} s simulated "
          f"(real-time factor {r['simulated'] / r['wall']:.2f})")


if __name__ == "__main__":
    main()
