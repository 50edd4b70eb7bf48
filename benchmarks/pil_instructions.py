"""Benchmark: the host instructions a loop of the emulated board alone, over each link, counted
by valgrind's callgrind: a figure that does not move with the machine's load, to compare two
builds of the emulator on a shared machine, where wall time moves by a factor of two.

Boots the Teensy image as the drop-in does (``PilBoard`` over each link), runs a warm-up, then
counts the host's instructions over N loops driven as the drop-in drives them (inputs in, one
loop, outputs out, a sync every 50th), as benchmarks/pil_speed.py drives the board alone; and
prints them a loop for each link, and USB's against UART0's. The count runs under valgrind
(some 50x slower than native): callgrind's instrumentation is switched on after the warm-up
and off after the loops (``callgrind_control``), so the boot is not counted. The loops'
counts, times and telemetry are those of a run without valgrind: the emulator reads no clock.

    python benchmarks/pil_instructions.py [--loops 200] [--elf PATH]

Needs valgrind (callgrind and callgrind_control). Never a test.
"""

from __future__ import annotations

import argparse
import os
import pathlib
import shutil
import subprocess
import sys
import tempfile
import time

LINKS = ("uart", "usb")
WARM_UP = 100
SYNC_EVERY = 50


def _callgrind(state: str) -> None:
    """Switch this process's instrumentation on or off. callgrind takes the command while the
    process runs, so it polls meanwhile instead of blocking in a wait."""
    control = subprocess.Popen(["callgrind_control", "-i", state, str(os.getpid())],
                               stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    while control.poll() is None:
        time.sleep(0.01)


def child(elf: str, link: str, loops: int) -> None:
    """Under valgrind: boot, warm up, and run ``loops`` counted loops."""
    # the drop-in's modules, only in the process valgrind runs
    from heliquad.sim.chip.pil.board import PilBoard
    from heliquad.sim.sensor.mpu6050_packets import raw_packet

    board = PilBoard(elf, link=link)
    board.boot()
    sample = raw_packet([0.01, -0.02, 0.005], [0.0, 0.0, -9.80665])
    rc = [1500, 1500, 1000, 1500, 2000, 1000, 0, 0]

    def run(n):
        for k in range(n):
            board.frame(sample, False, rc, 0, sync=(k % SYNC_EVERY == SYNC_EVERY - 1))
            board.telemetry_out.clear()

    run(WARM_UP)
    _callgrind("on")
    run(loops)
    _callgrind("off")


def counted(elf: str, link: str, loops: int) -> float:
    """The host instructions a loop over ``link``, from a run under callgrind."""
    with tempfile.TemporaryDirectory() as tmp:
        out = pathlib.Path(tmp) / "callgrind.out"
        cmd = ["valgrind", "--tool=callgrind", "--instr-atstart=no", "--smc-check=all-non-file",
               f"--callgrind-out-file={out}", sys.executable, __file__, "--elf", elf,
               "--loops", str(loops), "--child", link]
        subprocess.run(cmd, check=True, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        totals = [line for line in out.read_text().splitlines() if line.startswith("totals:")]
        return int(totals[0].split()[1]) / loops


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--loops", type=int, default=200, help="loops counted (default 200)")
    p.add_argument("--elf", help="the Teensy image (default: the installed or in-tree one)")
    p.add_argument("--child", choices=LINKS, help=argparse.SUPPRESS)
    args = p.parse_args()
    if args.child:
        child(args.elf, args.child, args.loops)
        return 0
    if not (shutil.which("valgrind") and shutil.which("callgrind_control")):
        raise SystemExit("valgrind (callgrind, callgrind_control) is not installed")
    from heliquad.sim.base.firmware_image import teensy35_image  # the installed image's path

    elf = args.elf or str(teensy35_image("elf"))
    print(f"image: {elf}")
    per = {}
    for link in LINKS:
        per[link] = counted(elf, link, args.loops)
        print(f"the board alone over {link}: {per[link] / 1e3:.1f}k host instructions a loop "
              f"({args.loops} loops after {WARM_UP} of warm-up)")
    print(f"usb / uart: {per['usb'] / per['uart']:.4f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
