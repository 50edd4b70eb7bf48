"""Benchmark: processor in the loop against the host build, one run each, same experiment.

Runs the same sine experiment (`heliquad sil`: the roll transfer function, mixer injection,
1 Hz, 0.05) on the host build and on the Teensy 3.5 image in the emulated MK64FX512, and
prints for each the frames per second of the lockstep loop (wall time of the loop alone,
start-up excluded) as a multiple of real time at 200 Hz; then the PIL's rate as a ratio to
the host build's measured in the same run (the baseline), and where the PIL's time goes: the
emulated board driven in this process for the same number of loops under cProfile, its time
split into unicorn's own execution, the harness's callbacks (block accounting, peripheral
accesses, exceptions, events) and the rest.

    python benchmarks/pil_speed.py [--cycles 10] [--elf PATH] [--profile-loops 400]

Figures are wall-clock ratios on a shared machine: they move with the load. Never a test.
"""

from __future__ import annotations

import argparse
import cProfile
import pathlib
import pstats
import sys
import tempfile
import time

ROOT = pathlib.Path(__file__).resolve().parents[1]
LOOP_HZ = 200.0


def run(firmware: str, cycles: int, elf: str | None, out: str):
    from heliquad.sim.sil import SilConfig, run_sil

    cfg = SilConfig(axis="roll", inject="mixer", freq_hz=1.0, amplitude=0.05, cycles=cycles,
                    fade_cycles=1, firmware=firmware,
                    firmware_image=elf if firmware == "teensy35" else None)
    t0 = time.perf_counter()
    r = run_sil(cfg, out, progress=lambda *_: None)
    return r, time.perf_counter() - t0


def profile(elf: str, loops: int):
    """The emulated board alone, driven loop by loop as the drop-in drives it."""
    from heliquad.sim.mpu6050_packets import raw_packet
    from heliquad.sim.pil import PilBoard

    board = PilBoard(elf)
    board.boot()
    sample = raw_packet([0.01, -0.02, 0.005], [0.0, 0.0, -9.80665])
    rc = [1500, 1500, 1000, 1500, 2000, 1000, 0, 0]
    prof = cProfile.Profile()
    t0 = time.perf_counter()
    prof.enable()
    for k in range(loops):
        board.frame(sample, False, rc, 0, sync=(k % 50 == 49))
        board.telemetry_out.clear()
    prof.disable()
    wall = time.perf_counter() - t0
    return wall, pstats.Stats(prof)


def split(stats: pstats.Stats):
    """Own time (tottime) grouped: unicorn's emu_start, the harness (sim/mk64 and the
    drop-in), everything else."""
    groups = {"unicorn emu_start (emulation, native hooks)": 0.0,
              "harness: sim/mk64 models and hooks": 0.0, "drop-in (sim/pil.py)": 0.0,
              "other": 0.0}
    for (path, _, name), (_, _, tottime, _, _) in stats.stats.items():
        if name == "emu_start" or "unicorn" in path:
            groups["unicorn emu_start (emulation, native hooks)"] += tottime
        elif "/mk64/" in path:
            groups["harness: sim/mk64 models and hooks"] += tottime
        elif path.endswith("pil.py"):
            groups["drop-in (sim/pil.py)"] += tottime
        else:
            groups["other"] += tottime
    return groups


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--cycles", type=int, default=10, help="full-amplitude cycles (default 10)")
    p.add_argument("--elf", help="the Teensy image (default: the installed or in-tree one)")
    p.add_argument("--profile-loops", type=int, default=400)
    args = p.parse_args()
    from heliquad.sim.firmware_image import teensy35_image

    elf = args.elf or str(teensy35_image("elf"))
    print(f"image: {elf}")
    rates = {}
    with tempfile.TemporaryDirectory() as tmp:
        for fw in ("host", "teensy35"):
            r, total = run(fw, args.cycles, elf, str(pathlib.Path(tmp) / fw))
            rate = r.frames / r.loop_s
            rates[fw] = rate
            print(f"{fw:9s}: {r.frames} frames ({r.frames / LOOP_HZ:.2f} s simulated); lockstep "
                  f"{r.loop_s:.2f} s wall = {rate:.0f} frames/s = {rate / LOOP_HZ:.2f}x real "
                  f"time; start-up and shutdown {total - r.loop_s:.2f} s")
    print(f"PIL / host lockstep rate: {rates['teensy35'] / rates['host']:.4f}")
    wall, stats = profile(elf, args.profile_loops)
    print(f"\nthe emulated board alone, {args.profile_loops} loops under cProfile: {wall:.2f} s "
          f"wall ({args.profile_loops / LOOP_HZ / wall:.2f}x real time with the profiler's "
          "overhead)")
    groups = split(stats)
    total = sum(groups.values()) or 1.0
    for name, t in groups.items():
        print(f"  {name:45s} {t:6.2f} s  {100 * t / total:5.1f} %")
    print("\ntop functions by own time:")
    stats.sort_stats("tottime").print_stats(12)
    return 0


if __name__ == "__main__":
    sys.exit(main())
