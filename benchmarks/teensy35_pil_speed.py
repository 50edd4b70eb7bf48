"""Benchmark: how fast the emulated Teensy 3.5 (sim/chip) runs the image's main loop, as a
processor-in-the-loop target would drive it.

From reset to the first loop, then a warm-up (every block decoded once), then N loops the
way a lockstep driver runs them: one raw IMU sample pushed into the MPU6050's FIFO per loop,
the run stopped at each ``hq::FlightController::step`` entry, the telemetry that left UART0
since the last loop taken (921600 baud, at line rate, the TX interrupt feeding the FIFO).
Reports:

* loops per second of wall time and the real-time factor at 200 Hz (loops/s over 200);
* per loop: instructions, busy cycles (the stated CPI model; sleep excluded), interrupts,
  telemetry bytes;
* where the wall time goes, per loop: translated blocks entered (unicorn's), runs of the CPU
  (uc_emu_start calls, or the engine's runs), peripheral accesses handled natively and in
  Python, events run natively and in Python, exceptions;
* with --profile, the Python functions that took the most time (cProfile, self time).

Wall-clock figures are this machine's; the counts are deterministic. The chip runs on its
default CPU, the engine; HQ_CHIP_CPU=unicorn measures unicorn.

    python benchmarks/teensy35_pil_speed.py [--loops 2000] [--profile] [--elf PATH]
"""

import argparse
import cProfile
import io
import pathlib
import pstats
import time

from heliquad.sim.chip import Teensy35

ROOT = pathlib.Path(__file__).resolve().parents[1]
DEFAULT_ELF = ROOT / "build" / "teensy35" / "heliquad-fw-teensy35.elf"
LOOP_HZ = 200
BOOT_BUDGET = 40_000_000
PER_LOOP_BUDGET = 200_000
WARM_UP = 50


def sample():
    from heliquad.sim.sensor.mpu6050_packets import raw_packet
    return raw_packet([0.01, -0.02, 0.005], [0.0, 0.0, -9.80665])


class Rig:
    """The board, driven one loop at a time."""

    def __init__(self, elf):
        self.board = Teensy35(elf)
        self.m = self.board.machine
        self.packet = sample()
        self.telemetry = 0
        stop = self.board.run_to_loop(1, instructions=BOOT_BUDGET)
        if stop.reason != "loop":
            raise SystemExit(f"the image did not reach its loop: {stop}")

    def loop(self):
        board = self.board
        board.mpu.emu.push_fifo(self.packet, False)
        stop = board.run_to_loop(board.loops + 1, instructions=PER_LOOP_BUDGET)
        if stop.reason != "loop":
            raise SystemExit(f"loop {board.loops}: {stop}")
        self.telemetry += len(board.take_telemetry())

    def snapshot(self):
        m = self.m
        c = m.counts()
        c.update(instructions=m.instructions, busy=m.cycles - m.sleep_cycles,
                 cycles=m.cycles, telemetry=self.telemetry,
                 interrupts=sum(m.exception_counts.values()))
        return c


def main():
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--loops", type=int, default=2000)
    parser.add_argument("--elf", type=pathlib.Path, default=DEFAULT_ELF)
    parser.add_argument("--profile", action="store_true",
                        help="also profile a second run of the loops (cProfile)")
    args = parser.parse_args()
    if not args.elf.exists():
        raise SystemExit(f"{args.elf} not found: cmake --preset teensy35 && cmake --build "
                         "--preset teensy35")
    t0 = time.perf_counter()
    rig = Rig(args.elf)
    boot = time.perf_counter() - t0
    for _ in range(WARM_UP):
        rig.loop()
    before = rig.snapshot()
    t0, c0 = time.perf_counter(), time.process_time()
    for _ in range(args.loops):
        rig.loop()
    wall, cpu = time.perf_counter() - t0, time.process_time() - c0
    after = rig.snapshot()
    n = args.loops
    per = {k: (after[k] - before[k]) / n for k in after}
    rate = n / wall
    simulated = (after["cycles"] - before["cycles"]) / rig.m.core_hz
    print(f"image: {args.elf.relative_to(ROOT) if args.elf.is_relative_to(ROOT) else args.elf}")
    print(f"boot to the first loop: {boot:.2f} s wall, {rig.board.loop_starts[0][0]} instructions")
    print(f"{n} loops after {WARM_UP} of warm-up: {wall:.3f} s wall for {simulated:.3f} s "
          f"simulated")
    print(f"loops per second of wall time: {rate:.0f}; real-time factor at {LOOP_HZ} Hz: "
          f"{rate / LOOP_HZ:.2f} (emulated time over wall time: {simulated / wall:.2f})")
    print(f"per loop: {per['instructions']:.0f} instructions, {per['busy']:.0f} busy cycles, "
          f"{per['interrupts']:.1f} interrupts, {per['telemetry']:.1f} telemetry bytes")
    print(f"per loop, where the time goes: {per['blocks']:.0f} blocks entered (unicorn's), "
          f"{per['emu_starts']:.1f} runs of the CPU, {per['native_accesses']:.0f} native and "
          f"{per['python_accesses']:.1f} Python peripheral accesses, {per['native_events']:.1f} "
          f"native and {per['python_events']:.2f} Python events, {per['exceptions']:.1f} "
          f"exceptions taken, {per['decodes']:.2f} blocks decoded, {per['fpu_checks']:.2f} "
          f"FPU-watch callbacks")
    print(f"wall time per loop: {1e6 * wall / n:.0f} us; this process's CPU time per loop: "
          f"{1e6 * cpu / n:.0f} us ({n / cpu:.0f} loops per CPU second: the figure to compare on "
          "a shared machine)")
    if args.profile:
        profiler = cProfile.Profile()
        profiler.enable()
        for _ in range(n):
            rig.loop()
        profiler.disable()
        out = io.StringIO()
        pstats.Stats(profiler, stream=out).sort_stats("tottime").print_stats(12)
        print("cProfile, by self time (the native run is inside Mk64Core.run):")
        print("\n".join(line for line in out.getvalue().splitlines()[4:] if line.strip()))


if __name__ == "__main__":
    main()
