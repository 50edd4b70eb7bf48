"""Benchmark: what an excitation costs the Teensy 3.5 image's loop, in the emulated MK64FX512.

Flies short sweeps of the roll transfer-function plant with the Teensy image in the emulated
chip (``heliquad sweep --sil --plant tf --firmware teensy35``): a sine dwell, a multisine of
4 lines and one of 15 (most of the 16 the firmware takes). From each log it reads the image's
own measurement of its loop (HQ_FW_STATUS, once a second: the median and the largest CPU
cycles of one loop's work, FlightController::step, over that second, from the cycle counter)
and sets the seconds at full amplitude against the seconds armed before the excitation, the
baseline measured in the same run. It prints, for each: the median cycles per loop and the
largest, each as a share of the 5 ms loop's budget (600 000 cycles at 120 MHz), and the
median's ratio to the baseline's.

The cycles are the emulator's stated cycle model (sim/chip/timing.py), not a board's: the
ratios between signals are what to read; a board's own HQ_FW_STATUS gives its absolute
figures (``heliquad log``).

    python benchmarks/teensy35_excitation_load.py [--rig-time 20]
"""

import argparse
import statistics
import subprocess
import sys
import tempfile

from heliquad.host.records.tlog import read_tlog_table
from heliquad.sim.base.dialect import dialect

BUDGET = 120e6 / 200                    # cycles of one 5 ms loop at 120 MHz
SWEEP = ("sweep", "--axis", "roll", "--sil", "--plant", "tf", "--firmware", "teensy35")


def signals(rig_time_s: float) -> dict:
    """Each signal's sweep options: a sine lasting about the multisines' rig time."""
    return {"sine 1 Hz": ("--freqs-hz", "1", "--cycles", str(max(3, int(rig_time_s) - 2))),
            "multisine, 4 lines": ("--signal", "multisine", "--lines", "4",
                                   "--rig-time", str(rig_time_s)),
            "multisine, 15 lines": ("--signal", "multisine", "--lines", "15",
                                    "--rig-time", str(rig_time_s))}


def loop_cycles(folder: str) -> tuple:
    """``(baseline, running)``: the HQ_FW_STATUS records' (median, largest) cycles per loop,
    armed before the excitation, and at its full amplitude."""
    d = dialect()
    status = read_tlog_table(f"{folder}/sweep.tlog", d, "HQ_FW_STATUS")
    running_at = [k for k, s in enumerate(status) if s.exc_state != d.HQ_EXCITATION_STATE_IDLE]
    before = status[:running_at[0]] if running_at else status
    idle = [(int(s.loop_cycles_median), int(s.loop_cycles_max)) for s in before if s.armed]
    running = [(int(s.loop_cycles_median), int(s.loop_cycles_max)) for s in status
               if s.exc_state == d.HQ_EXCITATION_STATE_RUNNING]
    if not idle or not running:
        raise SystemExit(f"{folder}: the log has {len(idle)} armed idle and {len(running)} "
                         "running seconds of HQ_FW_STATUS; both are needed")
    return idle, running


def main(argv=None) -> None:
    p = argparse.ArgumentParser(description=__doc__,
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--rig-time", type=float, default=20.0,
                   help="seconds of each multisine, fades included (default 20)")
    args = p.parse_args(argv)
    print(f"baseline: the same run's armed seconds before the excitation; budget "
          f"{BUDGET:.0f} cycles a loop")
    with tempfile.TemporaryDirectory() as tmp:
        for k, (name, options) in enumerate(signals(args.rig_time).items()):
            folder = f"{tmp}/{k}"
            res = subprocess.run([sys.executable, "-m", "heliquad.host.cli.parser", *SWEEP, *options,
                                  "--out", folder], capture_output=True, text=True)
            if res.returncode != 0:
                raise SystemExit(f"the {name} sweep failed: {res.stderr.strip()[-1000:]}")
            idle, running = loop_cycles(folder)
            base = statistics.median(m for m, _ in idle)
            med = statistics.median(m for m, _ in running)
            top = max(x for _, x in running)
            print(f"{name:>20}: {med:.0f} cycles a loop (load {med / BUDGET:.2%}), largest "
                  f"{top} ({top / BUDGET:.2%}); baseline {base:.0f} ({base / BUDGET:.2%}), "
                  f"ratio {med / base:.4f} over {len(running)} s")


if __name__ == "__main__":
    main()
