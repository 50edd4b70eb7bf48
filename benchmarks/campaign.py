"""Benchmark: the desk time of a campaign, section by section.

* demo: ``heliquad demo`` (three axes side by side, the vehicle, the firmware in the loop):
  its wall time, its simulated time, and its ratio to the lockstep-only time of the same
  schedule. Lockstep-only means the demo's six sweeps alone (the same plans, rigs, sensor
  and seed: ``heliquad sweep --axis AXIS --sil --seed 1``, then the tuning sweeps with
  ``--tuning-band``), each three side by side as the demo runs its axes, with no identify,
  validate, tune, verify or report: the time the firmware-in-the-loop flying itself takes.
  The ratio says how much the demo adds to it (1.0: nothing); the verifications' sweeps,
  flown one axis after the other once the three are done, are part of what it adds.
* identify: ``heliquad identify`` of a 10-minute session (a SIL sweep of the yaw band with
  the transfer-function plant and 12 cycles a frequency, about 600 s of logged flight),
  with delay fitting (the default) and without (``--no-delay``).
* sil: the fixed cost of a ``heliquad sil`` run, what it pays before and after its lockstep
  whatever the run's length: a short run (1.75 s simulated) against a long one (45.5 s),
  ``fixed = t_short - (t_long - t_short) * sim_short / (sim_long - sim_short)``, the short
  run's time less its share of the lockstep at the rate the difference between the two
  shows.

* rig: the rig time per axis for the paper's dwell and for one multisine at equal accuracy
  (``benchmarks/rig_time.py``, its own docstring says how; ``--repeat`` seeds under
  turbulence).

Each figure is the median of ``--repeat`` runs (default 3); the machine's other load moves
them, so compare figures taken in one run. There are no targets here; the tests never
measure speed.

    python benchmarks/campaign.py [--skip demo] [--skip identify] [--skip sil] [--skip rig]
                                  [--repeat N]
"""

from __future__ import annotations

import argparse
import json
import re
import statistics
import subprocess
import sys
import tempfile
import time

from heliquad.host.records import paper

AXES = tuple(paper.BANDS_HZ)    # the demo's axes
DEMO_SEED = 1                   # heliquad demo's default seed
SIL_COMMON = ("--axis", "roll", "--inject", "mixer", "--amplitude", 0.05, "--fade-cycles", 1)
SIL_SHORT = ("--freq-hz", 10, "--cycles", 1)
SIL_LONG = ("--freq-hz", 0.5, "--cycles", 20)


def command(*args) -> list:
    return [sys.executable, "-m", "heliquad.host.cli.parser", *map(str, args)]


def heliquad(*args) -> tuple:
    """Run ``heliquad ARGS``: (wall seconds, stdout); fails loudly if it fails."""
    t0 = time.perf_counter()
    res = subprocess.run(command(*args), capture_output=True, text=True)
    wall = time.perf_counter() - t0
    if res.returncode != 0:
        raise SystemExit(f"heliquad {' '.join(map(str, args))} failed ({res.returncode}): "
                         f"{res.stderr.strip()[-2000:]}")
    return wall, res.stdout


