"""Benchmark: the linearity campaign's verdict over many seeds, with and without hinge
friction on the simulated rig.

For each friction value and seed: `heliquad sweep --sil --signal multisine --linearity`
(the axis's rig, the 6-DoF vehicle, mixer injection, the IMU's noise; turbulence if asked)
and `heliquad identify`, read back from models.json's `linearity`: per amplitude, whether
it is flagged, its distortion and noise (dB of the response), and the amplitude dependence.
Prints one row per run and, per friction value, how many seeds flagged each amplitude: the
frictionless rig's flags are false flags.

    python benchmarks/linearity.py [--axis roll] [--friction 0 0.002] [--seeds 20]
        [--turbulence light] [--keep DIR]
"""

import argparse
import json
import os
import shutil
import subprocess
import sys
import tempfile

from heliquad.sim.base.dialect import AXES


def heliquad(*args):
    res = subprocess.run([sys.executable, "-m", "heliquad.host.cli.parser", *map(str, args)],
                         capture_output=True, text=True)
    if res.returncode:
        raise SystemExit(f"heliquad {' '.join(map(str, args))}: {res.stderr.strip()}")
    return res


def one(folder, axis, friction, seed, turbulence):
    sweep = ["sweep", "--sil", "--axis", axis, "--signal", "multisine", "--linearity",
             "--seed", seed, "--hinge-friction", friction, "--out", folder]
    if turbulence:
        sweep += ["--turbulence", turbulence]
    heliquad(*sweep)
    heliquad("identify", folder)
    with open(os.path.join(folder, "models.json")) as fh:
        return json.load(fh)["linearity"]


def main():
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--axis", default="roll", choices=tuple(AXES))
    parser.add_argument("--friction", type=float, nargs="+", default=[0.0, 0.002])
    parser.add_argument("--seeds", type=int, default=20)
    parser.add_argument("--turbulence", choices=("light", "moderate", "severe"))
    parser.add_argument("--keep", metavar="DIR", help="keep the sweep folders here")
    args = parser.parse_args()
    base = args.keep or tempfile.mkdtemp(prefix="linearity-")
    print(f"{'N m':>7} {'seed':>4} | {'large: flag':>11} {'dist dB':>8} {'noise dB':>8} | "
          f"{'small: flag':>11} {'dist dB':>8} {'noise dB':>8} | {'dep dB':>6} {'deg':>6}",
          flush=True)
    for friction in args.friction:
        flags = [0, 0]
        for seed in range(1, args.seeds + 1):
            rec = one(os.path.join(base, f"{friction:g}-{seed}"), args.axis, friction, seed,
                      args.turbulence)
            cells = []
            for i, level in enumerate(rec["levels"]):
                flags[i] += bool(level["flagged"])
                cells.append(f"{'yes' if level['flagged'] else 'no':>11} "
                             f"{level['distortion_db']:8.1f} {level['noise_db']:8.1f}")
            dep = rec.get("amplitude_dependence", {})
            print(f"{friction:7.4g} {seed:4d} | {' | '.join(cells)} | "
                  f"{dep.get('max_db', float('nan')):6.2f} {dep.get('max_deg', float('nan')):6.1f}",
                  flush=True)
        print(f"friction {friction:g} N m: flagged at the large amplitude in {flags[0]} of "
              f"{args.seeds} seeds, at the small in {flags[1]} of {args.seeds}", flush=True)
    if not args.keep:
        shutil.rmtree(base)


if __name__ == "__main__":
    main()
