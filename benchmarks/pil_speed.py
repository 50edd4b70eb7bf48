"""Benchmark: processor in the loop against the host build, one run each, same experiment.

Runs the same sine experiment (`heliquad sil`: the roll transfer function, mixer injection,
1 Hz, 0.05) on the host build and on the Teensy 3.5 image in the emulated MK64FX512 over each
of its links (`--link uart`, `--link usb`) with each of the emulated chip's CPUs (unicorn and
the engine, sim/chip/cpu.py; `--cpus` chooses), and prints for each the frames per second of
the lockstep loop (wall time of the loop alone: from the firmware being up, after the
drop-in's Python start and the image's boot, to the run's end) as a multiple of real time at
200 Hz, and the whole run's with that start-up; then each PIL run's rate as a ratio to the host build's measured in the same run
(the baseline), USB's to UART0's and the engine's to unicorn's, and where the PIL's time goes:
the emulated board driven alone for as many loops as the drop-in drives it (its share of a
frame; the rest is the lockstep around it), for each CPU and link, with the board's own counts
per loop; last, those boards driven in turns with a sync every loop, so that they are compared
under the same load.

    python benchmarks/pil_speed.py [--cycles 30] [--elf PATH] [--board-loops 1000]
                                   [--cpus unicorn,engine] [--python-frames]

``--python-frames`` also flies each PIL run with every frame in the drop-in's Python path
(HQ_PIL_FRAMES=python; by default its plain frames run natively) and prints the native
path's rate as a ratio to it.

Figures are wall-clock ratios on a shared machine: they move with the load. Never a test.
"""

from __future__ import annotations

import argparse
import os
import pathlib
import sys
import tempfile
import time

ROOT = pathlib.Path(__file__).resolve().parents[1]
LOOP_HZ = 200.0
LINKS = ("uart", "usb")
CPUS = ("unicorn", "engine")
CPU_VARIABLE = "HQ_CHIP_CPU"    # the emulated chip's CPU, for this process and the drop-in's
FRAMES_VARIABLE = "HQ_PIL_FRAMES"   # the drop-in's frames: native (plain ones) or python
TURNS = 4                   # turns of the boards driven in turns (boards_in_turns)


def use_cpu(cpu: str):
    """The CPU every emulated chip made from now on runs (the drop-in inherits it)."""
    os.environ[CPU_VARIABLE] = cpu


def run(firmware: str, link: str, cycles: int, elf: str | None, out: str):
    from heliquad.host.acquire.experiment import run_sil
    from heliquad.sim.rig.setup import SilConfig

    cfg = SilConfig(axis="roll", inject="mixer", freq_hz=1.0, amplitude=0.05, cycles=cycles,
                    fade_cycles=1, firmware=firmware,
                    firmware_image=elf if firmware == "teensy35" else None,
                    firmware_link=link)
    t0 = time.perf_counter()
    r = run_sil(cfg, out, progress=lambda *_: None)
    return r, time.perf_counter() - t0


def _board_inputs():
    """A loop's inputs for a board driven alone: a level, still IMU sample; RC sticks
    centred, throttle low, disarmed."""
    from heliquad.sim.sensor.mpu6050_packets import raw_packet

    return (raw_packet([0.01, -0.02, 0.005], [0.0, 0.0, -9.80665]),
            [1500, 1500, 1000, 1500, 2000, 1000, 0, 0])


def board_alone(elf: str, cpu: str, link: str, loops: int):
    """The emulated board driven loop by loop as the drop-in drives it (inputs in, one loop,
    outputs out), without the ptys, the codec or the simulator: wall time, and the board's
    own counts per loop (Machine.counts(): blocks, runs of the CPU, native and Python
    accesses and events)."""
    from heliquad.sim.chip.pil.board import PilBoard

    use_cpu(cpu)
    board = PilBoard(elf, link=link)
    board.boot()
    sample, rc = _board_inputs()
    m = board.machine
    before = m.counts()
    t0 = time.perf_counter()
    for k in range(loops):
        board.frame(sample, False, rc, 0, sync=(k % 50 == 49))
        board.telemetry_out.clear()
    wall = time.perf_counter() - t0
    after = m.counts()
    return wall, {k: (after[k] - before[k]) / loops for k in after}


def boards_in_turns(elf: str, cpus, loops: int, turns: int = TURNS) -> dict:
    """The board for each CPU and link, booted once each and driven in turns (``turns`` turns
    of ``loops`` loops, a sync every loop as the lockstep asks for its telemetry): each one's
    wall time a loop. Turns taken in the same minutes see the same load on a shared
    machine, which the runs one after the other above do not."""
    from heliquad.sim.chip.pil.board import PilBoard

    sample, rc = _board_inputs()
    boards = {}
    for cpu in cpus:
        use_cpu(cpu)
        for link in LINKS:
            boards[cpu, link] = PilBoard(elf, link=link)
    wall = dict.fromkeys(boards, 0.0)
    for board in boards.values():
        board.boot()
    for _ in range(turns):
        for key, board in boards.items():
            t0 = time.perf_counter()
            for _ in range(loops):
                board.frame(sample, False, rc, 0, sync=True)
                board.telemetry_out.clear()
            wall[key] += time.perf_counter() - t0
    return {key: wall[key] / (turns * loops) for key in boards}


