"""Benchmark: processor in the loop against the host build, one run each, same experiment.

Runs the same sine experiment (`heliquad sil`: the roll transfer function, mixer injection,
1 Hz, 0.05) on the host build and on the Teensy 3.5 image in the emulated MK64FX512 over each
of its links (`--link uart`, `--link usb`), and prints for each the frames per second of the
lockstep loop (wall time of the loop alone, start-up excluded) as a multiple of real time at
200 Hz; then each PIL run's rate as a ratio to the host build's measured in the same run (the
baseline) and USB's to UART0's, and where the PIL's time goes: the emulated board driven
alone for as many loops as the drop-in drives it (its share of a frame; the rest is the
lockstep around it), over each link, with the board's own counts per loop.

    python benchmarks/pil_speed.py [--cycles 30] [--elf PATH] [--board-loops 1000]

Figures are wall-clock ratios on a shared machine: they move with the load. Never a test.
"""

from __future__ import annotations

import argparse
import pathlib
import sys
import tempfile
import time

ROOT = pathlib.Path(__file__).resolve().parents[1]
LOOP_HZ = 200.0
LINKS = ("uart", "usb")
RUNS = [("host", "uart")] + [("teensy35", link) for link in LINKS]


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


def board_alone(elf: str, link: str, loops: int):
    """The emulated board driven loop by loop as the drop-in drives it (inputs in, one loop,
    outputs out), without the ptys, the codec or the simulator: wall time, and the board's
    own counts per loop (Machine.counts(): blocks, emu_start calls, native and Python
    accesses and events)."""
    from heliquad.sim.chip.pil.board import PilBoard
    from heliquad.sim.sensor.mpu6050_packets import raw_packet

    board = PilBoard(elf, link=link)
    board.boot()
    sample = raw_packet([0.01, -0.02, 0.005], [0.0, 0.0, -9.80665])
    rc = [1500, 1500, 1000, 1500, 2000, 1000, 0, 0]
    m = board.machine
    before = m.counts()
    t0 = time.perf_counter()
    for k in range(loops):
        board.frame(sample, False, rc, 0, sync=(k % 50 == 49))
        board.telemetry_out.clear()
    wall = time.perf_counter() - t0
    after = m.counts()
    return wall, {k: (after[k] - before[k]) / loops for k in after}


def board_report(elf: str, link: str, n: int, pil_rate: float):
    wall, per = board_alone(elf, link, n)
    board_rate = n / wall
    pil_frame_us = 1e6 / pil_rate
    print(f"\nthe emulated board alone over {link}, {n} loops driven as the drop-in drives "
          f"them: {board_rate:.0f} loops/s = {board_rate / LOOP_HZ:.2f}x real time, "
          f"{1e6 / board_rate:.0f} us a loop")
    print(f"  so of the PIL's {pil_frame_us:.0f} us a frame, the board takes "
          f"{1e6 / board_rate:.0f} us and the lockstep around it (ptys, codec, the simulator's "
          f"plant and telemetry tap) {pil_frame_us - 1e6 / board_rate:.0f} us")
    print(f"  per loop: {per['blocks']:.0f} blocks entered, {per['emu_starts']:.1f} emu_start "
          f"calls, {per['native_accesses']:.0f} native and {per['python_accesses']:.1f} Python "
          f"peripheral accesses, {per['native_events']:.1f} native and "
          f"{per['python_events']:.2f} Python events, {per['exceptions']:.1f} exceptions")


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--cycles", type=int, default=30,
                   help="full-amplitude cycles (default 30: a 33 s experiment; a shorter one "
                        "weighs the one-time costs of its first seconds, arming and the first "
                        "translation of each code path, more)")
    p.add_argument("--elf", help="the Teensy image (default: the installed or in-tree one)")
    p.add_argument("--board-loops", type=int, default=1000,
                   help="loops of the board driven alone (default 1000)")
    args = p.parse_args()
    from heliquad.sim.base.firmware_image import teensy35_image

    elf = args.elf or str(teensy35_image("elf"))
    print(f"image: {elf}")
    rates = {}
    with tempfile.TemporaryDirectory() as tmp:
        for fw, link in RUNS:
            name = fw if fw == "host" else f"{fw} {link}"
            r, total = run(fw, link, args.cycles, elf, str(pathlib.Path(tmp) / f"{fw}-{link}"))
            rate = r.frames / r.loop_s
            rates[name] = rate
            print(f"{name:14s}: {r.frames} frames ({r.frames / LOOP_HZ:.2f} s simulated); "
                  f"lockstep {r.loop_s:.2f} s wall = {rate:.0f} frames/s = "
                  f"{rate / LOOP_HZ:.2f}x real time; start-up and shutdown {total - r.loop_s:.2f} s")
    for link in LINKS:
        print(f"PIL over {link} / host lockstep rate: {rates[f'teensy35 {link}'] / rates['host']:.4f}")
    print(f"PIL over usb / over uart: {rates['teensy35 usb'] / rates['teensy35 uart']:.4f}")
    for link in LINKS:
        board_report(elf, link, args.board_loops, rates[f"teensy35 {link}"])
    print("  (benchmarks/teensy35_pil_speed.py --profile breaks the board's own time down)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
