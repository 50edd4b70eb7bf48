"""Benchmark: the whole demo (wall time, simulated time, real-time factor) and the identify
step on a 10-minute session.

The 10-minute session is a SIL sweep of the yaw band with the transfer-function plant, long
enough (cycles per frequency scaled) for about 600 s of logged flight; identify is timed
without and with delay fitting. Prints the figures; there is no target ratio.

    python benchmarks/campaign.py [--skip-demo]
"""

import argparse
import json
import re
import subprocess
import sys
import tempfile
import time


def heliquad(*args):
    return subprocess.run([sys.executable, "-m", "heliquad.host.cli", *map(str, args)],
                          capture_output=True, text=True, check=True)


def main():
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--skip-demo", action="store_true")
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        if not args.skip_demo:
            t0 = time.perf_counter()
            out = heliquad("demo", "--out", f"{tmp}/demo").stdout
            wall = time.perf_counter() - t0
            sim = float(re.search(r"([\d.]+) s simulated", out).group(1))
            print(f"demo (3 axes, vehicle, firmware in the loop): {wall:.0f} s wall, {sim:.0f} s "
                  f"simulated, {sim / wall:.1f}x real time")
        t0 = time.perf_counter()
        heliquad("sweep", "--axis", "yaw", "--sil", "--plant", "tf", "--cycles", 12,
                 "--out", f"{tmp}/long")
        sweep_wall = time.perf_counter() - t0
        m = json.load(open(f"{tmp}/long/manifest.json"))
        span = (m["frequencies"][-1]["end_us"] - m["frequencies"][0]["start_us"]) * 1e-6
        for extra in ([], ["--delay"]):
            t0 = time.perf_counter()
            heliquad("identify", f"{tmp}/long", *extra)
            print(f"identify{' --delay' if extra else ''} of a {span / 60:.1f}-minute session "
                  f"(sweep took {sweep_wall:.0f} s): {time.perf_counter() - t0:.1f} s")


if __name__ == "__main__":
    main()