def board_report(elf: str, cpu: str, link: str, n: int, pil_rate: float):
    wall, per = board_alone(elf, cpu, link, n)
    board_rate = n / wall
    pil_frame_us = 1e6 / pil_rate
    print(f"\nthe emulated board alone ({cpu}) over {link}, {n} loops driven as the drop-in drives "
          f"them: {board_rate:.0f} loops/s = {board_rate / LOOP_HZ:.2f}x real time, "
          f"{1e6 / board_rate:.0f} us a loop")
    print(f"  so of the PIL's {pil_frame_us:.0f} us a frame, the board takes "
          f"{1e6 / board_rate:.0f} us and the lockstep around it (ptys, codec, the simulator's "
          f"plant and telemetry tap) {pil_frame_us - 1e6 / board_rate:.0f} us")
    print(f"  per loop: {per['blocks']:.0f} blocks entered (unicorn's), {per['emu_starts']:.1f} "
          f"runs of the CPU, {per['native_accesses']:.0f} native and {per['python_accesses']:.1f} Python "
          f"peripheral accesses, {per['native_events']:.1f} native and "
          f"{per['python_events']:.2f} Python events, {per['exceptions']:.1f} exceptions")


def _cpus(text: str):
    cpus = tuple(c for c in text.split(",") if c)
    bad = [c for c in cpus if c not in CPUS]
    if bad or not cpus:
        raise argparse.ArgumentTypeError(f"CPUs are {', '.join(CPUS)}, comma-separated")
    return cpus


def pil_runs(elf: str, cpus, cycles: int, frame_paths=("native",)) -> dict:
    """The experiment on the host build, then on the image for each CPU, link and frame
    path (the Python path's runs named "... python-frames"): each run's lockstep rate
    (frames a second of wall time), printed as it comes."""
    rates = {}
    runs = [("host", "host", "uart", "native")] + [
        (f"{cpu} {link}" + ("" if path == "native" else " python-frames"), cpu, link, path)
        for cpu in cpus for link in LINKS for path in frame_paths]
    with tempfile.TemporaryDirectory() as tmp:
        for name, cpu, link, path in runs:
            os.environ[FRAMES_VARIABLE] = path
            if cpu != "host":
                use_cpu(cpu)
            fw = "host" if cpu == "host" else "teensy35"
            r, total = run(fw, link, cycles, elf, str(pathlib.Path(tmp) / name.replace(" ", "-")))
            rate = r.frames / r.loop_s
            rates[name] = rate
            print(f"{name:28s}: {r.frames} frames ({r.frames / LOOP_HZ:.2f} s simulated); "
                  f"lockstep {r.loop_s:.2f} s wall = {rate:.0f} frames/s = "
                  f"{rate / LOOP_HZ:.2f}x real time; start-up and shutdown {total - r.loop_s:.2f} s "
                  f"(with them {r.frames / LOOP_HZ / total:.2f}x)")
    return rates


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--cycles", type=int, default=30,
                   help="full-amplitude cycles (default 30: a 33 s experiment; a shorter one "
                        "weighs the one-time costs of its first seconds, arming and the first "
                        "translation of each code path, more)")
    p.add_argument("--elf", help="the Teensy image (default: the installed or in-tree one)")
    p.add_argument("--board-loops", type=int, default=1000,
                   help="loops of the board driven alone (default 1000)")
    p.add_argument("--cpus", type=_cpus, default=CPUS,
                   help="the emulated chip's CPUs to measure, comma-separated (default "
                        "unicorn,engine)")
    p.add_argument("--python-frames", action="store_true",
                   help="also fly each PIL run with every frame in the drop-in's Python path "
                        "(its plain frames run natively otherwise), and compare")
    args = p.parse_args()
    from heliquad.sim.base.firmware_image import teensy35_image

    elf = args.elf or str(teensy35_image("elf"))
    print(f"image: {elf}")
    rates = pil_runs(elf, args.cpus, args.cycles,
                     ("native", "python") if args.python_frames else ("native",))
    for cpu in args.cpus:
        for link in LINKS:
            if args.python_frames:
                print(f"PIL ({cpu}) over {link}, native frames / Python frames: "
                      f"{rates[f'{cpu} {link}'] / rates[f'{cpu} {link} python-frames']:.4f}")
        for link in LINKS:
            print(f"PIL ({cpu}) over {link} / host lockstep rate: "
                  f"{rates[f'{cpu} {link}'] / rates['host']:.4f}")
        print(f"PIL ({cpu}) over usb / over uart: {rates[f'{cpu} usb'] / rates[f'{cpu} uart']:.4f}")
    if set(CPUS) <= set(args.cpus):
        for link in LINKS:
            print(f"PIL over {link}, engine / unicorn: "
                  f"{rates[f'engine {link}'] / rates[f'unicorn {link}']:.4f}")
    for cpu in args.cpus:
        for link in LINKS:
            board_report(elf, cpu, link, args.board_loops, rates[f"{cpu} {link}"])
    loops = max(1, args.board_loops // TURNS)
    per_loop = boards_in_turns(elf, args.cpus, loops)
    print(f"\nthe boards driven in turns ({TURNS} turns of {loops} loops each, a sync every "
          "loop): " + ", ".join(f"{cpu} {link} {1e6 * t:.0f} us a loop"
                               for (cpu, link), t in per_loop.items()))
    print("  (benchmarks/teensy35_pil_speed.py --profile breaks the board's own time down)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