def side_by_side(commands: list) -> float:
    """Wall seconds of the commands run at once, each in a process of its own."""
    t0 = time.perf_counter()
    procs = [subprocess.Popen(c, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
             for c in commands]
    for proc, c in zip(procs, commands):
        _, err = proc.communicate()
        if proc.returncode != 0:
            raise SystemExit(f"{' '.join(c)} failed ({proc.returncode}): {err[-2000:]}")
    return time.perf_counter() - t0


def simulated_s(folder) -> float:
    """A sweep folder's simulated time, from its manifest: the first frequency's start to
    the last one's end (the hover before it excluded)."""
    with open(f"{folder}/manifest.json") as fh:
        f = json.load(fh)["frequencies"]
    return (f[-1]["end_us"] - f[0]["start_us"]) * 1e-6


def demo_section(tmp: str, repeat: int) -> None:
    walls, ratios, sims = [], [], []
    for i in range(repeat):
        wall, out = heliquad("demo", "--out", f"{tmp}/demo{i}")
        sims.append(float(re.search(r"([\d.]+) s simulated", out).group(1)))
        lockstep = sum(side_by_side([command("sweep", "--axis", axis, "--sil", "--seed",
                                             DEMO_SEED, *band, "--out",
                                             f"{tmp}/sweeps{i}/{axis}{name}")
                                     for axis in AXES])
                       for name, band in (("", ()), ("-tuning", ("--tuning-band",))))
        walls.append(wall)
        ratios.append(wall / lockstep)
    sweeps = {axis: (simulated_s(f"{tmp}/sweeps0/{axis}"),
                     simulated_s(f"{tmp}/sweeps0/{axis}-tuning")) for axis in AXES}
    print(f"demo (3 axes side by side): {statistics.median(walls):.1f} s wall "
          f"({', '.join(f'{w:.1f}' for w in walls)}), {sims[0]:.0f} s simulated, "
          f"{sims[0] / statistics.median(walls):.1f}x real time")
    print(f"  against its lockstep alone (the same sweeps side by side, nothing else): "
          f"{statistics.median(ratios):.2f}x ({', '.join(f'{r:.2f}' for r in ratios)}); "
          "the sweeps' measured flight (paper's band + tuning band): "
          + ", ".join(f"{axis} {a:.0f} + {b:.0f} s" for axis, (a, b) in sweeps.items()))


def identify_section(tmp: str, repeat: int) -> None:
    session = f"{tmp}/long"
    sweep_wall, _ = heliquad("sweep", "--axis", "yaw", "--sil", "--plant", "tf", "--cycles", 12,
                             "--out", session)
    span = simulated_s(session)
    print(f"identify of a {span / 60:.1f}-minute session (its sweep took {sweep_wall:.0f} s):")
    for label, extra in (("with delay (the default)", ()), ("--no-delay", ("--no-delay",))):
        walls = [heliquad("identify", session, *extra)[0] for _ in range(repeat)]
        print(f"  {label}: {statistics.median(walls):.2f} s "
              f"({', '.join(f'{w:.2f}' for w in walls)})")


def sil_section(tmp: str, repeat: int) -> None:
    runs = {"short": [], "long": []}
    for i in range(repeat):
        for name, extra in (("short", SIL_SHORT), ("long", SIL_LONG)):
            wall, out = heliquad("sil", *SIL_COMMON, *extra, "--out", f"{tmp}/{name}{i}")
            sim = float(re.search(r"\(([\d.]+) s simulated\)", out).group(1))
            runs[name].append((wall, sim))
    (t_s, sim_s), (t_l, sim_l) = ((statistics.median(w for w, _ in runs[n]), runs[n][0][1])
                                  for n in ("short", "long"))
    fixed = t_s - (t_l - t_s) * sim_s / (sim_l - sim_s)
    print(f"heliquad sil: short ({sim_s:g} s simulated) {t_s:.2f} s, long ({sim_l:g} s) "
          f"{t_l:.2f} s: fixed cost {fixed:.2f} s, lockstep {(sim_l - sim_s) / (t_l - t_s):.0f}x "
          "real time")


def rig_section(tmp: str, repeat: int) -> None:
    """Rig time per axis, the paper's dwell against one multisine at equal accuracy:
    benchmarks/rig_time.py (still air, then moderate turbulence over ``repeat`` seeds)."""
    import rig_time  # beside this script

    rig_time.main(["--seeds", str(repeat)])


#: The sections in the order they run; --skip leaves any out.
SECTIONS = {"demo": demo_section, "identify": identify_section, "sil": sil_section,
            "rig": rig_section}


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--skip", action="append", default=[], choices=tuple(SECTIONS),
                        help="leave this section out (again for more)")
    parser.add_argument("--repeat", type=int, default=3, help="runs of each figure (median)")
    args = parser.parse_args(argv)
    with tempfile.TemporaryDirectory() as tmp:
        for name, section in SECTIONS.items():
            if name not in args.skip:
                section(tmp, max(1, args.repeat))


if __name__ == "__main__":
    main()
